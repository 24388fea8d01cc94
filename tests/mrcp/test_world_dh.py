"""DH tables as data: the RX60B file against spec §2, the kinematics against closed forms and
finite differences, and bad robot files against clear errors."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.core.errors import ConfigError
from vasim.mrcp import closed_form_ik, dh
from vasim.mrcp.dh import load_robot, parse_robot

RX = load_robot("rx60b")


def test_rx60b_table_is_the_spec_table() -> None:
    # spec §2 / seed Table 2.1: (alpha_{i-1} [deg], a_{i-1} [m], d_i [m])
    expected = [(0, 0, 0), (-90, 0, 0), (0, 0.290, 0.049), (-90, 0, 0.310), (90, 0, 0),
                (-90, 0, 0)]
    got = [(round(math.degrees(j.alpha), 9), j.a, j.d) for j in RX.joints]
    assert got == expected
    # seed Table 3.1, imposed joint limits [rad]
    assert RX.lower.tolist() == [-2.79, -3.80, 1.66, -3.05, 0.09, -3.05]
    assert RX.upper.tolist() == [2.79, 1.65, 3.92, 3.05, 2.01, 3.05]


def test_home_is_inside_the_imposed_limits() -> None:
    assert RX.within_limits(RX.home)


def test_home_pose_in_closed_form() -> None:
    # home: upper arm vertical (a2 up), forearm horizontal (d4 along x), lateral offset d3,
    # flange pointing down (TCP 65 mm below the wrist centre)
    pos, rot = dh.fk(RX, RX.home)
    np.testing.assert_allclose(pos, [0.310, 0.049, 0.290 - 0.065], atol=1e-12)
    np.testing.assert_allclose(rot[:, 2], [0, 0, -1], atol=1e-12)


def test_joint3_limit_sits_just_past_the_straight_arm_singularity() -> None:
    # links 2-3 aligned at q3 = pi/2: the wrist centre is as far from the shoulder as the
    # arm allows, sqrt((a2 + d4)^2 + d3^2), and the 6x6 Jacobian is singular there.
    q = RX.home.copy()
    q[2] = math.pi / 2
    frames = dh.link_frames(RX, q)
    assert np.linalg.norm(frames[5, :3, 3]) == pytest.approx(math.hypot(0.6, 0.049), abs=1e-12)
    assert abs(np.linalg.det(dh.jacobian(RX, q))) < 1e-12
    assert 0 < RX.lower[2] - math.pi / 2 < math.radians(5.2)
    q[2] = RX.lower[2]
    assert abs(np.linalg.det(dh.jacobian(RX, q))) > 1e-5


def test_planar_two_link_arm_matches_closed_form() -> None:
    text = """
        name = "planar2"
        home = [0.0, 0.0]
        [[joints]]
        alpha_deg = 0.0
        a = 0.0
        d = 0.0
        lower = -3.0
        upper = 3.0
        max_velocity = 1.0
        max_acceleration = 1.0
        [[joints]]
        alpha_deg = 0.0
        a = 0.4
        d = 0.0
        lower = -3.0
        upper = 3.0
        max_velocity = 1.0
        max_acceleration = 1.0
    """
    arm = parse_robot(text.replace("\n        ", "\n"))
    arm = dh.RobotModel(arm.name, arm.joints, tcp=np.array([0.3, 0.0, 0.0]), home=arm.home)
    for q1, q2 in [(0.3, -0.7), (1.2, 2.0), (-2.5, 0.1)]:
        pos, _ = dh.fk(arm, np.array([q1, q2]))
        expect = [0.4 * math.cos(q1) + 0.3 * math.cos(q1 + q2),
                  0.4 * math.sin(q1) + 0.3 * math.sin(q1 + q2), 0.0]
        np.testing.assert_allclose(pos, expect, atol=1e-12)


joint_vectors = st.tuples(*[st.floats(float(lo), float(up)) for lo, up in
                            zip(RX.lower, RX.upper, strict=True)]).map(np.array)


@settings(max_examples=40, deadline=None)
@given(joint_vectors)
def test_jacobian_matches_finite_differences(q: np.ndarray) -> None:
    jac = dh.jacobian(RX, q)
    h = 1e-6
    for i in range(6):
        dq = np.zeros(6)
        dq[i] = h
        p1, r1 = dh.fk(RX, q + dq)
        p0, r0 = dh.fk(RX, q - dq)
        np.testing.assert_allclose(jac[:3, i], (p1 - p0) / (2 * h), atol=1e-7)
        w = (r1 - r0) / (2 * h) @ dh.fk(RX, q)[1].T          # skew(omega)
        np.testing.assert_allclose(jac[3:, i], [w[2, 1], w[0, 2], w[1, 0]], atol=1e-7)


def test_batched_kinematics_equal_the_single_ones() -> None:
    rng = np.random.default_rng(3)
    qs = rng.uniform(RX.lower, RX.upper, size=(30, 6))
    base = np.eye(4)
    base[:3, 3] = [0.4, -0.1, 0.2]
    base[:3, :3] = dh.rot_z(0.7) @ dh.rot_x(0.2)
    pos, rot = dh.fk_batch(RX, qs, base)
    jac = dh.jacobian_batch(RX, qs, base)
    for i, q in enumerate(qs):
        p, r = dh.fk(RX, q, base)
        np.testing.assert_allclose(pos[i], p, atol=1e-14)
        np.testing.assert_allclose(rot[i], r, atol=1e-14)
        np.testing.assert_allclose(jac[i], dh.jacobian(RX, q, base), atol=1e-14)
        np.testing.assert_allclose(dh.link_frames(RX, q, base), dh.frames_one(RX, q, base),
                                   atol=1e-14)


def _rx_text() -> str:
    return dh.robots_dir().joinpath("rx60b.toml").read_text()


@pytest.mark.parametrize(("old", "new", "field"), [
    ("lower = 1.66", "lower = 3.95", "joints[2].lower"),
    ("max_velocity = 5.5851", "max_velocity = -1.0", "joints[4].max_velocity"),
    ("alpha_deg = 90.0", 'alpha_deg = "ninety"', "joints[4].alpha_deg"),
    ('name = "rx60b"', 'name = "rx60b"\ncolour = "grey"', "colour"),
    ("home = [0.0, -1.5707963267948966, 3.141592653589793",
     "home = [0.0, -1.5707963267948966, 0.5", "home[2]"),
    ("radius = 0.055", "radius = 0.0", "links[3].radius"),
])
def test_bad_robot_files_name_file_field_and_value(old: str, new: str, field: str) -> None:
    text = _rx_text()
    assert old in text
    with pytest.raises(ConfigError) as err:
        parse_robot(text.replace(old, new, 1), file="bad.toml")
    assert err.value.field == field
    assert err.value.file == "bad.toml"
    assert "bad.toml" in str(err.value)


def test_unknown_robot_name_lists_the_shipped_ones() -> None:
    with pytest.raises(ConfigError, match="rx60b"):
        load_robot("no_such_robot")


def test_closed_form_ik_returns_every_branch_and_the_original() -> None:
    base = np.eye(4)
    base[:3, 3] = [0.2, -0.1, 0.3]
    base[:3, :3] = dh.rot_z(0.7)
    assert closed_form_ik.is_puma_like(RX)
    for q in np.random.default_rng(21).uniform(RX.lower, RX.upper, size=(100, 6)):
        pos, rot = dh.fk(RX, q, base)
        sols = closed_form_ik.puma_ik(RX, pos, rot, base)
        assert len(sols) == 8
        for s in sols:
            p2, r2 = dh.fk(RX, s, base)
            np.testing.assert_allclose(p2, pos, atol=1e-12)
            np.testing.assert_allclose(r2, rot, atol=1e-12)
        wrapped = closed_form_ik.wrap_into_batch(np.array(sols), RX.lower - 10, RX.upper + 10, q)
        assert np.min(np.linalg.norm(wrapped - q, axis=1)) < 1e-9


def test_closed_form_ik_out_of_reach_and_other_structures() -> None:
    assert closed_form_ik.puma_ik(RX, np.array([0.0, 0.0, 0.8]), np.eye(3)) == []
    planar = dh.RobotModel("p", RX.joints[:2], home=RX.home[:2])
    assert not closed_form_ik.is_puma_like(planar)
    assert closed_form_ik.puma_ik(planar, np.zeros(3), np.eye(3)) == []


def test_wrap_into_picks_the_in_limit_turn_nearest_the_reference() -> None:
    lo, up = np.array([-3.0, 0.0]), np.array([3.0, 6.0])
    out = closed_form_ik.wrap_into(np.array([2.0 * math.pi + 0.5, -0.5]), lo, up,
                                   np.array([0.0, 5.0]))
    np.testing.assert_allclose(out, [0.5, 2 * math.pi - 0.5])
    assert closed_form_ik.wrap_into(np.array([3.1, 1.0]), lo, up, np.zeros(2)) is None


# -- Robot-file checks: names, key points per link, the links table, implausible lengths and
# limits.
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
