"""The one interface of every suitability index, its evaluation context and the registry.

An index maps one robot at one task point, along the predicted trajectory, to a value in
``[0, 1]`` (or ``>= 0``) where ``0`` means "cannot continue the task" (spec/mrcp.md §4).
The kernel builds one :class:`EvalContext` per (robot, task point) and calls every index on
it; indices never see devices or the kernel's state machine. Adding an index means
registering a factory with ``@INDICES.add("name")``: no control code changes (requisite 7).

An index whose value depends on all robots at once (the collision risk ``CR_r = timp_r /
max timp``) also implements :class:`GroupIndex`: the kernel evaluates it per (robot, point)
and then calls ``combine`` once with every raw value.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol, TypeVar, runtime_checkable

import numpy as np
from numpy.typing import NDArray

from vasim.mrcp.interfaces import ArmKinematics, ProximityWorld

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
Key = tuple[str, int]


@dataclass(frozen=True)
class Wrench:
    """A force-torque sensor reading at the grasped task point (world frame).

    Attributes:
        force: ``(3,)`` force [N].
        torque: ``(3,)`` torque about ``point`` [N m].
        point: ``(3,)`` where the torque is measured [m].
    """

    force: FloatArray
    torque: FloatArray
    point: FloatArray

    def moved_to(self, point: FloatArray) -> Wrench:
        """The same load expressed at another point: ``τ' = τ + (p - p') x F``."""
        p = np.asarray(point, dtype=np.float64)
        return Wrench(self.force, self.torque + np.cross(self.point - p, self.force), p)


@dataclass(frozen=True)
class NearestQuery:
    """The nearest of a set of bodies, at each trajectory point of a context: the bodies
    of the world other than the context's robot, less ``exclude``, restricted to ``only``
    when given; values capped at ``max_distance`` [m].

    An index that reads only such a minimum declares its queries (``nearest_queries(world)``)
    so the kernel answers them for every context of a cycle in one batched call
    (:func:`prefetch_distances_all`); it reads them with
    :meth:`EvalContext.nearest_distances`.
    """

    max_distance: float
    exclude: frozenset[str] = frozenset()
    only: frozenset[str] | None = None

    def bodies(self, world: ProximityWorld, robot: str) -> list[str]:
        """The bodies of the set for ``robot``, in the world's order."""
        return [b for b in (*world.robot_names(), *world.obstacle_names())
                if b != robot and b not in self.exclude
                and (self.only is None or b in self.only)]


@dataclass(frozen=True)
class EvalContext:
    """Everything an index may read to evaluate one robot at one task point.

    Point ``k = 0`` of every trajectory array is *now*; ``k = 1..K`` are predicted.

    Attributes:
        robot: robot name.
        arm: its kinematics.
        point: task-point index ``q``.
        selected: True for RSel evaluated at CuTP (it holds the task), False for a
            candidate evaluated as if it held the task at ``point``.
        times: ``(K+1,)`` absolute times of the trajectory points [s].
        positions: ``(K+1, 3)`` task-point positions [m] (world frame); ``[0]`` observed.
        std: ``(K+1, 3)`` standard deviation of each predicted position [m] (``[0] = 0``).
        rotations: ``(K+1, 3, 3)`` task-point orientations, or None for a position-only task.
        configs: ``(K+1, n)`` joint configurations reaching each point (IK, seeded along the
            trajectory); rows where ``reachable`` is False are NaN. For RSel, ``configs[0]``
            is the measured configuration.
        reachable: ``(K+1,)`` whether IK found a configuration within the joint limits.
        joint_velocity: ``(K+1, n)`` joint velocities along the trajectory [rad/s] (for RSel
            ``[0]`` is measured; otherwise finite differences of ``configs``).
        past_configs: configurations this robot was predicted to have at this point in
            earlier cycles: ``past_configs[j]`` is the ``(K+1, n)`` prediction made ``j + 1``
            prediction steps ago (most recent first), for the RJ range shrinking.
        world: the proximity world, posed at the measured configurations (an index that
            poses a robot must restore it).
        wrench: the force-torque reading of the task, if the station has a sensor.
        extras: scenario data for task-oriented indices (e.g. the camera pose).
        distance_points: ``"all"`` (distance queries at every reachable trajectory point)
            or ``"ends"`` (the first and last only: half the queries for a costly world;
            points in between are NaN, skipped by the indices).
    """

    robot: str
    arm: ArmKinematics
    point: int
    selected: bool
    times: FloatArray
    positions: FloatArray
    std: FloatArray
    rotations: FloatArray | None
    configs: FloatArray
    reachable: BoolArray
    joint_velocity: FloatArray
    past_configs: Sequence[FloatArray]
    world: ProximityWorld
    wrench: Wrench | None = None
    extras: Mapping[str, Any] = field(default_factory=dict)
    distance_points: str = "all"
    _memo: dict[Any, Any] = field(default_factory=dict, repr=False, compare=False)

    @property
    def horizon(self) -> int:
        """``K``: the number of predicted points after *now*."""
        return int(self.times.shape[0]) - 1

    def distance_rows(self) -> NDArray[np.intp]:
        """The trajectory rows whose distances are queried: every reachable point, or its
        first and last for ``distance_points="ends"``."""
        idx = np.flatnonzero(self.reachable)
        if self.distance_points == "ends" and idx.size > 2:
            idx = idx[[0, -1]]
        return idx

    def body_distances(self, max_distance: float) -> tuple[list[str], FloatArray]:
        """Minimum distance from this robot, posed at each trajectory point, to every other
        body of the world (robots at their measured configurations, obstacles).

        Queried once per context and shared by the indices that need it (CR, visibility):
        uses the world's batched ``min_distances(robot, configs, bodies, max_distance)``
        when it has one, else poses the robot and calls ``min_distance`` per body (the
        pose is restored).

        Returns:
            The body names and a ``(K+1, B)`` array [m], NaN rows at unreachable points,
            values capped at ``max_distance``.
        """
        cached = self._memo.get("distances")
        if cached is not None and cached[0] >= max_distance:
            names, dist = cached[1], np.minimum(cached[2], max_distance)
            return names, np.where(np.isnan(cached[2]), np.nan, dist)
        world = self.world
        names = [b for b in (*world.robot_names(), *world.obstacle_names()) if b != self.robot]
        out = np.full((self.configs.shape[0], len(names)), np.nan)
        idx = self.distance_rows()
        batched = getattr(world, "min_distances", None)
        if names and idx.size:
            if batched is not None:
                out[idx] = np.asarray(batched(self.robot, self.configs[idx], names,
                                              max_distance), dtype=np.float64)
            else:
                saved = world.configuration(self.robot)
                try:
                    for k in idx:
                        world.set_configuration(self.robot, self.configs[k])
                        out[k] = [world.min_distance(self.robot, b, max_distance).distance
                                  for b in names]
                finally:
                    world.set_configuration(self.robot, saved)
        out = np.where(np.isnan(out), np.nan, np.minimum(out, max_distance))
        self._memo["distances"] = (max_distance, names, out)
        return names, out


    def nearest_distances(self, query: NearestQuery) -> FloatArray:
        """``(K+1,)`` distance from this robot, posed at each trajectory point, to the
        nearest body of ``query`` [m] (capped at its ``max_distance``); NaN at the points
        whose distances are not queried (:meth:`distance_rows`) and where the set is empty.

        Read from the kernel's batched answer when it made one
        (:func:`prefetch_distances_all`), else the row minimum of :meth:`body_distances`
        over the set's bodies (the same values, bit for bit).
        """
        cached = self._memo.get(("nearest", query))
        if cached is not None:
            return np.asarray(cached, dtype=np.float64)
        names, dist = self.body_distances(query.max_distance)
        wanted = set(query.bodies(self.world, self.robot))
        keep = [j for j, b in enumerate(names) if b in wanted]
        out = np.full(self.configs.shape[0], np.nan)
        if keep:
            sub = dist[:, keep]
            rows = ~np.all(np.isnan(sub), axis=1)
            out[rows] = np.nanmin(sub[rows], axis=1)
        self._memo[("nearest", query)] = out
        return out

def prediction_weights(count: int) -> FloatArray:
    """``w_k = 1/(k+1)`` for ``k = 0..count-1`` (seed eq. 3.19)."""
    return 1.0 / (np.arange(count, dtype=np.float64) + 1.0)


@runtime_checkable
class Index(Protocol):
    """A suitability index: ``evaluate(ctx) -> value`` (0 = cannot continue)."""

    name: str

    def evaluate(self, ctx: EvalContext) -> float: ...


@runtime_checkable
class GroupIndex(Index, Protocol):
    """An index normalised across all evaluated (robot, point) pairs of a cycle."""

    def combine(self, raw: Mapping[Key, float]) -> dict[Key, float]: ...


F = TypeVar("F", bound=Callable[..., Index])


class IndexRegistry:
    """Name -> index factory. A duplicate name raises ``ValueError``."""

    def __init__(self) -> None:
        self._factories: dict[str, Callable[..., Index]] = {}

    def add(self, name: str) -> Callable[[F], F]:
        """Decorator registering a factory (usually the index class) under ``name``."""

        def deco(factory: F) -> F:
            if name in self._factories:
                raise ValueError(f"index {name!r} is already registered")
            self._factories[name] = factory
            return factory

        return deco

    def names(self) -> list[str]:
        return sorted(self._factories)

    def create(self, name: str, **params: Any) -> Index:
        """Instantiate the index ``name`` with keyword parameters.

        Raises:
            ValueError: for an unknown name (the known names are listed).
        """
        try:
            factory = self._factories[name]
        except KeyError:
            raise ValueError(f"unknown index {name!r}; known: {self.names()}") from None
        return factory(**params)

    def __contains__(self, name: object) -> bool:
        return name in self._factories


INDICES = IndexRegistry()


def prefetch_distances(contexts: Sequence[EvalContext], max_distance: float) -> int:
    """Answer the distance queries of several contexts of one robot in one batched call.

    The contexts' :meth:`EvalContext.body_distances` then read the stored values (up to
    ``max_distance``; a larger range queries again). The values are those each context
    would have queried itself: the world's ``min_distances`` answers every configuration
    independently of the others in the batch, and the world is not moved in between.

    **Decision** (cost, issue #17 §4): the kernel calls this once per robot per cycle with
    all the (robot, point) contexts of that robot — one compiled distance call instead of
    one per task point (5 per candidate with 6 task points), the per-call Python work
    (frames, packing, argument checks) paid once. Worlds without ``min_distances`` are
    left alone (the contexts query one pose at a time as before).

    Args:
        contexts: contexts of one robot (same ``robot`` and ``world``), any task points.
        max_distance: the range to store [m] (the largest any index will ask for).

    Returns:
        The number of configurations queried (0 when nothing was prefetched).

    Raises:
        ValueError: if the contexts are not all of one robot in one world.
    """
    todo = [c for c in contexts if "distances" not in c._memo]
    if not todo:
        return 0
    robot, world = todo[0].robot, todo[0].world
    if any(c.robot != robot or c.world is not world for c in todo):
        raise ValueError(f"prefetch_distances: contexts must share one robot and world, got "
                         f"robots {sorted({c.robot for c in todo})}")
    batched = getattr(world, "min_distances", None)
    if batched is None:
        return 0
    names = [b for b in (*world.robot_names(), *world.obstacle_names()) if b != robot]
    rows = [c.distance_rows() for c in todo]
    count = sum(int(r.size) for r in rows)
    values = None
    if names and count:
        stacked = np.concatenate([c.configs[r] for c, r in zip(todo, rows, strict=True)])
        values = np.asarray(batched(robot, stacked, names, max_distance), dtype=np.float64)
    start = 0
    for c, r in zip(todo, rows, strict=True):
        out = np.full((c.configs.shape[0], len(names)), np.nan)
        if values is not None and r.size:
            out[r] = values[start:start + r.size]
            start += int(r.size)
        out = np.where(np.isnan(out), np.nan, np.minimum(out, max_distance))
        c._memo["distances"] = (max_distance, names, out)
    return count


def prefetch_distances_all(contexts: Sequence[EvalContext], max_distance: float | None,
                           nearest: Sequence[NearestQuery] = ()) -> int:
    """:func:`prefetch_distances` for the contexts of every robot of a cycle in one call of
    the world's ``min_distances_many(queries, max_distance)`` (one query per robot: all
    its contexts' rows), when the world has it; else one :func:`prefetch_distances` per
    robot. The stored values are the same either way (``min_distances_many`` answers each
    query as ``min_distances`` does, bit for bit).

    **Decision** (cost, issue #17 §4): the kernel's evaluation makes its distance queries
    for all robots at once — one compiled call per cycle (per robot model) for the link
    frames and distances of every robot at every trajectory point, the other bodies'
    geometry computed once for all of them — instead of one call per robot.

    The ``nearest`` queries (:class:`NearestQuery`: an index that reads only the nearest
    of a set of bodies) are answered for every context in one call of the world's
    ``nearest_distances_many`` when it has one (one branch and bound over the whole set:
    see :meth:`vasim.mrcp.world.PybulletWorld.nearest_distances_many`), stored for
    :meth:`EvalContext.nearest_distances` with the values it would compute itself.

    Args:
        contexts: contexts of any robots of one world.
        max_distance: the per-body range to store [m] (the largest any index reading
            :meth:`EvalContext.body_distances` will ask for), None: no per-body values.
        nearest: the nearest-body queries to answer.

    Returns:
        The number of configurations queried (0 when nothing was prefetched).

    Raises:
        ValueError: if the contexts are not all of one world.
    """
    if any(c.world is not contexts[0].world for c in contexts):
        raise ValueError("prefetch_distances_all: contexts must share one world")
    count = _prefetch_nearest(contexts, nearest) if nearest else 0
    if max_distance is None:
        return count
    todo = [c for c in contexts if "distances" not in c._memo]
    if not todo:
        return count
    world = todo[0].world
    by_robot: dict[str, list[EvalContext]] = {}
    for c in todo:
        by_robot.setdefault(c.robot, []).append(c)
    many = getattr(world, "min_distances_many", None)
    if many is None:
        return count + sum(prefetch_distances(cs, max_distance) for cs in by_robot.values())
    all_names = (*world.robot_names(), *world.obstacle_names())
    names = {r: [b for b in all_names if b != r] for r in by_robot}
    rows = {r: [c.distance_rows() for c in cs] for r, cs in by_robot.items()}
    queries = [(r, np.concatenate([c.configs[k] for c, k in zip(cs, rows[r], strict=True)]),
                names[r]) for r, cs in by_robot.items()
               if names[r] and sum(int(k.size) for k in rows[r])]
    values = dict(zip([q[0] for q in queries],
                      many(queries, max_distance) if queries else [], strict=True))
    for r, cs in by_robot.items():
        got = values.get(r)
        start = 0
        for c, k in zip(cs, rows[r], strict=True):
            out = np.full((c.configs.shape[0], len(names[r])), np.nan)
            if got is not None and k.size:
                out[k] = np.asarray(got, dtype=np.float64)[start:start + k.size]
                start += int(k.size)
            out = np.where(np.isnan(out), np.nan, np.minimum(out, max_distance))
            c._memo["distances"] = (max_distance, names[r], out)
        count += sum(int(k.size) for k in rows[r])
    return count


def _prefetch_nearest(contexts: Sequence[EvalContext], queries: Sequence[NearestQuery]) -> int:
    """Store every context's :meth:`EvalContext.nearest_distances` for ``queries`` from one
    ``nearest_distances_many`` call (worlds without it: nothing is stored, the contexts
    compute them from :meth:`EvalContext.body_distances`)."""
    world = contexts[0].world if contexts else None
    many = getattr(world, "nearest_distances_many", None)
    if world is None or many is None:
        return 0
    queries = list(dict.fromkeys(queries))
    todo = [c for c in contexts if any(("nearest", q) not in c._memo for q in queries)]
    by_robot: dict[str, list[EvalContext]] = {}
    for c in todo:
        by_robot.setdefault(c.robot, []).append(c)
    groups = {r: [q.bodies(world, r) for q in queries] for r in by_robot}
    rows = {r: [c.distance_rows() for c in cs] for r, cs in by_robot.items()}
    asked = [(r, np.concatenate([c.configs[k] for c, k in zip(cs, rows[r], strict=True)]),
              groups[r]) for r, cs in by_robot.items()
             if sum(int(k.size) for k in rows[r])]
    values = dict(zip([a[0] for a in asked],
                      many(asked, [q.max_distance for q in queries]) if asked else [],
                      strict=True))
    count = 0
    for r, cs in by_robot.items():
        got = values.get(r)
        start = 0
        for c, k in zip(cs, rows[r], strict=True):
            for g, q in enumerate(queries):
                out = np.full(c.configs.shape[0], np.nan)
                if got is not None and k.size and groups[r][g]:
                    out[k] = np.asarray(got, dtype=np.float64)[start:start + k.size, g]
                c._memo[("nearest", q)] = out
            start += int(k.size)
        count += start
    return count
