"""One MRCP control cycle: evaluate, decide, act (spec/mrcp.md §§3-8, seed chapter 4).

The kernel sees robots only through :class:`~vasim.mrcp.interfaces.ArmKinematics` and the
station through :class:`~vasim.mrcp.interfaces.ProximityWorld`; it never sees a device
protocol. Each call of :meth:`MRCPKernel.step` is one evaluation period (18 ms default):

1. **Observe**: measured configurations are read from the world (the workspace sensors);
   the *increment* of the operator's task pose since the last cycle is applied in TOp and
   discarded in TT (the master is decoupled while the task is held, as with a clutch).
2. **Predict** (§3): the world positions of every task point are extrapolated ``K`` points
   ahead (one fit for all points), the task orientation likewise.
3. **Evaluate** (§4): RSel at CuTP and every candidate at every other task point, with
   every configured index, on an :class:`~vasim.mrcp.indices.EvalContext` built once per
   (robot, point); group indices (CR) are normalised across the cycle.
4. **Time** (§5-6): ``texec`` per index and its minimum, ``ttransf*`` of the candidates,
   ``tus``; RCnt by Algorithm 1; NTT against the threshold.
5. **Act** (§7, Algorithm 2): RSel follows the task (never into a collision: that is the
   ``RSEL_COLLISION`` safety stop); the candidates, in order of decreasing ``tus``, move
   toward the pre-grasp pose of their best point with the guidance displacement, each
   one's new pose an obstacle for the next. In TT, RCnt approaches, grasps, then RSel
   releases and the roles swap (:mod:`vasim.mrcp.modes`).

The kernel poses its world at the commanded configurations (its model of the station);
a robot driver sends :attr:`CycleRecord.commands` to the controllers.

**Decisions**:

* A candidate is evaluated as if it held the task at the point: ``configs[0]`` is IK of the
  point's current pose; an unreachable current pose scores 0 on every index.
* Predicted points are ``stride`` cycles apart so the RJ error ``e_k`` compares a
  prediction with the measurement it predicted.
* RSel does not follow a task increment it cannot perform (IK fails, joint speed above its
  limit, or a collision): the task is held where it is (the achieved task pose, not the
  commanded one, feeds the predictor). A collision with an obstacle, a robot holding the
  task or itself also raises the safety stop; a step blocked only by robots that do not
  hold the task (candidates, which move themselves and never into RSel) is a hold
  (``rsel_hold ... blocked by``), so the hold rule hands the task over (issue #26 §4:
  ``eight_robots`` stopped at 36 s when the new RSel, R7, turning the cube, met its
  waiting neighbour R0 -- nothing was in collision, the step was refused).
* A transfer that has not completed within ``tt_timeout`` is aborted (back to TOp, roles
  unchanged) and that (robot, point) sits out ``abort_cooldown``; RCnt's final approach to
  the grasp ignores repulsion (collision checks stay) and, once within
  ``grasp_tolerance``, closing the gripper centres it on the grasp pose.
* ``texec`` needs ``texec_min_samples`` values of a series (a fit through fewer
  extrapolates noise); a series restarts after a gap (the TT cycles are not evaluated).
* The transfer event names its cause: the index with the smallest ``texec`` of RSel
  (``hold`` when RSel could not follow the task for ``hold_transfer_s``, see
  :class:`KernelConfig`).

Cost options for arms or worlds with expensive queries: ``trajectory_ik="linear"`` and
``distance_points="ends"`` (see :class:`KernelConfig`); ``bench/mrcp.py`` prints both.

Example:
    A candidate takes over a task that its holder must not continue (a plug-in index):

    >>> import numpy as np
    >>> from vasim.mrcp.interfaces import Proximity
    >>> class Point:                       # a 3-DoF Cartesian "arm" (TCP = q)
    ...     def __init__(self, name): self.name = name
    ...     n_joints = 3
    ...     joint_lower = np.full(3, -1.0); joint_upper = np.full(3, 1.0)
    ...     max_velocity = np.full(3, 1.0); max_acceleration = np.full(3, 10.0)
    ...     def tcp_pose(self, q): return np.array(q, float), np.eye(3)
    ...     def jacobian(self, q): return np.vstack([np.eye(3), np.zeros((3, 3))])
    ...     def ik(self, p, rotation=None, q_seed=None):
    ...         return np.array(p, float) if np.all(np.abs(p) <= 1.0) else None
    >>> class Empty:                       # a world with nothing to hit
    ...     def __init__(self): self.q = {"a": np.zeros(3), "b": np.array([0.3, 0, 0])}
    ...     def robot_names(self): return list(self.q)
    ...     def obstacle_names(self): return []
    ...     def set_configuration(self, r, q): self.q[r] = np.array(q, float)
    ...     def configuration(self, r): return self.q[r].copy()
    ...     def min_distance(self, a, b, max_distance=1.0):
    ...         nan = np.full(3, np.nan); return Proximity(max_distance, nan, nan)
    ...     def in_collision(self, r): return False
    >>> class NotA:
    ...     name = "not_a"
    ...     def evaluate(self, ctx): return 0.0 if ctx.robot == "a" else 1.0
    >>> points = [TaskPoint(np.zeros(3)), TaskPoint(np.array([0.1, 0.0, 0.0]))]
    >>> k = MRCPKernel({"a": Point("a"), "b": Point("b")}, Empty(), points, "a", 0,
    ...                np.zeros(3), parts=KernelParts(indices=[NotA()]))
    >>> events = [e for i in range(30) for e in k.step((i + 1) * 0.018, np.zeros(3)).events]
    >>> for e in events:
    ...     print(e.split(" (")[0])
    transfer_start b@1
    transfer_pregrasp b@1
    transfer_grasped b@1
    transfer_done a -> b@1
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.core.geometry import rotvec_between, vector_norm
from vasim.mrcp.batch_ik import TrajectoryRequest, solve_first_attempts
from vasim.mrcp.indices import INDICES, EvalContext, GroupIndex, Index, Wrench
from vasim.mrcp.indices.base import (
    NearestQuery,
    prefetch_distances,
    prefetch_distances_all,
)
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld
from vasim.mrcp.kernel_config import IndexSpec as IndexSpec
from vasim.mrcp.kernel_config import KernelConfig as KernelConfig
from vasim.mrcp.modes import KernelEvent, KernelState, next_state
from vasim.mrcp.planner import Mover, ObstacleMemory, move_candidate
from vasim.mrcp.predict import PolynomialPredictor, Predictor, predict_rotations
from vasim.mrcp.select import Assignment, candidate_hierarchy
from vasim.mrcp.timefx import Continuity, continuity_robot, estimate_transfer, texec_many

FloatArray = NDArray[np.float64]
Key = tuple[str, int]


@dataclass(frozen=True)
class TaskPoint:
    """A grasp point of the task (object, needle, tool), in the task frame.

    Attributes:
        position: ``(3,)`` [m] in the task frame.
        rotation: ``(3, 3)`` gripper orientation in the task frame, or None (position-only:
            IK is asked for the position alone).
        approach: ``(3,)`` pre-grasp offset [m] in the task frame (grasp + approach).
    """

    position: FloatArray
    rotation: FloatArray | None = None
    approach: FloatArray = field(default_factory=lambda: np.zeros(3))


@dataclass
class Evaluation:
    """Per-(robot, point) results of one cycle (for plots and the event log)."""

    values: dict[str, float]
    texec: dict[str, float]
    texec_min: float
    ttransf: float
    tus: float


@dataclass
class CycleRecord:
    """What one cycle decided.

    Attributes:
        t: cycle time [s].
        state: kernel state after the cycle.
        rsel, cutp: the robot holding the task and its point (after the cycle).
        holders: robots grasping the task after the cycle (never empty).
        task_position, task_rotation: the achieved task pose after the cycle.
        commands: robot -> commanded configuration.
        evaluations: (robot, point) -> :class:`Evaluation` (TOp cycles only).
        continuity: RCnt and NTT (TOp cycles only).
        rcnt, target: the transfer's receiving robot and point (during TT).
        events: what happened, e.g. ``"transfer_start r2@3 (ntt=0.93, rj)"``.
    """

    t: float
    state: KernelState
    rsel: str
    cutp: int
    holders: tuple[str, ...]
    task_position: FloatArray
    task_rotation: FloatArray | None
    commands: dict[str, FloatArray]
    evaluations: dict[Key, Evaluation]
    continuity: Continuity | None
    rcnt: str | None
    target: int | None
    events: list[str]


def _linear_step(arm: ArmKinematics, q: FloatArray, dp: FloatArray,
                 r0: FloatArray | None, r1: FloatArray | None) -> FloatArray | None:
    """First-order IK step ``q + J⁺ Δx`` (translation, plus rotation when given); None when
    it leaves the joint limits."""
    jac = arm.jacobian(q)
    if r0 is None or r1 is None:
        dq = np.linalg.pinv(jac[:3], rcond=1e-6) @ dp
    else:
        dw = rotvec_between(r0, r1)   # the log map of r1 r0^T (closed form, as the arm IK's)
        dq = np.linalg.pinv(jac, rcond=1e-6) @ np.concatenate([dp, dw])
    out = q + dq
    if np.any(out < arm.joint_lower) or np.any(out > arm.joint_upper):
        return None
    return out


@dataclass(frozen=True)
class KernelParts:
    """Instances an ``MRCPKernel`` uses instead of building them from its config (tests,
    custom indices).

    Attributes:
        predictor: trajectory predictor (None: least squares, ``config.predictor_degree``).
        indices: index instances (None: created from ``config.indices``).
    """

    predictor: Predictor | None = None
    indices: Sequence[Index] | None = None


class MRCPKernel:
    """The MRCP control kernel over a set of arms and a proximity world.

    Args:
        arms: robot name -> kinematics (names as in ``world``).
        world: the station, posed at the robots' current configurations.
        task_points: the task's grasp points (task frame).
        rsel: the robot holding the task at start.
        cutp: the task point it holds.
        task_position, task_rotation: the task pose at start (world frame).
        config: kernel parameters.
        parts: a predictor and index instances to use instead of those ``config`` names
            (``KernelParts``; default: none).

    Raises:
        ValueError: when a name or index is inconsistent.
    """

    def __init__(self, arms: Mapping[str, ArmKinematics], world: ProximityWorld,
                 task_points: Sequence[TaskPoint], rsel: str, cutp: int,
                 task_position: FloatArray, task_rotation: FloatArray | None = None,
                 config: KernelConfig | None = None, parts: KernelParts | None = None,
                 t0: float = 0.0) -> None:
        self.config = config or KernelConfig()
        self.arms = dict(arms)
        self.world = world
        if rsel not in self.arms:
            raise ValueError(f"rsel {rsel!r} is not one of the arms {sorted(self.arms)}")
        missing = set(self.arms) - set(world.robot_names())
        if missing:
            raise ValueError(f"arms {sorted(missing)} are not robots of the world")
        if not 0 <= cutp < len(task_points):
            raise ValueError(f"cutp {cutp!r} is not a task point index (0..{len(task_points)-1})")
        self.task_points = list(task_points)
        parts = parts or KernelParts()
        self.predictor = parts.predictor or PolynomialPredictor(self.config.predictor_degree)
        self.indices: list[Index] = (list(parts.indices) if parts.indices is not None else
                                     [INDICES.create(s.name, **dict(s.params))
                                      for s in self.config.indices])
        self._groups: list[GroupIndex] = [ix for ix in self.indices
                                          if isinstance(ix, GroupIndex)]
        self.state = KernelState.TOP
        self.rsel = rsel
        self.cutp = cutp
        self.holders: tuple[str, ...] = (rsel,)
        self.rcnt: str | None = None
        self.target: int | None = None
        self._tt_start = 0.0
        self._grasp_count = 0
        self._rng = np.random.default_rng(self.config.seed)
        self._memory = ObstacleMemory()
        w = self.config.window
        self._times: deque[float] = deque([t0], maxlen=w)
        rot0 = np.eye(3) if task_rotation is None else np.asarray(task_rotation, dtype=float)
        self._has_rotation = task_rotation is not None
        self._positions: deque[FloatArray] = deque([np.asarray(task_position, float)], maxlen=w)
        self._rotations: deque[FloatArray] = deque([rot0], maxlen=w)
        self._last_cmd: tuple[FloatArray, FloatArray] = (self._positions[-1].copy(), rot0)
        self._tp_local = np.array([tp.position for tp in self.task_points], dtype=float)
        self._cycle_times: deque[float] = deque(maxlen=self.config.texec_window)
        self._index_hist: dict[tuple[str, int, str], deque[tuple[float, float]]] = {}
        self._pred_hist: dict[Key, deque[FloatArray]] = {}
        self._last_eval_t: float | None = None
        self._last_q = {r: world.configuration(r).copy() for r in self.arms}
        self._seeds: dict[Key, FloatArray] = {}
        self._last_goals: dict[Key, float] = {}
        self._cooldown: dict[Key, float] = {}
        self._held_since: float | None = None   # RSel has not followed the task since
        self._t_now = 0.0
        self._tt_cause = ""

    # ------------------------------------------------------------------ geometry helpers
    def task_pose(self) -> tuple[FloatArray, FloatArray | None]:
        """The achieved task pose (position, rotation or None)."""
        return self._positions[-1].copy(), (self._rotations[-1].copy()
                                            if self._has_rotation else None)

    def point_pose(self, q: int, position: FloatArray, rotation: FloatArray
                   ) -> tuple[FloatArray, FloatArray | None]:
        """World pose of task point ``q`` for a task pose."""
        tp = self.task_points[q]
        pos = position + rotation @ tp.position
        rot = rotation @ tp.rotation if tp.rotation is not None else None
        return pos, rot

    def pregrasp(self, q: int, position: FloatArray, rotation: FloatArray
                 ) -> tuple[FloatArray, FloatArray | None]:
        pos, rot = self.point_pose(q, position, rotation)
        return pos + rotation @ self.task_points[q].approach, rot

    # ------------------------------------------------------------------ the cycle
    def step(self, t: float, task_position: FloatArray, task_rotation: FloatArray | None = None,
             wrench: Wrench | None = None, extras: Mapping[str, Any] | None = None
             ) -> CycleRecord:
        """Run one control cycle at time ``t`` with the operator's task pose.

        Args:
            t: cycle time [s] (increasing).
            task_position: ``(3,)`` commanded task position [m] (held during TT).
            task_rotation: ``(3, 3)`` commanded task orientation (None: keep the current).
            wrench: force-torque reading at the task, if any.
            extras: scenario data passed to the indices.
        """
        if self._times and not t > self._times[-1]:
            raise ValueError(f"MRCPKernel.step: t = {t!r} is not after the last cycle's "
                             f"t = {self._times[-1]!r} (cycle times must increase)")
        events: list[str] = []
        q_meas = {r: self.world.configuration(r).copy() for r in self.arms}
        qdot = {r: (q_meas[r] - self._last_q[r]) / self.config.dt for r in self.arms}
        evaluations: dict[Key, Evaluation] = {}
        continuity: Continuity | None = None
        if self.state is KernelState.FAULT:
            # The operator's input is tracked, not stored up: after reset_fault() the task
            # follows from where the master is then, not by the motion made during the stop.
            self._last_cmd = (np.asarray(task_position, float),
                              np.asarray(task_rotation, float) if task_rotation is not None
                              else self._last_cmd[1])
            self._last_q = q_meas
            return self._record(t, q_meas, evaluations, None, ["fault: no motion"])
        pos_now, rot_now = self._positions[-1], self._rotations[-1]
        self._t_now = t
        if self.state is KernelState.TOP:
            evaluations = self._evaluate(t, q_meas, qdot, wrench, extras or {})
            continuity = self._decide(t, evaluations)
            if continuity.transfer:
                self.state = next_state(self.state, KernelEvent.START_TRANSFER)
                self.rcnt, self.target = continuity.robot, continuity.point
                self._tt_start = t
                cause = min(evaluations[(self.rsel, self.cutp)].texec.items(),
                            key=lambda kv: kv[1])[0]
                self._tt_cause = cause
                events.append(f"transfer_start {self.rcnt}@{self.target} "
                              f"(ntt={continuity.ntt:.2f}, cause={cause})")
        # Act: RSel follows the operator in TOp; the task is held in TT.
        new_pos, new_rot = pos_now, rot_now
        cmd_pos = np.asarray(task_position, float)
        cmd_rot = (np.asarray(task_rotation, float) if task_rotation is not None
                   else self._last_cmd[1])
        if self.state is KernelState.TOP:
            goal_pos = pos_now + (cmd_pos - self._last_cmd[0])
            goal_rot = cmd_rot @ self._last_cmd[1].T @ rot_now
            if self._follow(goal_pos, goal_rot, q_meas, events):
                new_pos, new_rot = goal_pos, goal_rot
        self._last_cmd = (cmd_pos, cmd_rot)
        if self.state is not KernelState.FAULT:
            self._act_candidates(t, q_meas, evaluations, pos_now, rot_now, events)
        self._times.append(t)
        self._positions.append(new_pos)
        self._rotations.append(new_rot)
        self._last_q = q_meas
        return self._record(t, q_meas, evaluations, continuity, events)

    def reset_fault(self) -> None:
        """Leave the safety stop (the operator acknowledged it)."""
        self.state = next_state(self.state, KernelEvent.RESET)

    # ------------------------------------------------------------------ evaluate
    def _prediction(self, t: float) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
        """(times (K+1,), positions (K+1, nq, 3), std (K+1, nq, 3), task rotations (K+1,3,3))."""
        cfg = self.config
        times = np.array(self._times)
        pos = np.array(self._positions)
        rots = np.array(self._rotations)
        nq = len(self.task_points)
        world_tp = pos[:, None, :] + np.einsum("nij,qj->nqi", rots, self._tp_local)
        future = t + cfg.dt * cfg.stride * np.arange(1, cfg.horizon + 1, dtype=np.float64)
        pred = self.predictor.predict(times, world_tp.reshape(len(times), -1), future)
        all_t = np.concatenate([[t], future])
        mean = np.concatenate([world_tp[-1:], pred.mean.reshape(-1, nq, 3)])
        std = np.concatenate([np.zeros((1, nq, 3)), pred.std.reshape(-1, nq, 3)])
        if self._has_rotation and len(times) > 1:
            rpred = predict_rotations(times, rots, future, self.predictor)
        else:
            rpred = np.repeat(rots[-1:], cfg.horizon, axis=0)
        return all_t, mean, std, np.concatenate([rots[-1:], rpred])

    def _first_attempts(self, pairs: Sequence[Key], mean: FloatArray,
                        rotations: Mapping[Key, list[FloatArray | None]],
                        q_meas: Mapping[str, FloatArray]
                        ) -> dict[Key, tuple[FloatArray, NDArray[np.bool_]]]:
        """The first IK attempts along every pair's predicted points, in one compiled call
        (:mod:`vasim.mrcp.batch_ik`; exact trajectory IK only).

        **Decision** (issue #17 §4, cost): the pairs' IK is batched across robots: the
        attempts are the ones each ``arm.ik`` makes first, with the same seeds and the same
        compiled arithmetic, so the configurations are unchanged; a point whose attempt
        fails, and the rest of its pair, go through ``arm.ik`` as before.
        """
        if self.config.trajectory_ik != "exact" or not self.config.batch_ik:
            return {}
        reqs = [TrajectoryRequest(self.arms[r], self._seeds.get((r, q), q_meas[r]),
                                  q_meas[r] if r == self.rsel else None, mean[:, q],
                                  rotations[(r, q)]) for r, q in pairs]
        return {key: res for key, res in zip(pairs, solve_first_attempts(reqs), strict=True)
                if res is not None}

    def _trajectory_configs(self, arm: ArmKinematics, key: Key, first: FloatArray | None,
                            seed: FloatArray, positions: FloatArray,
                            rotations: list[FloatArray | None],
                            attempts: tuple[FloatArray, NDArray[np.bool_]] | None = None
                            ) -> tuple[FloatArray, NDArray]:
        n_pts = positions.shape[0]
        configs = np.full((n_pts, arm.n_joints), np.nan)
        reach = np.zeros(n_pts, dtype=bool)
        s = self._seeds.get(key, seed)
        linear = self.config.trajectory_ik == "linear"
        last = 0                    # the last reachable point: a linear step starts there
        for k in range(n_pts):
            if attempts is not None and attempts[1][k]:     # solved in the batched call
                sol = attempts[0][k]
            elif k == 0:
                sol = first if first is not None else arm.ik(positions[0], rotations[0], s)
            elif linear:
                sol = _linear_step(arm, s, positions[k] - positions[last],
                                   rotations[last], rotations[k])
            else:
                sol = arm.ik(positions[k], rotations[k], s)
            if sol is None:
                if k == 0:
                    return configs, reach
                continue
            configs[k], reach[k] = sol, True
            s, last = sol, k
        self._seeds[key] = configs[0].copy()
        return configs, reach

    def _evaluate(self, t: float, q_meas: Mapping[str, FloatArray],
                  qdot: Mapping[str, FloatArray], wrench: Wrench | None,
                  extras: Mapping[str, Any]) -> dict[Key, Evaluation]:
        cfg = self.config
        if self._last_eval_t is not None and t - self._last_eval_t > 1.5 * cfg.dt:
            self._pred_hist.clear()     # cycles were skipped (TT, fault): stale predictions
        self._last_eval_t = t
        times, mean, std, trot = self._prediction(t)
        dt_pred = cfg.dt * cfg.stride
        raw: dict[Key, dict[str, float]] = {}
        contexts: dict[Key, EvalContext] = {}
        pairs = [(self.rsel, self.cutp)] + [(r, q) for r in self.arms if r != self.rsel
                                            for q in range(len(self.task_points))
                                            if q != self.cutp]
        pair_rotations = {(r, q): [trot[k] @ self.task_points[q].rotation
                                   if self.task_points[q].rotation is not None else None
                                   for k in range(times.shape[0])] for r, q in pairs}
        first = self._first_attempts(pairs, mean, pair_rotations, q_meas)
        for r, q in pairs:
            arm = self.arms[r]
            selected = r == self.rsel
            tp = self.task_points[q]
            rotations = pair_rotations[(r, q)]
            configs, reach = self._trajectory_configs(
                arm, (r, q), q_meas[r] if selected else None, q_meas[r], mean[:, q], rotations,
                first.get((r, q)))
            hist = self._pred_hist.setdefault((r, q), deque(maxlen=cfg.horizon * cfg.stride))
            if not reach[0]:
                raw[(r, q)] = {ix.name: 0.0 for ix in self.indices}
                hist.clear()
                continue
            vel = np.zeros_like(configs)
            if reach.all():     # the common case: the same values without the NaN masking
                vel[:-1] = np.diff(configs, axis=0) / dt_pred
            else:
                filled = np.where(reach[:, None], configs, np.nan)
                diffs = np.diff(np.nan_to_num(filled, nan=0.0), axis=0) / dt_pred
                ok = reach[1:] & reach[:-1]
                vel[:-1] = np.where(ok[:, None], diffs, 0.0)
            vel[-1] = vel[-2] if configs.shape[0] > 1 else 0.0
            if selected:
                vel[0] = qdot[r]
            past = [hist[-cfg.stride * (j + 1)] for j in range(cfg.horizon)
                    if len(hist) >= cfg.stride * (j + 1)]
            raw[(r, q)] = {}            # filled below; keeps the pairs' order in raw
            contexts[(r, q)] = EvalContext(
                robot=r, arm=arm, point=q, selected=selected, times=times,
                positions=mean[:, q], std=std[:, q],
                rotations=np.array(rotations) if tp.rotation is not None else None,
                configs=configs, reachable=reach, joint_velocity=vel, past_configs=past,
                world=self.world, wrench=wrench, extras=extras,
                distance_points=cfg.distance_points)
        if cfg.batch_distances:     # one batched call for all robots (see below)
            per_body, nearest = self._distance_queries()
            if contexts and (per_body is not None or nearest):
                prefetch_distances_all(list(contexts.values()), per_body, nearest)
        elif (reach_d := self._distance_range()) is not None:   # one call per robot
            for r in self.arms:
                prefetch_distances([c for (rr, _), c in contexts.items() if rr == r], reach_d)
        for key, values in zip(contexts, self._index_values(list(contexts.values())),
                               strict=True):
            raw[key] = values
            self._pred_hist[key].append(contexts[key].configs.copy())
        for ix in self._groups:
            combined = ix.combine({k: v[ix.name] for k, v in raw.items()})
            for k, v in combined.items():
                raw[k][ix.name] = v
        return self._to_time(t, raw, q_meas)

    def _index_values(self, contexts: Sequence[EvalContext]) -> list[dict[str, float]]:
        """Every index's value at every context (in the contexts' order).

        **Decision** (issue #17 §4, cost): with ``KernelConfig.batch_indices`` an index
        that evaluates many contexts at once (``evaluate_many(contexts)``: Θ, one compiled
        call for all robots' Jacobians) gets the whole cycle in one call; the values are
        its ``evaluate``'s, bit for bit, and no index depends on the order of the
        evaluations (they read the context and the world, which does not move).
        """
        columns: list[tuple[str, list[float]]] = []
        for ix in self.indices:
            many = getattr(ix, "evaluate_many", None) if self.config.batch_indices else None
            if many is not None:
                columns.append((ix.name, [float(v) for v in many(contexts)]))
            else:
                columns.append((ix.name, [float(ix.evaluate(c)) for c in contexts]))
        return [{name: values[i] for name, values in columns} for i in range(len(contexts))]

    def _distance_range(self) -> float | None:
        """The largest body-distance range any index declares (``distance_range(world)``),
        None when none reads distances.

        **Decision** (issue #17 §4, cost): every (robot, point) context gets its
        distances before any index runs, from one batched call for all robots
        (:func:`~vasim.mrcp.indices.base.prefetch_distances_all`: the world's
        ``min_distances_many``, one compiled call per robot model) or, with
        ``KernelConfig(batch_distances=False)``, one ``min_distances`` call per robot
        (:func:`~vasim.mrcp.indices.base.prefetch_distances`); the values are the ones each
        context would have queried (the world does not move during the evaluation), so
        every outcome is unchanged.
        """
        ranges = [f(self.world) for ix in self.indices
                  if (f := getattr(ix, "distance_range", None)) is not None]
        found = [float(v) for v in ranges if v is not None]
        return max(found) if found else None

    def _distance_queries(self) -> tuple[float | None, list[NearestQuery]]:
        """What the indices read of the world's distances: the per-body range of those that
        read :meth:`~vasim.mrcp.indices.EvalContext.body_distances` (None: none does) and
        the nearest-body queries of those that declare them (``nearest_queries(world)``:
        CR, visibility).

        **Decision** (issue #17 §4, cost): with ``batch_distances`` the evaluation's
        distances are one compiled call per cycle for all robots: an index that needs only
        the nearest of a set of bodies gets that minimum from one branch and bound over the
        whole set (``PybulletWorld.nearest_distances_many``), the others the per-body
        values (``min_distances_many``); the values are those of the per-robot queries.
        """
        ranges: list[float] = []
        nearest: list[NearestQuery] = []
        for ix in self.indices:
            declare = getattr(ix, "nearest_queries", None)
            if declare is not None:
                nearest.extend(declare(self.world))
                continue
            f = getattr(ix, "distance_range", None)
            if f is not None and (v := f(self.world)) is not None:
                ranges.append(float(v))
        return (max(ranges) if ranges else None), nearest

    def _to_time(self, t: float, raw: Mapping[Key, dict[str, float]],
                 q_meas: Mapping[str, FloatArray]) -> dict[Key, Evaluation]:
        cfg = self.config
        self._cycle_times.append(t)
        series: dict[tuple[float, int], list[tuple[str, int, str]]] = {}
        for (r, q), vals in raw.items():
            for name, v in vals.items():
                h = self._index_hist.setdefault((r, q, name), deque(maxlen=cfg.texec_window))
                if h and t - h[-1][0] > 1.5 * cfg.dt:      # a gap: restart the series
                    h.clear()
                h.append((t, v))
                series.setdefault((h[0][0], len(h)), []).append((r, q, name))
        texecs: dict[tuple[str, int, str], float] = {}
        for (_, n), keys in series.items():
            hs = [self._index_hist[k] for k in keys]
            if n < cfg.texec_min_samples:
                for k, h in zip(keys, hs, strict=True):
                    texecs[k] = cfg.t_max if h[-1][1] > 0.0 else 0.0
                continue
            times = np.array([s for s, _ in hs[0]])
            values = np.array([[v for _, v in h] for h in hs]).T
            for k, te in zip(keys, texec_many(times, values, cfg.t_max, cfg.texec_degree),
                             strict=True):
                texecs[k] = float(te)
        out: dict[Key, Evaluation] = {}
        for (r, q), vals in raw.items():
            te = {name: texecs[(r, q, name)] for name in vals}
            te_min = min(te.values()) if te else cfg.t_max
            if r == self.rsel:
                ttr = 0.0
            elif te_min <= 0.0:
                ttr = float("inf")
            else:
                goal, grot = self.point_pose(q, self._positions[-1], self._rotations[-1])
                speed = cfg.max_tcp_speed.get(r, cfg.default_tcp_speed)
                ttr = estimate_transfer(self.arms[r], q_meas[r], goal, grot, speed,
                                        cfg.ttc_samples, self._seeds.get((r, q))).total
            out[(r, q)] = Evaluation(dict(vals), te, te_min, ttr, te_min - ttr)
        own = (self.rsel, self.cutp)
        if (self._held_since is not None and own in out
                and t - self._held_since >= cfg.hold_transfer_s):
            e = out[own]                # held too long: no time left (KernelConfig)
            out[own] = Evaluation(e.values, {**e.texec, "hold": 0.0}, 0.0, 0.0, 0.0)
        return out

    def _decide(self, t: float, ev: Mapping[Key, Evaluation]) -> Continuity:
        tus = {k: (e.tus if self._cooldown.get(k, -np.inf) <= t else -np.inf)
               for k, e in ev.items()}
        ttr = {k: e.ttransf for k, e in ev.items()}
        return continuity_robot(tus, ttr, self.rsel, self.cutp, self.config.ntt_threshold)

    # ------------------------------------------------------------------ act
    def _follow(self, position: FloatArray, rotation: FloatArray,
                q_meas: Mapping[str, FloatArray], events: list[str]) -> bool:
        """RSel follows the task increment; False (task held) when it cannot."""
        arm = self.arms[self.rsel]
        q = q_meas[self.rsel]
        goal, grot = self.point_pose(self.cutp, position, rotation)
        sol = arm.ik(goal, grot, q)
        if sol is None:
            events.append(f"rsel_hold {self.rsel}: task pose unreachable")
            if self._held_since is None:
                self._held_since = self._t_now
            return False
        if np.any(np.abs(sol - q) > arm.max_velocity * self.config.dt * (1.0 + 1e-9)):
            events.append(f"rsel_hold {self.rsel}: joint speed limit")
            if self._held_since is None:
                self._held_since = self._t_now
            return False
        self.world.set_configuration(self.rsel, sol)
        if self.world.in_collision(self.rsel):
            near = self._near_bodies(self.rsel)
            self.world.set_configuration(self.rsel, q)
            touching = [b for b, d in near if d <= 0.0]
            if touching and all(b in self.arms and b not in self.holders for b in touching):
                # a robot that does not hold the task is in the way: hold (KernelConfig.
                # hold_transfer_s), not a safety stop (module docstring, issue #26 §4)
                events.append(f"rsel_hold {self.rsel}: blocked by {near[0][0]} "
                              f"({near[0][1] * 1e3:.1f} mm)")
                if self._held_since is None:
                    self._held_since = self._t_now
                return False
            self.state = next_state(self.state, KernelEvent.RSEL_COLLISION)
            events.append(f"rsel_collision {self.rsel}: safety stop "
                          f"({self._nearest_text(near)})")
            return False
        self._held_since = None
        return True

    def _near_bodies(self, robot: str) -> list[tuple[str, float]]:
        """The other bodies within 5 cm of ``robot`` as posed, nearest first, with their
        signed distances [m] (negative: penetration)."""
        near = []
        for b in self._bodies(robot):
            d = float(self.world.min_distance(robot, b, max_distance=0.05).distance)
            if d < 0.05:
                near.append((b, d))
        return sorted(near, key=lambda bd: bd[1])

    @staticmethod
    def _nearest_text(near: list[tuple[str, float]]) -> str:
        """What ``robot`` would hit, for the safety stop's event (issue #26 §4: the cause
        is named, not only the stop): the nearest other body and its signed distance at
        the refused pose, or a self-collision when no other body is within 5 cm."""
        if not near:
            return "a self-collision: no other body within 5 cm"
        return f"nearest body {near[0][0]} at {near[0][1] * 1e3:.1f} mm"

    def _bodies(self, robot: str) -> list[str]:
        return [b for b in (*self.world.robot_names(), *self.world.obstacle_names())
                if b != robot]

    def _act_candidates(self, t: float, q_meas: Mapping[str, FloatArray],
                        ev: Mapping[Key, Evaluation], pos: FloatArray, rot: FloatArray,
                        events: list[str]) -> None:
        cfg = self.config
        reserved = {self.cutp}
        if self.state is not KernelState.TOP and self.target is not None:
            reserved.add(self.target)
            self._act_rcnt(t, q_meas, pos, rot, events)
        candidates = [r for r in self.arms if r not in self.holders and r != self.rcnt]
        tus = {k: e.tus for k, e in ev.items() if k[0] in candidates}
        if not tus:   # TT cycles are not evaluated: keep going to the last goals
            tus = {(r, q): v for (r, q), v in self._last_goals.items() if r in candidates}
        order: list[Assignment] = candidate_hierarchy(tus, candidates, reserved)
        self._last_goals = {(a.robot, a.point): a.tus for a in order if a.point is not None}
        for a in order:
            goal = grot = None
            if a.point is not None:
                goal, grot = self.pregrasp(a.point, pos, rot)
            move_candidate(Mover(self.world, self.arms[a.robot], a.robot), q_meas[a.robot],
                           goal, grot, self._bodies(a.robot), self._memory, cfg.planner,
                           cfg.dt, self._rng)

    def _act_rcnt(self, t: float, q_meas: Mapping[str, FloatArray], pos: FloatArray,
                  rot: FloatArray, events: list[str]) -> None:
        cfg = self.config
        r, q = self.rcnt, self.target
        if r is None or q is None:
            raise RuntimeError("task transfer without a receiving robot")
        arm = self.arms[r]
        if self.state is KernelState.TT_HANDOVER:
            self._grasp_count += 1
            if self._grasp_count >= cfg.grasp_cycles:
                self._swap_roles(events)
            return
        if t - self._tt_start > cfg.tt_timeout:
            self.state = next_state(self.state, KernelEvent.ABORT)
            events.append(f"transfer_abort {r}@{q}: timeout")
            self._cooldown[(r, q)] = t + cfg.abort_cooldown
            self.rcnt = self.target = None
            return
        grasp, grot = self.point_pose(q, pos, rot)
        pre, _ = self.pregrasp(q, pos, rot)
        tcp, _ = arm.tcp_pose(q_meas[r])
        if self.state is KernelState.TT_APPROACH:
            if vector_norm(pre - tcp) <= cfg.grasp_tolerance:
                self.state = next_state(self.state, KernelEvent.AT_PREGRASP)
                events.append(f"transfer_pregrasp {r}@{q}")
            else:
                move_candidate(Mover(self.world, arm, r), q_meas[r], pre, grot,
                               self._bodies(r), self._memory, cfg.planner, cfg.dt, self._rng)
                return
        if self.state is KernelState.TT_GRASP:
            if vector_norm(grasp - tcp) <= cfg.grasp_tolerance and self._snap(
                    r, arm, q_meas[r], grasp, grot):
                self.state = next_state(self.state, KernelEvent.GRASPED)
                self.holders = (self.rsel, r)
                self._grasp_count = 0
                events.append(f"transfer_grasped {r}@{q}")
                return
            move_candidate(Mover(self.world, arm, r), q_meas[r], grasp, grot, self._bodies(r),
                           self._memory, cfg.planner, cfg.dt, self._rng, repel=False)

    def _snap(self, robot: str, arm: ArmKinematics, q: FloatArray, grasp: FloatArray,
              grot: FloatArray | None) -> bool:
        """Close the gripper: the last (sub-tolerance) step onto the grasp pose, if safe."""
        sol = arm.ik(grasp, grot, q)
        if sol is None:
            return False
        self.world.set_configuration(robot, sol)
        if self.world.in_collision(robot):
            self.world.set_configuration(robot, q)
            return False
        return True

    def _swap_roles(self, events: list[str]) -> None:
        old = self.rsel
        if self.rcnt is None or self.target is None:
            raise RuntimeError("task transfer without a receiving robot")
        if self._tt_cause == "hold":
            # The pose the old RSel could not follow is not handed straight back to it
            # (as after an aborted transfer): eight_robots otherwise bounced the cube
            # between R4 (holding) and R6 (at its wrist limit) every half second.
            self._cooldown[(old, self.cutp)] = self._t_now + self.config.abort_cooldown
        self.rsel, self.cutp = self.rcnt, self.target
        self._held_since = None
        self.holders = (self.rsel,)
        self.state = next_state(self.state, KernelEvent.RELEASED)
        events.append(f"transfer_done {old} -> {self.rsel}@{self.cutp}")
        self.rcnt = self.target = None
        self._pred_hist.clear()

    def _record(self, t: float, q_meas: Mapping[str, FloatArray],
                ev: dict[Key, Evaluation], cont: Continuity | None,
                events: list[str]) -> CycleRecord:
        pos, rot = self.task_pose()
        commands = {r: self.world.configuration(r).copy() for r in self.arms}
        return CycleRecord(t, self.state, self.rsel, self.cutp, self.holders, pos, rot,
                           commands, ev, cont, self.rcnt, self.target, events)
