"""Robot actions: reactive guidance of the candidates (spec/mrcp.md §7, seed eq. 4.7-4.12,
Algorithm 2).

Each cycle a candidate's TCP moves by the guidance displacement

    F = F_attr + Σ F_rep + w_rand F_rand,   |F| <= ΔR_max

* ``F_attr = ΔR_max d̂`` when ``|d| >= ΔR_max`` else ``d`` (``d = goal - TCP``; greedy).
* ``F_rep`` per obstacle: magnitude ``h = ΔR_max / (1 + (|d'|/d_scale)^l)``,
  ``d' = d + d_offset``, direction ``-Δû`` with ``Δû = (u_i - u_{i-1}) / |u_i - u_{i-1}|`` and
  ``u`` the unit min-distance vector from the robot to the obstacle: the field turns the
  robot around the obstacle the way it is already sliding (a tangential field with variable
  direction). Applied only while the distance decreases.
* ``F_rand`` (unit, random direction) only when ``|F_attr + Σ F_rep|`` is (nearly) zero, with
  a residual weight ``0 <= w_rand <= 0.2``. **Decision**: only when there is an attraction
  to cancel (a robot with no goal, or on it, is not deadlocked and stays still).

**Decisions**:

* The seed's eq. 4.10 prints contradictory conditions; repulsion acts while approaching.
* ``h`` takes the distance in units of ``d_scale`` (default 5 cm): the seed's formula has no
  unit; in metres ``|d|^l`` would make the repulsion saturate at any sub-metre distance.
* With no usable ``Δû`` (first contact, or ``u`` unchanged: a head-on approach) the
  direction is ``-u`` (straight away from the obstacle).
* Within ``ΔR_max`` of its goal a robot takes the last step without repulsion (the
  tangential field would otherwise keep it circling a goal that lies near an obstacle).
* Safety over progress: a move whose configuration collides (or comes closer than
  ``safety_margin`` to a body it was farther from) is rejected.
* Slide, then retreat (no deadlock at the margin): a candidate waiting exactly at
  ``safety_margin`` from a body has every step toward a goal behind that body's side
  rejected, so it would stall and its transfer time out. When the guidance step is
  rejected, the candidate tries the step projected onto the tangent plane of the nearest
  body (the component along the unit witness direction ``n`` robot -> body removed when it
  points at the body: ``F - max(F·n, 0) n``, i.e. it slides along the surface); if that is
  rejected too (or vanishes: the goal lies straight behind the body), a retreat step of the
  same length straight away from the nearest body (``-|F| n``). Every fallback passes the
  same collision / margin test; when none does, the candidate stays. The fallbacks start
  only after ``stall_cycles`` consecutive rejected guidance steps (and stop at the next
  accepted one; when they fail too, the count starts again): a rejection is usually
  transient (the holder or the task moves on), retreating at once set up a slide/retreat
  limit cycle in the laparoscopic scenario, and trying them every cycle for a candidate
  boxed in for good doubled the 4-robot cycle (bench/mrcp: 8.1 -> 14.7 ms).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vasim.core.geometry import rotation_angle, slerp_matrix, vector_norm
from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class PlannerParams:
    """Parameters of the action planner.

    Attributes:
        dr_max: ΔR_max, the largest TCP displacement per cycle [m].
        rot_max: the largest TCP rotation per cycle [rad].
        shape_l: the exponent l of h (>= 1; low: smooth around isolated obstacles, high: corridors).
        d_offset: offset added to the distance in ``h`` [m].
        d_scale: length unit of ``h`` [m].
        w_rand: weight of the random force (0..0.2).
        influence: obstacles farther than this are ignored [m].
        safety_margin: a move may not bring the robot closer than this to any body [m].
        stall_cycles: consecutive rejected guidance steps before a candidate slides along
            (or retreats from) the nearest body.
    """

    dr_max: float = 0.01
    rot_max: float = 0.1
    shape_l: float = 2.0
    d_offset: float = 0.0
    d_scale: float = 0.05
    w_rand: float = 0.05
    influence: float = 0.3
    safety_margin: float = 0.005
    stall_cycles: int = 10

    def __post_init__(self) -> None:
        if self.dr_max <= 0.0:
            raise ValueError(f"PlannerParams.dr_max must be > 0, got {self.dr_max!r}")
        if self.shape_l < 1.0:
            raise ValueError(f"PlannerParams.shape_l must be >= 1, got {self.shape_l!r}")
        if not 0.0 <= self.w_rand <= 0.2:
            raise ValueError(f"PlannerParams.w_rand must be in [0, 0.2], got {self.w_rand!r}")
        if self.stall_cycles < 1:
            raise ValueError(f"PlannerParams.stall_cycles must be >= 1, got {self.stall_cycles!r}")
        if self.d_scale <= 0.0:
            raise ValueError(f"PlannerParams.d_scale must be > 0, got {self.d_scale!r}")


def attraction(delta: FloatArray, dr_max: float) -> FloatArray:
    """``F_attr`` (seed eq. 4.8): the full step toward the goal, or the rest of the way.

    Example:
        >>> import numpy as np
        >>> attraction(np.array([0.3, 0.4, 0.0]), 0.1).round(6)
        array([0.06, 0.08, 0.  ])
    """
    d = np.asarray(delta, dtype=np.float64)
    n = vector_norm(d)
    return d * (dr_max / n) if n >= dr_max else d.copy()


def repulsion_magnitude(distance: float, dr_max: float, shape_l: float, d_offset: float = 0.0,
                        d_scale: float = 1.0) -> float:
    """``h(d) = ΔR_max / (1 + (|d + d_offset| / d_scale)^l)`` (seed eq. 4.11)."""
    return float(dr_max / (1.0 + (abs(distance + d_offset) / d_scale) ** shape_l))


def repulsion(u_now: FloatArray, u_prev: FloatArray | None, dist_now: float,
              dist_prev: float | None, p: PlannerParams) -> FloatArray:
    """``F_rep`` of one obstacle (zero unless the distance is decreasing).

    Args:
        u_now, u_prev: unit min-distance vectors robot -> obstacle, now and last cycle.
        dist_now, dist_prev: the distances [m].
    """
    if dist_prev is None or u_prev is None or dist_now >= dist_prev:
        return np.zeros(3)
    h = repulsion_magnitude(dist_now, p.dr_max, p.shape_l, p.d_offset, p.d_scale)
    du = np.asarray(u_now) - np.asarray(u_prev)
    ndu = vector_norm(du)
    direction = -du / ndu if ndu > 1e-6 else -np.asarray(u_now)
    return h * direction


def guidance(f_attr: FloatArray, f_reps: Iterable[FloatArray], p: PlannerParams,
             rng: np.random.Generator) -> FloatArray:
    """``F = F_attr + Σ F_rep (+ w_rand F_rand on a deadlock)``, clipped to ``ΔR_max``.

    A deadlock is an attraction cancelled by the repulsions. A robot with no goal, or
    already on it, has no attraction: it gets no random force either (it would otherwise
    jitter every cycle and wander off, e.g. an idle instrument near tissue).
    """
    f = np.asarray(f_attr, dtype=np.float64).copy()
    pulled = vector_norm(f) >= 1e-3 * p.dr_max
    for r in f_reps:
        f = f + r
    if pulled and vector_norm(f) < 1e-3 * p.dr_max and p.w_rand > 0.0:
        rnd = rng.standard_normal(3)
        f = f + p.w_rand * p.dr_max * rnd / max(vector_norm(rnd), 1e-12)
    n = vector_norm(f)
    return f * (p.dr_max / n) if n > p.dr_max else f


def _limit_rotation(current: FloatArray, goal: FloatArray, rot_max: float) -> FloatArray:
    angle = rotation_angle(current, goal)
    if angle <= rot_max:
        return np.asarray(goal, dtype=np.float64)
    return slerp_matrix(current, goal, rot_max / angle)


@dataclass
class ObstacleMemory:
    """Last cycle's distance and unit vector per (robot, body) for ``Δû``, and per robot
    the number of consecutive rejected guidance steps."""

    last: dict[tuple[str, str], tuple[float, FloatArray]]
    stalled: dict[str, int]

    def __init__(self) -> None:
        self.last = {}
        self.stalled = {}


def _unit(a: FloatArray, b: FloatArray) -> FloatArray | None:
    d = np.asarray(b) - np.asarray(a)
    n = vector_norm(d)
    if not np.isfinite(n) or n < 1e-12:
        return None
    return d / n


def step_limits(arm: ArmKinematics, q: FloatArray, q_new: FloatArray, dt: float) -> FloatArray:
    """Clamp a joint step to the velocity limits and the joint range."""
    dq = np.clip(q_new - q, -arm.max_velocity * dt, arm.max_velocity * dt)
    return np.clip(q + dq, arm.joint_lower, arm.joint_upper)


@dataclass(frozen=True)
class Mover:
    """The robot a planner step moves.

    Attributes:
        world: the station. arm: the robot's kinematics. robot: its name in ``world``.
    """

    world: ProximityWorld
    arm: ArmKinematics
    robot: str


def move_candidate(mover: Mover, q: FloatArray,
                   goal: FloatArray | None, goal_rotation: FloatArray | None,
                   bodies: Sequence[str], memory: ObstacleMemory, p: PlannerParams,
                   dt: float, rng: np.random.Generator, repel: bool = True) -> FloatArray:
    """One cycle of a candidate (Algorithm 2 inner loop); poses ``mover.world`` at the result.

    Args:
        mover: the candidate (``Mover``); its robot is posed at ``q`` in its world on entry.
        goal, goal_rotation: target TCP pose (None: no goal, only avoid obstacles).
        bodies: obstacles to repel from (RSel, better-ranked candidates at their new poses,
            obstacles).
        memory: per-(robot, body) distances of the last cycle (updated).
        repel: False for the final straight approach to a grasp.

    Returns:
        The new configuration (``q`` when no safe move exists).
    """
    world, arm, robot = mover.world, mover.arm, mover.robot
    tcp, rot = arm.tcp_pose(q)
    f_attr = attraction(goal - tcp, p.dr_max) if goal is not None else np.zeros(3)
    if goal is not None and vector_norm(goal - tcp) < p.dr_max:
        repel = False                   # the last step onto the goal: settle, no limit cycle
    reps = []
    before: dict[str, float] = {}
    nearest: tuple[float, FloatArray] | None = None     # (distance, unit witness direction)
    for body in bodies:
        prox = world.min_distance(robot, body, p.influence)
        before[body] = prox.distance
        u = _unit(prox.point_a, prox.point_b)
        if u is not None and (nearest is None or prox.distance < nearest[0]):
            nearest = (prox.distance, u)
        key = (robot, body)
        prev = memory.last.get(key)
        if u is not None and prox.distance < p.influence:
            if repel and prev is not None:
                reps.append(repulsion(u, prev[1], prox.distance, prev[0], p))
            memory.last[key] = (prox.distance, u)
        else:
            memory.last.pop(key, None)
    f = guidance(f_attr, reps, p, rng)
    if vector_norm(f) < 1e-9 and (goal_rotation is None):
        return q
    target_rot = (_limit_rotation(rot, goal_rotation, p.rot_max)
                  if goal_rotation is not None else None)
    q_new = _safe_step(mover, q, tcp, f, target_rot, bodies, before, p, dt)
    if q_new is not None:
        memory.stalled[robot] = 0
        return q_new
    if nearest is None:
        return q
    memory.stalled[robot] = memory.stalled.get(robot, 0) + 1
    if memory.stalled[robot] < p.stall_cycles:
        return q
    for fallback in fallback_steps(f, nearest[1]):
        q_new = _safe_step(mover, q, tcp, fallback, target_rot, bodies, before, p, dt)
        if q_new is not None:
            return q_new
    # Nothing moves it: wait another stall_cycles before trying again (a candidate boxed in
    # for good would otherwise pay three IK + collision checks every cycle).
    memory.stalled[robot] = 0
    return q


def fallback_steps(f: FloatArray, n: FloatArray) -> list[FloatArray]:
    """The slide and retreat steps tried after the step ``f`` was rejected (see the module
    decision): ``f`` without its component toward the body (unit direction ``n`` robot ->
    body), when that remains, then ``|f|`` straight away from the body.

    Example:
        >>> import numpy as np
        >>> [s.round(6).tolist() for s in fallback_steps(np.array([0.006, 0.008, 0.0]),
        ...                                             np.array([1.0, 0.0, 0.0]))]
        [[0.0, 0.008, 0.0], [-0.01, -0.0, -0.0]]
    """
    f = np.asarray(f, dtype=np.float64)
    n = np.asarray(n, dtype=np.float64)
    size = vector_norm(f)
    out: list[FloatArray] = []
    slide = f - max(float(f @ n), 0.0) * n
    if vector_norm(slide) > 1e-6 * size:
        out.append(slide)
    if size > 0.0:
        out.append(-size * n)
    return out


def _safe_step(mover: Mover, q: FloatArray, tcp: FloatArray, f: FloatArray,
               target_rot: FloatArray | None, bodies: Sequence[str], before: dict[str, float],
               p: PlannerParams, dt: float) -> FloatArray | None:
    """Move the TCP by ``f`` (IK, halved without orientation when out of reach, joint limits);
    the new configuration, or None (``world`` back at ``q``) when it collides or comes too
    close to a body."""
    world, arm, robot = mover.world, mover.arm, mover.robot
    q_new = arm.ik(tcp + f, target_rot, q)
    if q_new is None:
        q_new = arm.ik(tcp + 0.5 * f, None, q)
        if q_new is None:
            return None
    q_new = step_limits(arm, q, q_new, dt)
    world.set_configuration(robot, q_new)
    if world.in_collision(robot) or _too_close(world, robot, q_new, bodies, before, p):
        world.set_configuration(robot, q)
        return None
    return q_new


def _too_close(world: ProximityWorld, robot: str, q: FloatArray, bodies: Sequence[str],
               before: dict[str, float], p: PlannerParams) -> bool:
    """A body now nearer than the safety margin that was farther before the move."""
    if not bodies:
        return False
    batched = getattr(world, "min_distances", None)
    if batched is not None:
        after = np.asarray(batched(robot, q[None, :], list(bodies), p.influence))[0]
    else:
        after = np.array([world.min_distance(robot, b, p.influence).distance for b in bodies])
    limit = np.minimum(p.safety_margin, np.array([before[b] for b in bodies]))
    return bool(np.any(after < limit))


def remember(memory: ObstacleMemory, bodies: Sequence[str], robot: str,
             world: ProximityWorld, p: PlannerParams) -> None:
    """Refresh the memory of a robot that did not plan this cycle (RSel, RCnt in TT)."""
    for body in bodies:
        prox = world.min_distance(robot, body, p.influence)
        u = _unit(prox.point_a, prox.point_b)
        if u is not None and prox.distance < p.influence:
            memory.last[(robot, body)] = (prox.distance, u)
        else:
            memory.last.pop((robot, body), None)



