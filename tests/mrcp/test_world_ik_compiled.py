"""The compiled full-pose IK (issue #17 §5): the same iteration as the Python loop it
replaced (an independent numpy copy of that loop here), IK that lands on the pose (analytic
FK round trip), and the wrist-centre test that skips searches which cannot succeed."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial.transform import Rotation

from vasim.mrcp import _ik_kernels, closed_form_ik, dh
from vasim.mrcp.backend import PybulletArm, pose_matrix, rotation_error

RX = dh.load_robot("rx60b")
BASE = pose_matrix([0.3, -0.2, 0.5], dh.rot_z(1.0) @ dh.rot_x(0.3))


@pytest.fixture(scope="module")
def arm() -> PybulletArm:
    return PybulletArm(RX, BASE)


@pytest.fixture(scope="module")
def numeric_arm() -> PybulletArm:
    return PybulletArm(RX, BASE, closed_form=False)


def _reference_refine(q0: np.ndarray, target: np.ndarray, rot: np.ndarray, tol_p: float,
                      tol_r: float, iterations: int) -> tuple[np.ndarray, bool]:
    """The Python loop of ``PybulletArm._refine`` before it was compiled (numpy LU solve,
    scipy near π), kept here as the independent reference."""
    lower, upper = RX.lower, RX.upper
    q = np.clip(np.array(q0, dtype=float), lower, upper)
    history: list[float] = []
    for it in range(iterations):
        pos, cur, jac = dh.fk_and_jacobian(RX, q, BASE)
        err = np.concatenate([target - pos, rotation_error(cur, rot)])
        if np.linalg.norm(err[:3]) <= tol_p and np.linalg.norm(err[3:]) <= tol_r:
            return q, True
        norm = float(np.linalg.norm(err))
        history.append(norm)
        if it >= 8 and norm > 0.7 * history[-6]:
            return q, False
        dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), err)
        step = float(np.max(np.abs(dq)))
        if step > 0.5:
            dq *= 0.5 / step
        q = q + dq
        for i in range(6):          # wrap by 2π into the limits, then clamp
            for k in (-1, 1, -2, 2):
                if lower[i] <= q[i] <= upper[i]:
                    break
                if lower[i] <= q[i] + k * 2.0 * math.pi <= upper[i]:
                    q[i] = q[i] + k * 2.0 * math.pi
                    break
        q = np.clip(q, lower, upper)
    return q, False


@pytest.mark.parametrize("angle", [1e-9, 1e-4, 0.3, 2.0, 2.9, 3.0])
def test_compiled_rotation_error_is_the_axis_angle(angle: float) -> None:
    axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
    r0 = dh.rot_x(0.4) @ dh.rot_z(-1.1)
    rot = Rotation.from_rotvec(angle * axis).as_matrix() @ r0
    out = np.empty(3)
    assert _ik_kernels.rotation_error(r0, rot, out)
    np.testing.assert_allclose(out, angle * axis, atol=1e-9)
    assert np.array_equal(out, rotation_error(r0, rot))          # bit for bit


def test_compiled_rotation_error_hands_angles_near_pi_back() -> None:
    r0 = dh.rot_x(0.4)
    rot = Rotation.from_rotvec([0.0, 3.13, 0.0]).as_matrix() @ r0      # cos = -0.99997
    out = np.full(3, 7.0)
    assert not _ik_kernels.rotation_error(r0, rot, out)
    assert np.all(out == 7.0)


def test_compiled_refine_is_the_python_loop_bit_for_bit(arm: PybulletArm) -> None:
    rng = np.random.default_rng(11)
    runs = converged = handed_back = 0
    for i in range(80):
        q = rng.uniform(RX.lower, RX.upper)
        pos, rot = dh.fk(RX, q, BASE)
        # small and large start errors: the tracking case, and starts beyond pi
        spread = 0.4 if i % 2 else 2.5
        start = np.clip(q + rng.normal(0.0, spread, 6), RX.lower, RX.upper)
        for iterations in (4, 60):
            ref, ok_ref = _reference_refine(start, pos, rot, 1e-6, 1e-6, iterations)
            got = arm._refine(start, pos, rot, 1e-6, 1e-6, iterations)
            assert (got is not None) == ok_ref
            if got is not None:
                # Decision: equal to 1e-12 rad, not bit for bit: on some CPUs LLVM contracts
                # a*b+c into one FMA in the compiled loop, NumPy does not (seen 2026-11-27)
                np.testing.assert_allclose(got, ref, rtol=0.0, atol=1e-12)
            _, status, _ = _ik_kernels.pose_dls(RX.table, RX.tcp, BASE, start, pos, rot,
                                                RX.lower, RX.upper, 1e-6, 1e-6, iterations,
                                                1e-6)
            runs += 1
            converged += ok_ref
            handed_back += status == _ik_kernels.NEEDS_PYTHON
    assert runs == 160 and 20 < converged < 160 and handed_back > 0   # every path exercised


def test_compiled_refine_final_configurations_equal_the_python_loop(arm: PybulletArm) -> None:
    rng = np.random.default_rng(12)
    for _ in range(40):
        q = rng.uniform(RX.lower, RX.upper)
        pos, rot = dh.fk(RX, q, BASE)
        start = np.clip(q + rng.normal(0.0, 0.3, 6), RX.lower, RX.upper)
        ref, ok_ref = _reference_refine(start, pos, rot, 1e-6, 1e-6, 60)
        got, status, _ = _ik_kernels.pose_dls(RX.table, RX.tcp, BASE, start, pos, rot,
                                              RX.lower, RX.upper, 1e-6, 1e-6, 60, 1e-6)
        if status != _ik_kernels.NEEDS_PYTHON:
            assert (status == _ik_kernels.REACHED) == ok_ref
            # the last iterate too, reached or not (1e-12 rad: FMA contraction, see above)
            np.testing.assert_allclose(got, ref, rtol=0.0, atol=1e-12)


def test_ik_round_trip_lands_on_the_pose(arm: PybulletArm, numeric_arm: PybulletArm) -> None:
    rng = np.random.default_rng(5)
    for a in (arm, numeric_arm):
        for q in rng.uniform(RX.lower, RX.upper, size=(25, 6)):
            pos, rot = dh.fk(RX, q, BASE)
            seed = np.clip(q + rng.normal(0.0, 0.05, 6), RX.lower, RX.upper)
            sol = a.ik(pos, rot, q_seed=seed)
            assert sol is not None and RX.within_limits(sol)
            p2, r2 = dh.fk(RX, sol, BASE)
            assert np.linalg.norm(p2 - pos) <= 1e-6
            assert np.linalg.norm(rotation_error(r2, rot)) <= 1e-6


def test_wrist_centres_of_reached_poses_are_inside() -> None:
    rng = np.random.default_rng(2)
    for q in rng.uniform(-math.pi, math.pi, size=(500, 6)):
        p, r = dh.fk(RX, q, BASE)
        assert closed_form_ik.wrist_centre_outside(RX, p, r, BASE) <= 1e-12


@settings(max_examples=60, deadline=None)
@given(st.lists(st.floats(-0.8, 0.8), min_size=3, max_size=3),
       st.lists(st.floats(-1.0, 1.0), min_size=4, max_size=4))
def test_a_wrist_centre_outside_means_no_solution(numeric_arm: PybulletArm,
                                                  offset: list[float], quat: list[float]
                                                  ) -> None:
    q4 = np.array(quat)
    if np.linalg.norm(q4) < 1e-3:
        q4 = np.array([0.0, 0.0, 0.0, 1.0])
    rot = BASE[:3, :3] @ Rotation.from_quat(q4 / np.linalg.norm(q4)).as_matrix()
    p = BASE[:3, 3] + np.array(offset)
    outside = closed_form_ik.wrist_centre_outside(RX, p, rot, BASE)
    empty = not closed_form_ik.puma_ik(RX, p, rot, BASE)
    if outside > 1e-9:
        assert empty
    if outside < -1e-9:
        assert not empty
    if outside > 1e-5:      # the numeric search from the closed form's seeds finds nothing
        assert numeric_arm.ik(p, rot, RX.home, restarts=4) is None
