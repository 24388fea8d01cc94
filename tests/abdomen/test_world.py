"""The abdomen as a whole: tool contact on tissue, targets riding on breathing organs,
sleeping organs, snapshots, the physics thread."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest
import trimesh

from tests.abdomen.test_scene import LIVER, scene_text
from tests.polling import wait_until
from vasim.abdomen.contact import ToolPose, ToolShape, detect_contacts
from vasim.abdomen.integrate import OrganSolver, StepReport
from vasim.abdomen.model import AnchorRule, OrganParams, build_organ
from vasim.abdomen.runner import PhysicsThread
from vasim.abdomen.scene import load_scene, parse_scene
from vasim.abdomen.world import MAX_EVENTS, Abdomen, motion_phases, settled_positions
from vasim.core.errors import ConfigError
from vasim.tasks import point_task


def slab():
    """A 10 x 10 x 2 cm slab of tissue, bottom face glued (anchored), top at z = +1 cm."""
    mesh = trimesh.creation.box(extents=(0.1, 0.1, 0.02))
    for _ in range(3):
        mesh = mesh.subdivide()
    params = OrganParams(stiffness=200.0, bending_stiffness=20.0, mass=0.2, damping=0.05,
                         volume=True, volume_stiffness=100.0,
                         anchors=(AnchorRule(to="plane", point=(0, 0, -0.0099),
                                             normal=(0, 0, 1), within=0.0),))
    return build_organ(mesh, params, name="slab", gravity=(0.0, 0.0, 0.0))


def press(model, solver, state, pose, seconds, shape):
    targets = np.array(model.rest[model.anchors])
    contact = None
    for _ in range(round(seconds / solver.dt)):
        contact = None
        f = None
        if pose is not None:
            contact = detect_contacts(state.x, model.faces, model.mass, pose, shape,
                                      dt=solver.dt)
            if contact.in_contact:
                f = contact.external_forces(model.n_nodes)
        solver.step(state, targets, f)
    return contact


def test_pressing_5mm_into_a_patch_pushes_back_and_the_tissue_returns():
    model = slab()
    solver = OrganSolver(model, dt=0.004)
    state = solver.initial_state()
    shape = ToolShape()
    tip = np.array([0.004, -0.003, 0.01 - 0.005])  # 5 mm below the rest surface
    pose = ToolPose(fulcrum=tip + np.array([0.0, 0.0, 0.15]), tip=tip)
    c = press(model, solver, state, pose, 2.0, shape)
    assert c is not None and c.in_contact
    f = c.force
    # pushed back along the surface normal (+z), in the range of a hand's touch
    assert f[2] > 0 and np.linalg.norm(f[:2]) < 0.2 * f[2]
    assert 0.05 < f[2] < 20.0
    # the tissue under the tool is dented (the tool is 5 mm deep, the penalty keeps a gap)
    top = np.flatnonzero(np.isclose(model.rest[: model.n_surface, 2], 0.01))
    under = top[np.linalg.norm(model.rest[top, :2] - tip[:2], axis=1) < 0.01]
    dent = model.rest[under, 2] - state.x[under, 2]
    assert dent.max() > 1e-3
    # equilibrium: the force on the tool equals the springs' pull on the dented nodes
    # (the reaction is what the tissue receives, so their sum is -F)
    np.testing.assert_allclose(c.node_force.sum(axis=0), -f, atol=1e-12)
    # release: the tissue returns to its rest shape
    press(model, solver, state, None, 3.0, shape)
    assert np.abs(state.x - model.rest).max() < 5e-4
    assert np.all(np.isfinite(state.x))


@pytest.fixture(scope="module")
def world():
    return Abdomen("default")


def test_a_poi_on_the_liver_moves_with_the_prescribed_breathing(world):
    task = point_task()
    world.bind_targets(task.points, organs=["liver"])
    scene = load_scene("default")
    amp = np.asarray(scene.organ("liver").breathing_m)
    freq = scene.motion.breathing_hz
    t0 = world.t
    ts, ys = [], []
    for _ in range(round(2.0 / freq / world.dt)):  # two breaths
        s = world.step(None)
        ts.append(s.t)
        ys.append(s.targets[0].copy())
    ts, ys = np.array(ts), np.array(ys)
    # least-squares fit of the breathing and heartbeat sines to the POI's y coordinate
    motion = scene.organ("liver").motion(scene.motion)
    phases = np.array([motion_phases(motion, t) for t in ts])
    design = np.column_stack([np.ones_like(ts), phases])
    coef, *_ = np.linalg.lstsq(design, ys[:, 1], rcond=None)
    assert coef[1] == pytest.approx(amp[1], rel=0.02)   # breathing amplitude, cranio-caudal
    resid = ys[:, 1] - design @ coef
    assert np.abs(resid).max() < 1e-4
    # period: the y motion repeats after 1 / f
    n_period = round(1.0 / freq / world.dt)
    np.testing.assert_allclose(ys[n_period:, 1], ys[:-n_period, 1], atol=1e-9)
    assert ts[0] > t0


def test_snapshots_are_immutable_and_consistent(world):
    s = world.step(None)
    with pytest.raises(ValueError):
        s.targets[0, 0] = 1.0
    surf = s.organ("liver").surface
    with pytest.raises(ValueError):
        surf[0, 0] = 1.0
    s2 = world.step(None)
    assert s2.seq == s.seq + 1 and s2.t > s.t
    # an older snapshot still shows its own time's surface
    assert not np.array_equal(s.organ("liver").surface, s2.organ("liver").surface)


def test_sleeping_organs_match_integrated_ones():
    # Without a tool an integrated organ follows the motion field closely; the sleeping
    # shape is that field applied to the settled shape.
    awake = Abdomen("default", always_awake=True)
    asleep = Abdomen("default")
    for _ in range(250):  # 1 s
        a = awake.step(None)
        b = asleep.step(None)
    assert not any(asleep.awake().values())
    for name in ("liver", "stomach", "intestine_0"):
        d = np.abs(a.organ(name).surface - b.organ(name).surface).max()
        assert d < 2e-3, (name, d)


def test_contact_wakes_an_organ_and_non_finite_poses_are_ignored(world):
    liver = world.latest.organ("liver").surface
    top = liver[np.argmax(liver[:, 2])]
    fulcrum = top + np.array([0.0, -0.05, 0.1])
    s = world.step(ToolPose(fulcrum, top - np.array([0.0, 0.0, 0.004])))
    s = world.step(ToolPose(fulcrum, top - np.array([0.0, 0.0, 0.004])))
    assert "liver" in s.touching and world.awake()["liver"]
    assert s.force @ np.array([0.0, 0.0, 1.0]) > 0
    assert s.patch.size > 0
    s = world.step(ToolPose(fulcrum, np.array([np.nan, 0.0, 0.0])))
    assert not s.in_contact and np.all(np.isfinite(s.force))
    assert world.quality.contact_count >= 1 and world.quality.force_integral > 0


def test_the_vessel_counts_as_damage():
    w = Abdomen("default", tool=ToolShape())
    vessel = w.latest.organ("vessel").surface
    p = vessel[np.argmax(vessel[:, 2])]
    pose = ToolPose(p + np.array([0.0, 0.0, 0.12]), p - np.array([0.0, 0.0, 0.003]))
    for _ in range(3):
        s = w.step(pose)
    assert s.delicate_contact and "vessel" in s.touching
    assert w.quality.delicate_count == 1 and w.quality.delicate_time > 0


def test_physics_thread_publishes_whole_snapshots():
    w = Abdomen("default")
    with PhysicsThread(w) as physics:
        physics.set_tool(ToolPose(np.zeros(3), np.array([np.inf, 0.0, 0.0])))  # ignored
        wait_until(lambda: physics.latest.seq > 0, what="a first physics snapshot")
        first = physics.latest
        wait_until(lambda: physics.latest.seq > first.seq, what="a later physics snapshot")
        second = physics.latest
    assert physics.error is None
    assert second.seq > first.seq > 0
    stats = physics.stats()
    assert stats["steps"] >= second.seq
    # the physics thread's CPU time per step is measured. It is not compared with the
    # wall-clock cost: the thread CPU clock and perf_counter tick differently, so a
    # step's CPU time can read a few microseconds above its wall time (CI saw 73.9 vs 71.4 us)
    assert 0.0 < stats["cpu_p50"] <= stats["cpu_max"]
    assert 0.0 < stats["cost_p50"] <= stats["cost_max"]
    assert not physics.running


def test_frame_velocities_are_point_motions_velocities_to_the_bit():
    world = Abdomen("default")
    for b in world._bodies:
        for t in (0.0, 0.123, 1.7, 12.345):
            np.testing.assert_array_equal(b.frame_velocities(t), b.node_motion.velocities(t))


# -- A kinematic delicate vessel in contact, settling that keeps resetting, huge poses and
# reset events.
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
