"""The cycle's trajectory IK for every (robot, task point) pair in one compiled call (issue
#17 §4: batch the per-robot work across robots).

Each cycle the kernel solves IK at every predicted point of every evaluated pair (36 pairs
x 4 points for 8 robots and 6 task points), each point seeded with the previous one's
solution. An arm that describes the first attempt of its ``ik`` (:class:`FirstAttempt`,
from ``first_attempt()``: :class:`vasim.mrcp.arm.PybulletArm`) has those attempts made by
:func:`vasim.mrcp._ik_kernels.trajectory_ik` for all pairs at once; a point where the
attempt fails, and every later point of its pair, is left to the arm's own ``ik`` (closed
form, restarts), called by the kernel exactly as before. The first attempt is the same
compiled arithmetic ``ik`` runs, so every configuration is the one ``ik`` returns.

Example:
    >>> import numpy as np
    >>> from vasim.mrcp.arm import PybulletArm
    >>> from vasim.mrcp.dh import load_robot
    >>> arm = PybulletArm(load_robot("rx60b"))
    >>> pos, rot = arm.tcp_pose(arm.home)
    >>> q = arm.home + 0.01
    >>> req = TrajectoryRequest(arm, q, None, np.array([pos]), [rot])
    >>> (configs, solved), = solve_first_attempts([req])
    >>> bool(solved[0]) and bool(np.array_equal(configs[0], arm.ik(pos, rot, q)))
    True
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vasim.mrcp._ik_kernels import trajectory_ik
from vasim.mrcp.interfaces import ArmKinematics, FloatArray


@dataclass(frozen=True, eq=False)
class FirstAttempt:
    """What an arm's ``ik(position, rotation, q_seed)`` tries first, as data.

    Attributes:
        table: ``(4, n)`` modified DH table (alpha, a, d, theta offset).
        tcp: ``(3,)`` TCP in the last joint frame [m].
        base: ``(4, 4)`` world-from-base transform.
        lower, upper: ``(n,)`` joint limits [rad].
        pose_iterations: damped-least-squares steps for a full pose.
        position_iterations: steps for a position-only target.
        tol_position: [m]; tol_rotation: [rad] (``ik``'s defaults).
    """

    table: FloatArray
    tcp: FloatArray
    base: FloatArray
    lower: FloatArray
    upper: FloatArray
    pose_iterations: int
    position_iterations: int
    tol_position: float
    tol_rotation: float


@dataclass(frozen=True, eq=False)
class TrajectoryRequest:
    """One pair's trajectory: its arm, the seed of point 0, point 0's configuration when it
    is given (RSel: the measured one) and the targets ``(K+1, 3)`` [m] with their
    orientations (each ``(3, 3)`` or None for position only; all or none per pair)."""

    arm: ArmKinematics
    seed: FloatArray
    first: FloatArray | None
    positions: FloatArray
    rotations: Sequence[FloatArray | None]


def solve_first_attempts(requests: Sequence[TrajectoryRequest]
                         ) -> list[tuple[FloatArray, NDArray[np.bool_]] | None]:
    """Per request, ``(configs (K+1, n), solved (K+1,))`` from the compiled first attempts
    (a prefix of the points is solved; the rest is for the arm's ``ik``), or None for a
    request whose arm has no :class:`FirstAttempt`. Arms with the same joint count and
    tolerances share one compiled call."""
    out: list[tuple[FloatArray, NDArray[np.bool_]] | None] = [None] * len(requests)
    groups: dict[tuple[int, int, float, float, int, int], list[int]] = {}
    specs: dict[int, FirstAttempt] = {}
    for i, req in enumerate(requests):
        describe = getattr(req.arm, "first_attempt", None)
        spec = describe() if describe is not None else None
        if spec is None:
            continue
        specs[id(req.arm)] = spec
        key = (req.arm.n_joints, req.positions.shape[0], spec.tol_position, spec.tol_rotation,
               spec.pose_iterations, spec.position_iterations)
        groups.setdefault(key, []).append(i)
    for (n, npts, tol_p, tol_r, pose_it, pos_it), idx in groups.items():
        arms: dict[int, int] = {}
        for i in idx:
            arms.setdefault(id(requests[i].arm), len(arms))
        chain = [specs[a] for a in arms]
        count = len(idx)
        configs = np.full((count, npts, n), np.nan)
        solved = np.zeros((count, npts), dtype=np.bool_)
        rotations = np.zeros((count, npts, 3, 3))
        full_pose = np.zeros(count, dtype=np.bool_)
        first = np.zeros(count, dtype=np.bool_)
        for j, i in enumerate(idx):
            req = requests[i]
            if req.first is not None:
                first[j] = True
                configs[j, 0] = req.first
            if req.rotations[0] is not None:
                full_pose[j] = True
                rotations[j] = np.asarray(req.rotations, dtype=np.float64)
        trajectory_ik(
            np.ascontiguousarray([c.table for c in chain], dtype=np.float64),
            np.ascontiguousarray([c.tcp for c in chain], dtype=np.float64),
            np.ascontiguousarray([c.base for c in chain], dtype=np.float64),
            np.ascontiguousarray([c.lower for c in chain], dtype=np.float64),
            np.ascontiguousarray([c.upper for c in chain], dtype=np.float64),
            np.array([arms[id(requests[i].arm)] for i in idx], dtype=np.int64),
            np.ascontiguousarray([requests[i].seed for i in idx], dtype=np.float64),
            first, np.ascontiguousarray([requests[i].positions for i in idx],
                                        dtype=np.float64),
            rotations, full_pose, float(tol_p), float(tol_r), int(pose_it), int(pos_it),
            configs, solved)
        for j, i in enumerate(idx):
            out[i] = (configs[j], solved[j])
    return out
