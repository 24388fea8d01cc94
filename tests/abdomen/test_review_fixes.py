"""Review fixes of vasim.abdomen: plausibility bounds of scenes, settling that keeps resetting,
kinematic organs in contact, unanchored parts, unit hints, degenerate triangles, huge poses,
reset events, and the physics thread's stop, step count and event hand-off."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import trimesh

from vasim.abdomen._contact_kernels import _closest
from vasim.abdomen.contact import ToolPose
from vasim.abdomen.integrate import StepReport
from vasim.abdomen.meshes import load_user_mesh
from vasim.abdomen.model import AnchorRule, OrganParams, build_organ
from vasim.abdomen.runner import PhysicsThread
from vasim.abdomen.scene import parse_scene
from vasim.abdomen.world import MAX_EVENTS, Abdomen, settled_positions
from vasim.core.errors import ConfigError
from vasim.trials.realtime import PhysicsLog
from vasim.trials.realtime.plant import ThreadFeed

LIVER = """
[[organs.liver.anchors]]
to = "plane"
point = [0.0, 0.142, 0.0]
normal = [0.0, -1.0, 0.0]
fraction = 0.1
"""


def scene_text(physics: str = "", motion: str = "", organ: str = "") -> str:
    return (f'name="x"\n[physics]\n{physics}\n[motion]\n{motion}\n[organs.liver]\n{organ}\n'
            + LIVER)


# -- 1. plausibility bounds ---------------------------------------------------------------


@pytest.mark.parametrize(("kw", "field", "value"), [
    ({"organ": "breathing_m=[0.0,12.0,0.0]"}, "organs.liver.breathing_m", "12.0"),
    ({"organ": "heartbeat_m=[0.0,0.0,0.02]"}, "organs.liver.heartbeat_m", "0.02"),
    ({"motion": "breathing_hz=100.0"}, "motion.breathing_hz", "100.0"),
    ({"motion": "heartbeat_hz=250.0"}, "motion.heartbeat_hz", "250.0"),
    ({"physics": "gravity=[0.0,0.0,-1e6]"}, "physics.gravity", "1000000.0"),
])
def test_implausible_motion_and_gravity_are_refused(kw: dict[str, str], field: str,
                                                    value: str) -> None:
    with pytest.raises(ConfigError) as info:
        parse_scene(scene_text(**kw), source="/x/scene.toml")
    assert info.value.field == field and info.value.file == "/x/scene.toml"
    assert value in str(info.value)


def test_plausible_values_and_still_motion_are_accepted() -> None:
    scene = parse_scene(scene_text(motion="breathing_hz=0.0\nheartbeat_hz=3.0",
                                   organ="breathing_m=[0.0,0.05,0.0]\nheartbeat_m=[0,0,0.01]"))
    assert scene.motion.heartbeat_hz == 3.0


# -- 3 / 4. kinematic organs --------------------------------------------------------------


def test_a_deformable_wall_and_an_all_kinematic_scene_are_refused() -> None:
    with pytest.raises(ConfigError, match="must be kinematic") as info:
        parse_scene('name="w"\n[organs.abdominal_wall]\nkinematic=false\n' + LIVER.replace(
            "liver", "abdominal_wall"))
    assert info.value.field == "organs.abdominal_wall.kinematic"
    with pytest.raises(ConfigError, match="deformable organ") as info:
        parse_scene('name="w"\n[organs.liver]\nkinematic=true\nvolume=false\n')
    assert info.value.field == "organs"


def test_a_kinematic_delicate_vessel_is_touched_and_counts_as_damage() -> None:
    scene = parse_scene(
        'name="kinvessel"\n[organs.liver]\n' + LIVER
        + '\n[organs.vessel]\nkinematic=true\nvolume=false\n')
    world = Abdomen(scene)
    body = next(b for b in world._bodies if b.model.name == "vessel")
    assert body.kinematic and body.model.delicate
    s = body.settled[: body.model.n_surface]
    p = s[int(np.argmax(s[:, 2]))]
    snap = world.step(ToolPose(p + np.array([0, 0, 0.1]), p - np.array([0, 0, 0.003])))
    assert "vessel" in snap.touching and snap.delicate_contact
    assert snap.force[2] > 0.0  # the rigid organ pushes the tool back (up)
    assert not world.awake()["vessel"]  # never stepped
    assert world.quality.delicate_count == 1 and world.quality.delicate_time > 0.0


# -- 2. settling that keeps resetting -----------------------------------------------------


class _ResettingSolver:
    dt = 0.004

    def __init__(self, solver: Any) -> None:
        self._inner = solver

    def initial_state(self) -> Any:
        return self._inner.initial_state()

    def step(self, state: Any, targets: Any, *a: Any, **k: Any) -> StepReport:
        state.v[...] = 0.0  # what a reset leaves: looks "still"
        return StepReport(False, True, "liver: blow-up; reset to rest", 0, 0, False, state.t)


def test_settling_that_keeps_resetting_is_refused_naming_the_organ() -> None:
    from vasim.abdomen.integrate import OrganSolver
    scene = parse_scene(scene_text(), source="/x/settle.toml")
    (model,) = scene.build()
    scene = parse_scene(scene_text().replace('name="x"', 'name="settle_reset_test"'),
                        source="/x/settle.toml")
    with pytest.raises(ConfigError, match="does not settle") as info:
        settled_positions(scene, model,
                          lambda: _ResettingSolver(OrganSolver(model, 0.004)))  # type: ignore
    assert info.value.field == "organs.liver" and "liver" in str(info.value)


# -- 5. unit hints ------------------------------------------------------------------------


def test_the_units_hint_names_centimetres_or_millimetres(tmp_path: Path) -> None:
    cm = tmp_path / "cm.obj"
    trimesh.creation.icosphere(subdivisions=2, radius=3.0).export(cm)
    with pytest.raises(ConfigError, match='centimetres; pass units="cm"'):
        load_user_mesh(cm)
    assert load_user_mesh(cm, units="cm").extents.max() == pytest.approx(0.06, rel=1e-6)
    mm = tmp_path / "mm.obj"
    trimesh.creation.icosphere(subdivisions=2, radius=150.0).export(mm)
    with pytest.raises(ConfigError, match='millimetres; pass units="mm"'):
        load_user_mesh(mm)


# -- 6. anchors per connected part --------------------------------------------------------


def test_unanchored_organs_and_parts_are_refused() -> None:
    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    with pytest.raises(ConfigError, match="no anchor") as info:
        build_organ(ball, OrganParams(), name="ball")
    assert info.value.field == "anchors"
    two = trimesh.util.concatenate([ball, ball.copy().apply_translation((0.2, 0.0, 0.0))])
    rule = AnchorRule(to="point", point=(0.0, 0.0, 0.0), fraction=0.1)
    with pytest.raises(ConfigError, match=r"'pair'.*part 1 of 2 connected parts"):
        build_organ(two, OrganParams(anchors=(rule,)), name="pair")
    rule2 = AnchorRule(to="point", point=(0.2, 0.0, 0.0), within=0.031)
    model = build_organ(two, OrganParams(anchors=(rule, rule2)), name="pair")
    assert len(model.anchors) > 0
    # a kinematic organ is entirely anchored: accepted
    build_organ(ball, OrganParams(kinematic=True, volume=False), name="rigid")


# -- 7. degenerate triangles --------------------------------------------------------------


def test_closest_point_on_a_degenerate_triangle_does_not_divide_by_zero() -> None:
    # a == b: the denominator of the edge-ac branch was zero (ZeroDivisionError in numba)
    q = _closest(1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)
    assert all(np.isfinite(q))
    for p in ((0.5, 1.0, 0.0), (2.0, 0.0, 0.0), (1.0, 1.0, 1.0)):
        assert all(np.isfinite(_closest(*p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0)))
        assert all(np.isfinite(_closest(*p, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)))


# -- 8 / 9 / 1. stepping: huge poses, reset events, bounded event list ---------------------


def test_huge_poses_are_no_contact_and_reset_events_name_the_organ_once() -> None:
    world = Abdomen("default", always_awake=True)
    assert world.events.maxlen == MAX_EVENTS
    for ful in ([0.0, 0.0, 1e155], [0.0, 0.0, 1e160], [1e200, 0.0, 0.0]):
        snap = world.step(ToolPose(np.array(ful), np.array([0.0, 0.0, 0.05])))
        assert not snap.in_contact and np.array_equal(snap.force, np.zeros(3))
    body = next(b for b in world._bodies if b.model.name == "liver")
    body.state.x[3] = np.nan
    snap = world.step(None)
    (_kind, detail), = [e for e in snap.events if e[0] == "organ_reset"]
    assert detail.startswith("liver: ") and not detail.startswith("liver: liver:")
    assert world.n_events == 1 and world.events[-1][2] == detail


# -- 10 / 11. the physics thread ----------------------------------------------------------


@dataclass(frozen=True)
class _Snap:
    t: float
    seq: int
    events: tuple[tuple[str, str], ...] = ()


class _FakeWorld:
    """Steps in no time; every step is a reset event; ``gate`` can hold a step."""

    dt = 0.001

    def __init__(self) -> None:
        self.calls = 0
        self.latest = _Snap(0.0, 0)
        self.gate = threading.Event()
        self.gate.set()

    def step(self, tool: Any) -> _Snap:
        self.gate.wait()
        self.calls += 1
        self.latest = _Snap(self.calls * self.dt, self.calls,
                            (("organ_reset", f"liver: reset {self.calls}"),))
        return self.latest


def test_stats_count_every_step_after_the_trim_and_events_are_drained_losslessly() -> None:
    world = _FakeWorld()
    physics = PhysicsThread(world, rate_hz=1e9)  # type: ignore[arg-type]
    physics.start()
    drained: list[tuple[float, str, str]] = []
    while world.calls < 100_500:
        drained += physics.drain_events()
        time.sleep(0.01)
    physics.stop()
    drained += physics.drain_events()
    assert physics.stats()["steps"] == world.calls > 100_000
    assert [d for _, _, d in drained] == [f"liver: reset {i}" for i in range(1, world.calls + 1)]


def test_stop_keeps_a_thread_that_did_not_end_registered() -> None:
    world = _FakeWorld()
    physics = PhysicsThread(world, rate_hz=1000.0)  # type: ignore[arg-type]
    physics.start()
    while world.calls < 2:
        time.sleep(0.001)
    world.gate.clear()  # the next step hangs
    time.sleep(0.01)
    physics.stop(timeout=0.05)
    assert physics.running
    with pytest.raises(RuntimeError, match="already running"):
        physics.start()
    world.gate.set()
    physics.stop()
    assert not physics.running


class _FakePhysics:
    def __init__(self) -> None:
        self.latest = _Snap(0.0, 0)
        self.events: list[tuple[float, str, str]] = []

    def set_tool(self, pose: Any) -> None:
        pass

    def drain_events(self) -> list[tuple[float, str, str]]:
        out, self.events = self.events, []
        return out


def test_the_thread_feed_hands_over_the_events_of_skipped_snapshots() -> None:
    physics = _FakePhysics()
    feed = ThreadFeed(physics, PhysicsLog())  # type: ignore[arg-type]
    pose = ToolPose(np.zeros(3), np.array([0.0, 0.0, -0.1]))
    # steps 1-3 reset (snapshots 1 and 2 skipped); step 4's event was queued after the
    # feed read snapshot 3: it waits for snapshot 4
    physics.events = [(0.004, "organ_reset", "a"), (0.008, "organ_reset", "b"),
                      (0.012, "organ_reset", "c"), (0.016, "organ_reset", "d")]
    physics.latest = _Snap(0.012, 3, (("organ_reset", "c"),))
    snap = feed(0, pose)
    assert snap.events == (("organ_reset", "a"), ("organ_reset", "b"), ("organ_reset", "c"))
    assert feed(1, pose) is None  # same snapshot
    physics.latest = _Snap(0.016, 4, (("organ_reset", "d"),))
    assert feed(2, pose).events == (("organ_reset", "d"),)
