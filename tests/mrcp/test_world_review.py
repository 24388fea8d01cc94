"""Regression tests of the world-layer review: unrefined -inf distances, NaN joints, IK input
validation and the shoulder singularity, the URDF cache (threads, partial caches,
generator changes), robot-file validation and the compiled model in deep penetration."""

from __future__ import annotations

import math
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.optimize import minimize_scalar

from vasim.core.errors import ConfigError
from vasim.mrcp import closed_form_ik, dh, urdf
from vasim.mrcp.backend import (
    COMPILED_TOLERANCE,
    PybulletArm,
    PybulletWorld,
    pose_matrix,
    rotation_error,
)
from vasim.mrcp.indices.collision import impact_time

RX = dh.load_robot("rx60b")


def _pybullet(world: PybulletWorld, robot: str, qs: np.ndarray, bodies: list[str]
              ) -> np.ndarray:
    world.compiled_distances = False
    try:
        return world.min_distances(robot, qs, bodies, 1.0)
    finally:
        world.compiled_distances = True


# ------------------------------------------------------------------ 1. -inf distances

def test_pairs_without_a_model_estimate_are_a_penetration_or_refined_on_request() -> None:
    w = PybulletWorld()
    w.add_robot("a", RX)
    frames = dh.frames_one(RX, RX.home)
    pts = RX.link_key_points(2)                      # inside the upper arm's key-point hull
    centre = (frames[2] @ np.c_[pts, np.ones(len(pts))].T).T[:, :3].mean(axis=0)
    w.add_sphere("ball", 0.02, centre)
    q = RX.home[None, :]
    fast = w.min_distances("a", q, ["ball"], 1.0)
    ref = _pybullet(w, "a", q, ["ball"])
    assert ref[0, 0] < -0.05 and fast[0, 0] <= ref[0, 0]    # -inf: "in, no estimate"
    w.refine_below = 0.0                                      # every penetration exact
    np.testing.assert_array_equal(w.min_distances("a", q, ["ball"], 1.0), ref)


def test_minus_infinity_is_an_impact_and_nan_is_still_skipped() -> None:
    t = np.array([0.0, 0.1, 0.2])
    assert impact_time(t, np.array([0.3, -np.inf, 0.1]), 5.0) == pytest.approx(0.1)
    assert impact_time(t, np.array([-np.inf, 0.2, 0.1]), 5.0) == 0.0
    assert impact_time(t, np.array([0.3, np.nan, 0.1]), 5.0) == pytest.approx(0.3)
    assert impact_time(t, np.array([0.3, np.nan, np.nan]), 5.0) == 5.0


# ----------------------------------------------------------------------- 2. NaN joints

def test_non_finite_joints_are_rejected_by_the_world() -> None:
    w = PybulletWorld()
    w.add_robot("a", RX)
    w.add_robot("b", RX, pose_matrix([0.5, 0.0, 0.0], dh.rot_z(math.pi)))
    q = RX.home.copy()
    q[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        w.set_configuration("a", q)
    np.testing.assert_array_equal(w.configuration("a"), RX.home)   # unchanged
    q[0] = np.inf
    with pytest.raises(ValueError, match="finite"):
        w.min_distances("a", np.stack([RX.home, q]), ["b"], 1.0)
    w.compiled_distances = False
    with pytest.raises(ValueError, match="finite"):
        w.min_distances("a", q[None], ["b"], 1.0)


# ------------------------------------------------------------------ 3. IK validation

@pytest.fixture(scope="module")
def arm() -> PybulletArm:
    return PybulletArm(RX)


def test_ik_rejects_non_finite_rotation_and_seed(arm: PybulletArm) -> None:
    p, r = arm.tcp_pose(RX.home)
    bad_r = r.copy()
    bad_r[0, 0] = np.nan
    with pytest.raises(ValueError, match="rotation"):
        arm.ik(p, bad_r, RX.home)
    with pytest.raises(ValueError, match="rotation"):
        arm.ik(p, bad_r)
    with pytest.raises(ValueError, match="rotation"):
        arm.ik(p, np.eye(4))
    with pytest.raises(ValueError, match="q_seed"):
        arm.ik(p, r, np.full(6, np.nan))
    with pytest.raises(ValueError, match="position"):
        arm.ik(np.array([np.nan, 0.0, 0.3]), r)


def test_ik_position_only_with_a_nan_seed_raises_instead_of_hanging() -> None:
    # in a subprocess: the old code looped forever inside pybullet
    code = ("import numpy as np\n"
            "from vasim.mrcp import dh\n"
            "from vasim.mrcp.backend import PybulletArm\n"
            "arm = PybulletArm(dh.load_robot('rx60b'))\n"
            "p, _ = arm.tcp_pose(arm.home)\n"
            "try:\n"
            "    arm.ik(p, None, np.full(6, np.nan))\n"
            "except ValueError as e:\n"
            "    print('ValueError', e)\n")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=False)
    assert "ValueError" in out.stdout and "q_seed" in out.stdout, out.stderr[-2000:]


# ------------------------------------------------------ 4. the shoulder singularity

def _shoulder_singular(q: np.ndarray) -> np.ndarray:
    """``q`` with joint 2 moved so that the wrist centre lies on the d3 circle about the
    first axis (rho2 = 0: the shoulder singularity)."""
    d3 = RX.joints[2].d

    def rho2(q2: float) -> float:
        qq = q.copy()
        qq[1] = q2
        w = dh.frames_one(RX, qq)[4][:3, 3]
        return float(w[0] ** 2 + w[1] ** 2 - d3 ** 2)

    res = minimize_scalar(rho2, bounds=(q[1] - 1e-3, q[1] + 1e-3), method="bounded",
                          options={"xatol": 1e-12})
    out = q.copy()
    out[1] = res.x
    assert abs(rho2(res.x)) < 1e-12
    return out


@pytest.mark.parametrize("q", [[-1.7107, -1.7253, 1.8697, 2.6558, 0.7911, -1.9774],
                               [-0.6936, -2.0168, 2.4321, 1.9764, 0.5328, 2.2632]])
def test_closed_form_ik_at_the_shoulder_singularity(arm: PybulletArm, q: list[float]
                                                    ) -> None:
    qs = _shoulder_singular(np.array(q))
    p, r = arm.tcp_pose(qs)
    assert len(closed_form_ik.puma_ik(RX, p, r)) == 8    # was 0 (rho2 ~ -1e-18, round-off)
    sol = arm.ik(p, r)
    assert sol is not None and RX.within_limits(sol)
    p2, r2 = arm.tcp_pose(sol)
    assert np.linalg.norm(p2 - p) <= 1e-6
    assert np.linalg.norm(rotation_error(r2, r)) <= 1e-6


def test_an_empty_closed_form_within_reach_falls_back_to_the_numeric_search(
        arm: PybulletArm, monkeypatch: pytest.MonkeyPatch) -> None:
    q = np.array([0.3, -1.2, 2.6, 0.4, 1.0, -0.5])
    p, r = arm.tcp_pose(q)
    monkeypatch.setattr(closed_form_ik, "puma_ik", lambda *args, **kwargs: [])
    assert arm._closed_form_ik(p, r, RX.home, 1e-6, 1e-6) == (None, False)
    sol = arm.ik(p, r)
    assert sol is not None
    assert np.linalg.norm(arm.tcp_pose(sol)[0] - p) <= 1e-6


# ------------------------------------------------------------------- 5./6. URDF cache

def test_concurrent_writers_in_threads_do_not_collide(
        tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("VASIM_CACHE", str(tmp_path))
    urdf.link_hulls(RX)
    text = urdf.urdf_text

    def slow_text(robot: dh.RobotModel) -> str:     # widens the race window
        time.sleep(0.02)
        return text(robot)

    monkeypatch.setattr(urdf, "urdf_text", slow_text)
    errors: list[BaseException] = []
    for trial in range(4):
        monkeypatch.setenv("VASIM_CACHE", str(tmp_path / str(trial)))
        barrier = threading.Barrier(4)

        def go(b: threading.Barrier = barrier) -> None:
            b.wait()
            try:
                urdf.write_urdf(RX)
            except BaseException as exc:       # collected, asserted below
                errors.append(exc)

        threads = [threading.Thread(target=go) for _ in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        folder = urdf.write_urdf(RX).parent
        names = sorted(p.name for p in folder.iterdir())
        assert names == [*(f"link{k}.obj" for k in range(7)), "rx60b.urdf"]   # no temps
    assert errors == []


def test_a_partial_cache_is_repaired(tmp_path: Path, monkeypatch: pytest.MonkeyPatch
                                     ) -> None:
    monkeypatch.setenv("VASIM_CACHE", str(tmp_path))
    path = urdf.write_urdf(RX)
    (path.parent / "link2.obj").unlink()
    assert urdf.write_urdf(RX) == path
    assert (path.parent / "link2.obj").is_file()
    w = PybulletWorld(compiled_distances=False)
    w.add_robot("a", RX)
    w.add_sphere("ball", 0.03, np.array([0.0, 0.0, 0.15]))    # on the upper arm at home
    assert w.in_collision("a")


def test_the_generator_version_is_part_of_the_model_key(monkeypatch: pytest.MonkeyPatch
                                                        ) -> None:
    text = dh.robots_dir().joinpath("rx60b.toml").read_text()
    before = urdf.model_key(dh.parse_robot(text))
    monkeypatch.setattr(urdf, "GENERATOR_VERSION", urdf.GENERATOR_VERSION + 1)
    assert urdf.model_key(dh.parse_robot(text)) != before


# ------------------------------------------------------------ 7.-9. robot-file checks

def _rx_text() -> str:
    return dh.robots_dir().joinpath("rx60b.toml").read_text()


def _sub(old: str, new: str) -> str:
    text = _rx_text()
    assert old in text
    return text.replace(old, new, 1)


@pytest.mark.parametrize("name", ["a/b", "..", ".hidden", 'a"b<c', "a b", "x\\y"])
def test_bad_robot_names_are_rejected(name: str) -> None:
    with pytest.raises(ConfigError) as err:
        dh.parse_robot(_sub('name = "rx60b"', f"name = '{name}'"), file="bad.toml")
    assert err.value.field == "name"
    with pytest.raises(ConfigError) as err:
        dh.RobotModel(name, RX.joints, home=RX.home)
    assert err.value.field == "name"


def test_a_plain_robot_name_is_accepted() -> None:
    assert dh.parse_robot(_sub('name = "rx60b"', 'name = "rx60b_v2.1-test"')).name == \
        "rx60b_v2.1-test"


def test_more_than_three_key_points_per_link_are_rejected_at_parse_time() -> None:
    text = _sub("radius = 0.07", "radius = 0.07\npoints = [[0.1, 0.0, 0.1]]")
    with pytest.raises(ConfigError) as err:
        dh.parse_robot(text, file="bad.toml")
    assert err.value.field == "links[2].points"
    # three points without the chain, or a duplicate of a chain point, are fine
    dh.parse_robot(_sub("radius = 0.07", "radius = 0.07\nchain = false\n"
                                         "points = [[0, 0, 0], [0.1, 0, 0], [0, 0.1, 0]]"))
    dh.parse_robot(_sub("radius = 0.07", "radius = 0.07\npoints = [[0.0, 0.0, 0.0]]"))


@pytest.mark.parametrize("value", ["5", '"abc"', "{ radius = 0.1 }"])
def test_a_links_value_that_is_not_a_table_list_is_a_config_error(value: str) -> None:
    text = re.sub(r"\[\[links\]\].*", "", _rx_text(), flags=re.S)
    text = text.replace('name = "rx60b"', f'name = "rx60b"\nlinks = {value}', 1)
    with pytest.raises(ConfigError) as err:
        dh.parse_robot(text, file="bad.toml")
    assert err.value.field == "links"


@pytest.mark.parametrize(("old", "new", "field"), [
    ("a = 0.290", "a = 290.0", "joints[2].a"),
    ("d = 0.310", "d = -310.0", "joints[3].d"),
    ("lower = -2.79\nupper = 2.79", "lower = -160.0\nupper = 160.0", "joints[0].lower"),
    ("lower = -3.05\nupper = 3.05", "lower = -3.05\nupper = 20.0", "joints[3].upper"),
])
def test_implausible_lengths_and_limits_are_rejected(old: str, new: str, field: str) -> None:
    with pytest.raises(ConfigError) as err:
        dh.parse_robot(_sub(old, new), file="bad.toml")
    assert err.value.field == field


# ------------------------------------------------------ 10. deep penetrations

_LB_CASE = {   # the reviewer's case: model 1.087 mm below pybullet at 7 cm penetration
    "ba": [[0.6065586612966181, 0.6222882066102803, 0.4948171160336066, -0.003110412232102527],
           [-0.795038735160781, 0.47476215289796175, 0.37751067239170577,
            -0.07116146500204364],
           [0.0, -0.6223811421383633, 0.782714324584996, -0.06115749309388823],
           [0.0, 0.0, 0.0, 1.0]],
    "bb": [[-0.4637633934137484, 0.8859590932595957, 0.0, 0.6046569087288115],
           [-0.8859590932595957, -0.4637633934137484, 0.0, -0.21407365127791042],
           [0.0, 0.0, 1.0, 0.13603952372220537], [0.0, 0.0, 0.0, 1.0]],
    "qb": [0.9472087527795794, 0.045796167675844046, 2.63276413571293, 0.08369175160069808,
           1.731545909362709, 2.2359516790409195],
    "qa": [0.6222055973835809, -0.5786288879283412, 2.345150827846893, -0.12003676022323218,
           0.46676072661299306, -0.08693023199629568],
}


@pytest.mark.parametrize("case", ["reviewer", "same_base"])
def test_deep_penetrations_stay_within_the_tolerance(case: str) -> None:
    w = PybulletWorld()
    if case == "reviewer":
        w.add_robot("a", RX, np.array(_LB_CASE["ba"]))
        w.add_robot("b", RX, np.array(_LB_CASE["bb"]), np.array(_LB_CASE["qb"]))
        q = np.array(_LB_CASE["qa"])
    else:               # two arms 5 cm apart at home: model 2.6 mm below pybullet
        w.add_robot("a", RX)
        w.add_robot("b", RX, pose_matrix([0.05, 0.0, 0.0]))
        q = RX.home
    fast = w.min_distances("a", q[None], ["b"], 1.0)
    ref = _pybullet(w, "a", q[None], ["b"])
    assert ref[0, 0] < -0.05
    assert fast[0, 0] - ref[0, 0] <= 1e-5           # still a lower bound
    w.refine_below = 0.0
    assert w.min_distances("a", q[None], ["b"], 1.0)[0, 0] == ref[0, 0]
    w.refine_below = -math.inf
    w.set_configuration("a", q)
    exact = w.min_distance("a", "b").distance
    w.compiled_distances = False
    assert exact == pytest.approx(w.min_distance("a", "b").distance, abs=1e-12)


def test_random_penetrations_are_lower_bounds_and_exact_on_request() -> None:
    """The model is a lower bound everywhere, within the tolerance where pybullet finds no
    penetration, and any penetration keeps its sign; refine_below = 0 makes penetrations
    pybullet's values."""
    rng = np.random.default_rng(11)
    w = PybulletWorld()
    w.add_robot("a", RX)
    w.add_robot("b", RX, pose_matrix([0.45, 0.05, 0.0], dh.rot_z(2.8)))
    w.add_sphere("s", 0.06, np.array([0.25, 0.0, 0.3]))
    negative = 0
    for _ in range(40):
        w.set_configuration("b", rng.uniform(RX.lower, RX.upper))
        qs = rng.uniform(RX.lower, RX.upper, size=(4, 6))
        w.refine_below = -math.inf
        fast = w.min_distances("a", qs, ["b", "s"], 1.0)
        ref = _pybullet(w, "a", qs, ["b", "s"])
        d = fast - ref
        assert d.max() <= 1e-5
        assert d[ref > 0].min(initial=0.0) >= -COMPILED_TOLERANCE
        assert np.all(fast[ref < -1e-5] < 0)                   # a penetration stays one
        w.refine_below = 0.0
        exact = w.min_distances("a", qs, ["b", "s"], 1.0)
        np.testing.assert_allclose(exact[ref < -COMPILED_TOLERANCE],
                                   ref[ref < -COMPILED_TOLERANCE], atol=1e-12)
        negative += int(np.sum(ref < 0))
    assert negative > 5
