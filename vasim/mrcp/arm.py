"""Robot arms over pybullet (:class:`PybulletArm`), implementing
:class:`~vasim.mrcp.interfaces.ArmKinematics`; the station is :mod:`vasim.mrcp.world`.

Every arm owns a private DIRECT client (never the GUI), so kinematic queries at sampled
configurations never disturb the poses of the station the proximity queries see.

**Decision** (per-query cost; the kernel calls FK and the Jacobian thousands of times per
18 ms cycle): :class:`PybulletArm` answers ``tcp_pose`` / ``jacobian`` from the compiled DH
chain of ``vasim.mrcp.dh`` by default (``kinematics="dh"``, about 3 µs a call), and from
pybullet with ``kinematics="pybullet"`` (``getLinkState`` / ``calculateJacobian``, 30-100 µs
a call). The tests hold the two to the same model: Jacobians agree to 1e-9 (measured 1e-15;
pybullet computes them in double precision), link frames to pybullet's reporting precision
(``getLinkState`` returns single-precision floats: about 3e-8 m measured). IK refines on the
compiled chain from the seed, with pybullet's ``calculateInverseKinematics`` among its
fallback starts. :meth:`PybulletArm.tcp_pose_batch` / :meth:`PybulletArm.jacobian_batch`
evaluate many sampled configurations at once (compiled). Joint states are written to
pybullet only when ``q`` changes, all joints in one call.

Example:
    >>> from vasim.mrcp.dh import load_robot
    >>> arm = PybulletArm(load_robot("rx60b"))
    >>> pos, rot = arm.tcp_pose(arm.home)
    >>> [round(float(v), 3) for v in pos]
    [0.31, 0.049, 0.225]
    >>> q = arm.ik(pos, rot, q_seed=arm.home)
    >>> bool(np.allclose(q, arm.home, atol=1e-6))
    True
"""

from __future__ import annotations

import contextlib
import math
import os
import sys
from collections.abc import Iterator, Sequence
from typing import Literal

import numpy as np
import pybullet as pb
from scipy.stats import qmc

from vasim.core import geometry
from vasim.core.config import check_choice
from vasim.core.kernel_args import readonly_c, writable_c
from vasim.mrcp import _ik_kernels, closed_form_ik, dh
from vasim.mrcp.batch_ik import FirstAttempt
from vasim.mrcp.dh import RobotModel
from vasim.mrcp.interfaces import FloatArray
from vasim.mrcp.urdf import write_urdf


@contextlib.contextmanager
def _quiet_stdout() -> Iterator[None]:
    """Silences C-level writes to stdout (pybullet prints its build time on connect)."""
    try:
        fd = sys.stdout.fileno()
    except (OSError, ValueError, AttributeError):   # captured stdout (pytest, notebooks)
        yield
        return
    sys.stdout.flush()
    saved = os.dup(fd)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), fd)
        try:
            yield
        finally:
            sys.stdout.flush()
            os.dup2(saved, fd)
            os.close(saved)


class _Client:
    """One private pybullet DIRECT client, disconnected when closed or collected."""

    def __init__(self) -> None:
        with _quiet_stdout():
            self.id = pb.connect(pb.DIRECT)
        if self.id < 0:
            raise RuntimeError("pybullet could not open a DIRECT client")

    def close(self) -> None:
        if self.id >= 0:
            with contextlib.suppress(pb.error):
                pb.disconnect(physicsClientId=self.id)
            self.id = -1

    def __del__(self) -> None:
        self.close()


def pose_matrix(position: FloatArray | None = None, rotation: FloatArray | None = None
                ) -> FloatArray:
    """``(4, 4)`` homogeneous transform from a position ``(3,)`` and rotation ``(3, 3)``."""
    return geometry.homogeneous(rotation, position)


def _quat(rotation: FloatArray) -> list[float]:
    return [float(v) for v in geometry.to_xyzw(geometry.quat_from_matrix(rotation))]  # xyzw


def _rot(quat: Sequence[float]) -> FloatArray:
    return geometry.matrix_from_quat(geometry.from_xyzw(quat))


def _load_robot(client: int, robot: RobotModel, base: FloatArray) -> int:
    path = write_urdf(robot)
    with _quiet_stdout():
        body = pb.loadURDF(str(path), basePosition=[float(v) for v in base[:3, 3]],
                           baseOrientation=_quat(base[:3, :3]), useFixedBase=True,
                           flags=pb.URDF_USE_INERTIA_FROM_FILE, physicsClientId=client)
    if pb.getNumJoints(body, physicsClientId=client) != robot.n_joints + 1:
        raise RuntimeError(f"URDF of {robot.name} loaded with an unexpected joint count")
    return body


rotation_error = geometry.rotvec_between
"""Axis-angle vector ``(3,)`` [rad], world frame, turning ``current`` into ``target``
(``rotation_error(current, target)``; the log map lives in ``vasim.core.geometry``)."""


class PybulletArm:
    """One serial arm (an :class:`~vasim.mrcp.interfaces.ArmKinematics`) on its own client.

    Args:
        robot: the DH model.
        base: ``(4, 4)`` world-from-base transform (default identity).
        name: the arm's name (default: the model's).
        kinematics: ``"dh"`` (compiled DH chain, default) or ``"pybullet"`` for
            ``tcp_pose`` and ``jacobian`` (see the module docstring).
        closed_form: use the closed-form IK when the arm has the PUMA structure (default);
            False forces the numeric search (for comparisons).
    """

    def __init__(self, robot: RobotModel, base: FloatArray | None = None,
                 name: str | None = None, kinematics: Literal["dh", "pybullet"] = "dh",
                 closed_form: bool = True) -> None:
        check_choice(kinematics, "kinematics", ("dh", "pybullet"))
        self.kinematics = kinematics
        self.robot = robot
        self.name = name or robot.name
        self.base = pose_matrix() if base is None else np.array(base, dtype=float)
        self._client = _Client()
        self._cid = self._client.id
        self._body = _load_robot(self._cid, robot, self.base)
        self._n = robot.n_joints
        self._tcp_link = self._n
        self._q: FloatArray | None = None
        self._zeros = [0.0] * self._n
        self._lower = [float(v) for v in robot.lower]
        self._upper = [float(v) for v in robot.upper]
        self._ranges = [u - lo for lo, u in zip(self._lower, self._upper, strict=True)]
        # IK: reach bound from the shoulder (frame 1's origin, fixed) and spread restarts
        self._shoulder = (self.base @ dh.joint_origin(robot.joints[0]))[:3, 3]
        self._reach = sum(float(np.linalg.norm(dh.joint_origin(j)[:3, 3]))
                          for j in robot.joints[1:]) + float(np.linalg.norm(robot.tcp)) + 1e-9
        self._closed_form = closed_form and closed_form_ik.is_puma_like(robot)
        self._offsets = robot.table[3]
        self._tcp_norm = float(np.linalg.norm(robot.tcp))
        self._first: FirstAttempt | None = None
        unit = qmc.Halton(d=self._n, scramble=True, seed=1).random(64)
        self._spread = robot.lower + unit * (robot.upper - robot.lower)

    # -- ArmKinematics -----------------------------------------------------------------
    @property
    def n_joints(self) -> int:
        return self._n

    @property
    def joint_lower(self) -> FloatArray:
        return self.robot.lower

    @property
    def joint_upper(self) -> FloatArray:
        return self.robot.upper

    @property
    def max_velocity(self) -> FloatArray:
        return self.robot.max_velocity

    @property
    def max_acceleration(self) -> FloatArray:
        return self.robot.max_acceleration

    @property
    def home(self) -> FloatArray:
        return self.robot.home

    def _set(self, q: FloatArray) -> None:
        q = np.asarray(q, dtype=float)
        if q.shape != (self._n,):
            raise ValueError(f"{self.name}: q must have shape ({self._n},), got {q.shape}")
        if self._q is not None and np.array_equal(q, self._q):
            return
        pb.resetJointStatesMultiDof(self._body, list(range(self._n)),
                                    targetValues=[[float(v)] for v in q],
                                    physicsClientId=self._cid)
        self._q = q.copy()

    def tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """TCP position ``(3,)`` [m] and rotation ``(3, 3)`` (world frame)."""
        if self.kinematics == "dh":
            return dh.fk(self.robot, q, self.base)
        return self.pybullet_tcp_pose(q)

    def jacobian(self, q: FloatArray) -> FloatArray:
        """``(6, n)`` geometric TCP Jacobian (world frame, linear rows first)."""
        if self.kinematics == "dh":
            return dh.jacobian(self.robot, q, self.base)
        return self.pybullet_jacobian(q)

    def pybullet_tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """TCP pose by pybullet's ``getLinkState`` (single-precision output)."""
        self._set(q)
        st = pb.getLinkState(self._body, self._tcp_link, computeForwardKinematics=1,
                             physicsClientId=self._cid)
        return np.array(st[4]), _rot(st[5])

    def pybullet_jacobian(self, q: FloatArray) -> FloatArray:
        """TCP Jacobian by pybullet's ``calculateJacobian`` (which expresses it in the base
        frame: rotated here to the world)."""
        self._set(q)
        lin, ang = pb.calculateJacobian(self._body, self._tcp_link, [0.0, 0.0, 0.0],
                                        [float(v) for v in q], self._zeros, self._zeros,
                                        physicsClientId=self._cid)
        r = self.base[:3, :3]
        return np.vstack([r @ np.array(lin), r @ np.array(ang)])

    def tcp_pose_batch(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """TCP positions ``(m, 3)`` and rotations ``(m, 3, 3)`` for ``(m, n)`` samples
        (numpy DH kinematics, identical to :meth:`tcp_pose` to 1e-9)."""
        return dh.fk_batch(self.robot, q, self.base)

    def dh_chain(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        """The compiled DH chain behind :meth:`jacobian_batch` / :meth:`tcp_pose_batch`:
        ``(table, tcp, base)`` as ``vasim.mrcp.dh``'s kernels take them (``base`` ``(4, 4)``,
        world frame), for indices that evaluate many configurations in one compiled call."""
        return (self.robot.table, self.robot.tcp,
                np.ascontiguousarray(self.base, dtype=float))

    def first_attempt(self) -> FirstAttempt | None:
        """What :meth:`ik` tries first with a seed and its default tolerances, as data
        (:mod:`vasim.mrcp.batch_ik` makes those attempts for many trajectories in one
        compiled call): damped least squares from the seed, 4 full-pose steps on a
        PUMA-like arm (60 otherwise), 60 position-only steps. None for a subclass that
        overrides :meth:`ik` (its first attempt is unknown here)."""
        if type(self).ik is not PybulletArm.ik:
            return None
        if self._first is None:
            self._first = FirstAttempt(
                self.robot.table, self.robot.tcp, np.ascontiguousarray(self.base, dtype=float),
                self.robot.lower, self.robot.upper, 4 if self._closed_form else 60, 60,
                1e-6, 1e-6)
        return self._first

    def jacobian_batch(self, q: FloatArray) -> FloatArray:
        """``(m, 6, n)`` TCP Jacobians for ``(m, n)`` samples (numpy DH kinematics)."""
        return dh.jacobian_batch(self.robot, np.atleast_2d(q), self.base)

    def link_frames(self, q: FloatArray) -> FloatArray:
        """``(..., n + 2, 4, 4)`` world frames of base, joints and TCP (numpy)."""
        return dh.link_frames(self.robot, q, self.base)

    def ik(self, position: FloatArray, rotation: FloatArray | None = None,
           q_seed: FloatArray | None = None, *, tol_position: float = 1e-6,
           tol_rotation: float = 1e-6, restarts: int = 16) -> FloatArray | None:
        """A configuration within the joint limits reaching the pose, or None.

        Arms with the PUMA structure (the RX60B) and a full pose: up to four Newton steps
        from ``q_seed`` (tracking a small task increment, ~50 µs), else the closed form
        (:func:`vasim.mrcp.closed_form_ik.puma_ik`, all 8 solutions) wrapped into the
        limits, the one closest to ``q_seed`` returned; no in-limit solution -> None
        (exact, ~0.1 ms).
        Otherwise (other arms, position-only targets, wrist singularities): damped least
        squares on the compiled DH chain, projected into the joint limits at every step
        (joints wrapped by 2π, then clamped), started from ``q_seed`` (the nearest branch
        when the target moved a little: the kernel's tracking case); for a position-only
        target on a PUMA-like arm next the closed form with the seed's orientation; then
        pybullet's ``calculateInverseKinematics`` (joint limits, rest pose = the seed), the
        home configuration, and ``restarts`` fixed configurations spread over the joint
        space (scrambled Halton). A start is abandoned when its error stops shrinking.
        Targets beyond the chain's reach return None at once.

        Costs of the numeric path (RX60B, one core): tracking ~0.1 ms; an arbitrary
        reachable pose from home ~1.5 ms (no failure in 200 random in-limit poses); an
        unreachable orientation within reach ~10 ms with the default ``restarts``.

        Args:
            position: ``(3,)`` TCP target [m], world frame.
            rotation: ``(3, 3)`` TCP target orientation (world frame), or None for a
                position-only solve (the minimum-norm steps keep the orientation near the
                seed's).
            q_seed: ``(n,)`` start / preferred configuration (default: home).
            restarts: how many spread configurations to try after the first three starts.
        """
        # inputs validated up front: a NaN seed made pybullet's IK loop forever, a NaN
        # rotation surfaced as an opaque LinAlgError deep in the solver
        target = np.asarray(position, dtype=float)
        if target.shape != (3,) or not math.isfinite(float(target.sum())):
            if target.shape != (3,) or not np.all(np.isfinite(target)):
                raise ValueError(f"{self.name}: position must be 3 finite numbers, got "
                                 f"{position!r}")
        rot = None if rotation is None else np.asarray(rotation, dtype=float)
        if rot is not None and (rot.shape != (3, 3) or not np.all(np.isfinite(rot))):
            raise ValueError(f"{self.name}: rotation must be a finite (3, 3) matrix, got "
                             f"{rotation!r}")
        if q_seed is not None:
            q_seed = np.asarray(q_seed, dtype=float)
            if q_seed.shape != (self._n,) or not np.all(np.isfinite(q_seed)):
                raise ValueError(f"{self.name}: q_seed must be {self._n} finite angles, got "
                                 f"{q_seed!r}")
        dx, dy, dz = (target - self._shoulder).tolist()
        if math.sqrt(dx * dx + dy * dy + dz * dz) > self._reach:
            return None
        seed = self.robot.home if q_seed is None else q_seed
        seed = np.clip(seed, self.robot.lower, self.robot.upper)
        if rot is not None and self._closed_form:
            if q_seed is not None:      # tracking: a few Newton steps from the seed suffice
                q = self._refine(seed, target, rot, tol_position, tol_rotation, iterations=4)
                if q is not None:
                    return q
            q, complete = self._closed_form_ik(target, rot, seed, tol_position, tol_rotation)
            if q is not None or complete:
                return q
            # **Decision** (issue #17 §5, cost): no numeric search where none can succeed:
            # a wrist centre outside the reachable set by more than the tolerances allow
            # (see closed_form_ik.wrist_centre_outside) has no solution; the search (18
            # starts, pybullet's among them) was ~1 ms per such pose, several a cycle
            slack = 2.0 * (tol_position + self._tcp_norm * tol_rotation) + 1e-9
            if closed_form_ik.wrist_centre_outside(self.robot, target, rot, self.base) > slack:
                return None
        q = self._refine(seed, target, rot, tol_position, tol_rotation)
        if q is not None:
            return q
        if rot is None and self._closed_form:      # keep the seed's orientation
            q, _ = self._closed_form_ik(target, dh.fk(self.robot, seed, self.base)[1], seed,
                                        tol_position, tol_rotation)
            if q is not None:
                return q
        starts = [self._pybullet_guess(target, rot, seed), self.robot.home,
                  *self._spread[:max(0, restarts)]]
        for start in starts:
            q = self._refine(start, target, rot, tol_position, tol_rotation)
            if q is not None:
                return q
        return None

    def _closed_form_ik(self, target: FloatArray, rot: FloatArray, seed: FloatArray,
                        tol_p: float, tol_r: float) -> tuple[FloatArray | None, bool]:
        """The in-limit closed-form solution closest to the seed, and whether the closed
        form enumerated every solution (False at a wrist singularity, where a continuum
        exists and only one split of theta4 + theta6 was tried; False with no candidate
        at all, since ``ik`` only calls this within reach: an empty closed form there may
        be round-off at a boundary, so the numeric search must still run)."""
        lower, upper = self.robot.lower, self.robot.upper
        cands = closed_form_ik.puma_ik(self.robot, target, rot, self.base)
        if not cands:       # all([]) would be True and skip the numeric fallback
            return None, False
        complete = all(abs(math.sin(c[4] + self._offsets[4])) > 1e-9 for c in cands)
        wrapped = closed_form_ik.wrap_into_batch(np.array(cands), lower, upper, seed)
        fits = ~np.isnan(wrapped[:, 0])
        if not np.any(fits):
            return None, complete
        wrapped = wrapped[fits]
        best = wrapped[int(np.argmin(np.linalg.norm(wrapped - seed, axis=1)))]
        pos, cur = dh.fk(self.robot, best, self.base)
        if (np.linalg.norm(pos - target) > tol_p
                or np.linalg.norm(rotation_error(cur, rot)) > tol_r):
            best = self._refine(best, target, rot, tol_p, tol_r)   # polish round-off
        return best, complete

    def _pybullet_guess(self, target: FloatArray, rot: FloatArray | None,
                        seed: FloatArray) -> FloatArray:
        self._set(np.clip(seed, self.robot.lower, self.robot.upper))
        kwargs = {"lowerLimits": self._lower, "upperLimits": self._upper,
                  "jointRanges": self._ranges, "restPoses": [float(v) for v in seed],
                  "maxNumIterations": 50, "residualThreshold": 1e-8,
                  "physicsClientId": self._cid}
        if rot is not None:
            kwargs["targetOrientation"] = _quat(rot)
        q = pb.calculateInverseKinematics(self._body, self._tcp_link,
                                          [float(v) for v in target], **kwargs)
        return np.array(q[:self._n], dtype=float)

    def _refine(self, q0: FloatArray, target: FloatArray, rot: FloatArray | None,
                tol_p: float, tol_r: float, iterations: int = 60) -> FloatArray | None:
        """Damped least squares from ``q0`` on the compiled DH chain: position only
        (:func:`vasim.mrcp.dh.position_dls`) or the full pose
        (:func:`vasim.mrcp._ik_kernels.pose_dls`); None when it stagnates or runs out of
        ``iterations``.

        **Decision** (issue #17 §5, cost): the full-pose iteration is compiled, with the
        Python loop's arithmetic bit for bit (the same BLAS products and LAPACK solve), so
        every run is unchanged; about 2 µs a step instead of 40 µs (the 8-robot scenario
        spent 80 % of its cycle in the Python loop). A step whose rotation error is near π
        (scipy's route in :func:`rotation_error`) is made here in Python
        (:meth:`_python_step`) and the compiled loop resumes after it.
        """
        if rot is None:     # the same iteration, compiled (dh.position_dls)
            return dh.position_dls(self.robot, q0, target, self.base, tol_p, iterations)
        history = np.empty(iterations)
        q, target, rot = writable_c(q0), writable_c(target), writable_c(rot)
        base = writable_c(self.base)
        lower, upper = readonly_c(self.robot.lower), readonly_c(self.robot.upper)
        it = 0
        while True:
            q, status, it = _ik_kernels.pose_dls(
                self.robot.table, self.robot.tcp, base, q, target, rot, lower, upper,
                float(tol_p), float(tol_r), int(iterations), 1e-6, it, history)
            if status != _ik_kernels.NEEDS_PYTHON:
                return q if status == _ik_kernels.REACHED else None
            q, status = self._python_step(q, target, rot, tol_p, tol_r, it, history)
            if status != _ik_kernels.NEEDS_PYTHON:      # decided at that step
                return q if status == _ik_kernels.REACHED else None
            it += 1
            if it >= iterations:
                return None

    def _python_step(self, q: FloatArray, target: FloatArray, rot: FloatArray, tol_p: float,
                     tol_r: float, it: int, history: FloatArray) -> tuple[FloatArray, int]:
        """Step ``it`` of :meth:`_refine` in Python (any rotation error): ``(q, REACHED)``,
        ``(q, FAILED)`` (stagnating) or the next configuration and ``NEEDS_PYTHON`` (go on);
        ``history[it]`` is filled."""
        pos, cur, jac = dh.fk_and_jacobian(self.robot, q, self.base)
        err = np.concatenate([target - pos, rotation_error(cur, rot)])
        if np.linalg.norm(err[:3]) <= tol_p and np.linalg.norm(err[3:]) <= tol_r:
            return q, _ik_kernels.REACHED
        norm = float(np.linalg.norm(err))
        history[it] = norm
        if it >= 8 and norm > 0.7 * history[it - 5]:     # stagnating: give this start up
            return q, _ik_kernels.FAILED
        dq = jac.T @ np.linalg.solve(jac @ jac.T + 1e-6 * np.eye(6), err)
        step = float(np.max(np.abs(dq)))
        if step > 0.5:
            dq *= 0.5 / step
        return dh.wrap_clip(q + dq, self.robot.lower, self.robot.upper), _ik_kernels.NEEDS_PYTHON

    def close(self) -> None:
        self._client.close()
