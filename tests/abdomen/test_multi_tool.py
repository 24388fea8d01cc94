"""Several instruments in the abdomen (issue #7 §4): per-instrument contact results, forces
summed per node on the tissue, quality accumulated over every instrument, and the
single-tool call unchanged bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.contact import ToolPose, detect_contacts
from vasim.abdomen.quality import TissueQuality
from vasim.abdomen.world import Abdomen

STEPS = 12
"""Physics steps of each pressing (48 ms at 4 ms)."""

NOWHERE = ToolPose(np.full(3, np.nan), np.full(3, np.nan))
"""An instrument out of the abdomen (a non-finite pose: no contact)."""


def top_press(world: Abdomen, organ: str, depth: float = 0.004,
              dx: float = 0.0) -> ToolPose:
    """A vertical instrument whose tip is ``depth`` under the top node of ``organ`` (moved
    ``dx`` along x on the surface)."""
    s = world.latest.organ(organ).surface
    top = s[np.argmax(s[:, 2])] + np.array([dx, 0.0, 0.0])
    if dx:
        near = s[np.linalg.norm(s[:, :2] - top[:2], axis=1) < 0.004]
        top[2] = near[:, 2].max()
    tip = top - np.array([0.0, 0.0, depth])
    return ToolPose(tip + np.array([0.0, 0.0, 0.10]), tip)


@pytest.fixture(scope="module")
def poses() -> dict[str, ToolPose]:
    w = Abdomen("default")
    return {"liver": top_press(w, "liver"), "stomach": top_press(w, "stomach"),
            "vessel": top_press(w, "vessel", 0.003)}


def run(tools_per_step: list[object]) -> tuple[Abdomen, list[object]]:
    w = Abdomen("default")
    return w, [w.step(tools) for tools in tools_per_step]


def test_the_instruments_are_apart(poses) -> None:
    # the two organs of the two-organ tests are far apart compared with the tool's reach
    d = np.linalg.norm(poses["liver"].tip - poses["stomach"].tip)
    assert d > 0.05


def test_two_tools_on_two_organs_each_feel_their_single_tool_force(poses) -> None:
    liv, sto = poses["liver"], poses["stomach"]
    both_w, both = run([{"grasper": liv, "driver": sto}] * STEPS)
    _, liver_only = run([liv] * STEPS)
    _, stomach_only = run([sto] * STEPS)
    for b, a1, a2 in zip(both, liver_only, stomach_only, strict=True):
        assert [tc.name for tc in b.tools] == ["grasper", "driver"]
        g, d = b.tool("grasper"), b.tool("driver")
        # organs do not touch each other: each instrument feels what it would alone
        for name in ("force", "force_tip", "torque", "stiffness_tip"):
            np.testing.assert_array_equal(getattr(g, name), getattr(a1, name))
            np.testing.assert_array_equal(getattr(d, name), getattr(a2, name))
        assert g.touching == ("liver",) and d.touching == ("stomach",)
        # the top-level fields are the first (haptic) instrument's
        np.testing.assert_array_equal(b.force, g.force)
        np.testing.assert_array_equal(b.patch.points, g.patch.points)
        assert b.touching == ("liver",) and b.touching_any == ("liver", "stomach")
        np.testing.assert_array_equal(b.organ("liver").surface, a1.organ("liver").surface)
        np.testing.assert_array_equal(b.organ("stomach").surface,
                                      a2.organ("stomach").surface)
    last = both[-1]
    assert last.tool("grasper").force[2] > 0 and last.tool("driver").force[2] > 0
    assert not np.allclose(last.tool("grasper").force, last.tool("driver").force)
    with pytest.raises(KeyError, match="camera"):
        last.tool("camera")
    assert both_w.awake()["liver"] and both_w.awake()["stomach"]


def test_quality_counts_any_contact_and_sums_force_and_torque_over_tools(poses) -> None:
    liv, ves = poses["liver"], poses["vessel"]
    # the grasper presses the liver in steps [0, 12), the driver the vessel in [6, 20)
    plan = [(liv if k < 12 else NOWHERE, ves if 6 <= k < 20 else NOWHERE)
            for k in range(26)]
    both_w, both = run([list(p) for p in plan])
    a_w, a = run([p[0] for p in plan])
    b_w, b = run([p[1] for p in plan])
    dt = both_w.dt
    in_a = np.array([s.in_contact for s in a])
    in_b = np.array([s.in_contact for s in b])
    assert in_a[:12].all() and in_b[7:20].all()   # the union has one gap-free run
    q, qa, qb = both_w.quality, a_w.quality, b_w.quality
    assert q.contact_time == pytest.approx(dt * np.sum(in_a | in_b), abs=1e-12)
    assert q.contact_time < qa.contact_time + qb.contact_time - 4 * dt  # overlap once
    assert q.contact_count == 1
    assert q.force_integral == pytest.approx(qa.force_integral + qb.force_integral,
                                             rel=1e-12)
    assert q.torque_integral == pytest.approx(qa.torque_integral + qb.torque_integral,
                                              rel=1e-12)
    fa = np.array([np.linalg.norm(s.force) for s in a])
    fb = np.array([np.linalg.norm(s.force) for s in b])
    assert q.max_force == pytest.approx(float((fa + fb).max()), rel=1e-12)
    # the vessel is touched by the second instrument: damage counts for any instrument
    assert q.delicate_count == qb.delicate_count == 1
    assert q.delicate_time == pytest.approx(qb.delicate_time, abs=1e-12) and qa.delicate_time == 0
    assert any(s.delicate_any and not s.delicate_contact for s in both)


def test_two_tools_on_one_organ_add_their_forces_per_node(poses) -> None:
    w = Abdomen("default")
    liv = poses["liver"]
    other = top_press(w, "liver", 0.004, dx=-0.02)
    body = next(b for b in w._bodies if b.model.name == "liver")
    for _ in range(4):
        x = np.array(body.positions(w.t))
        c1, c2 = (detect_contacts(x, body.model.faces, body.model.mass, p, w.tool, dt=w.dt,
                                  max_edge=body.max_edge) for p in (liv, other))
        snap = w.step((liv, other))
        assert c1.in_contact and c2.in_contact
        # an independent sum: each contact's reaction forces spread with np.add.at
        expected = c1.external_forces(body.model.n_nodes) + c2.external_forces(
            body.model.n_nodes)
        np.testing.assert_allclose(body.f_ext, expected, rtol=0, atol=1e-15)
        np.testing.assert_allclose(snap.tools[0].force, c1.force, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(snap.tools[1].force, c2.force, rtol=1e-12, atol=1e-15)
        # the tissue carries both loads: their sum balances the forces on the tools
        np.testing.assert_allclose(body.f_ext.sum(axis=0), -(c1.force + c2.force),
                                   atol=1e-12)


def test_a_single_pose_a_one_tuple_and_a_mapping_are_bit_identical(poses) -> None:
    liv = poses["liver"]
    far = ToolPose(liv.fulcrum, liv.tip + np.array([0.0, 0.0, 0.05]))
    seq = [liv] * 8 + [far] * 4 + [liv] * 4
    runs = [run(seq), run([(p,) for p in seq]), run([[p] for p in seq]),
            run([{"0": p} for p in seq])]
    (w0, ref), others = runs[0], runs[1:]
    for w, snaps in others:
        for s, r in zip(snaps, ref, strict=True):
            for name in ("force", "force_tip", "torque", "stiffness_tip", "targets",
                         "target_displacement"):
                np.testing.assert_array_equal(getattr(s, name), getattr(r, name))
            np.testing.assert_array_equal(s.patch.points, r.patch.points)
            np.testing.assert_array_equal(s.organ("liver").surface, r.organ("liver").surface)
            assert s.touching == r.touching and len(s.tools) == 1
        assert w.quality.as_dict() == w0.quality.as_dict()
    assert w0.quality.contact_count == 2 and ref[-1].tools[0].name == "0"


def test_no_tool_forms_and_bad_instruments() -> None:
    w = Abdomen("default")
    a = w.step(None)
    b = w.step(())
    assert a.tools == () == b.tools and not b.any_contact and b.touching_any == ()
    with pytest.raises(TypeError, match=r"instrument '1'.*ToolPose"):
        w.step([NOWHERE, (0.0, 0.0, 0.0)])


# Components below 1e-100 N are flushed to 0: their squares underflow (|F| is computed as
# sqrt(x² + y² + z²), like the single-instrument path, bit for bit) and no contact force is
# that small; math.hypot in the expectation would not underflow.
vec = st.tuples(*[st.floats(-50, 50, allow_nan=False).map(
    lambda v: 0.0 if abs(v) < 1e-100 else v)] * 3)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(vec, vec, st.booleans()), min_size=1, max_size=6))
def test_add_instruments_with_one_instrument_is_add_to_the_bit(steps) -> None:
    q1, q2 = TissueQuality(), TissueQuality()
    for f, tau, c in steps:
        q1.add(0.004, force=f, torque=tau, in_contact=c)
        q2.add_instruments(0.004, forces=[f], torques=[tau], in_contact=c)
    assert q1.as_dict() == q2.as_dict()


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(vec, vec, vec, vec), min_size=1, max_size=6))
def test_add_instruments_sums_magnitudes_in_any_order(steps) -> None:
    q, r = TissueQuality(), TissueQuality()
    expected_f = expected_tau = 0.0
    for f1, t1, f2, t2 in steps:
        q.add_instruments(0.004, forces=[f1, f2], torques=[t1, t2], in_contact=True)
        r.add_instruments(0.004, forces=[f2, f1], torques=[t2, t1], in_contact=True)
        expected_f += (math.hypot(*f1) + math.hypot(*f2)) * 0.004
        expected_tau += (math.hypot(*t1) + math.hypot(*t2)) * 0.004
    assert q.force_integral == pytest.approx(expected_f, rel=1e-12, abs=1e-300)
    assert q.torque_integral == pytest.approx(expected_tau, rel=1e-12, abs=1e-300)
    assert q.as_dict() == pytest.approx(r.as_dict(), rel=1e-12, abs=1e-300)
    assert q.contact_count == 1 and q.contact_time == pytest.approx(0.004 * len(steps))
    with pytest.raises(ValueError, match="2 forces and 1 torques"):
        q.add_instruments(0.004, forces=[f1, f2], torques=[t1], in_contact=True)
