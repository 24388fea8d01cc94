"""Robot stations over pybullet (:class:`PybulletWorld`): named robots and obstacles,
implementing :class:`~vasim.mrcp.interfaces.ProximityWorld`; the arms are
:mod:`vasim.mrcp.arm`.

A world owns a private DIRECT client (never the GUI); two worlds never share state.

**Decision** (distances; the kernel makes hundreds of queries per cycle, issue #7 §5):
:meth:`PybulletWorld.min_distances` answers robots and sphere obstacles with the compiled
sphere-swept model of the link hulls (``vasim.mrcp._distance_kernels``): a conservative
lower bound of pybullet's value, ``-COMPILED_TOLERANCE <= model - pybullet <= 1e-5`` m
where pybullet finds no penetration; in penetration a lower bound whose error grows with
the depth (1.1 mm at 7 cm measured), or ``-inf`` where it has no estimate (deep overlaps;
``refine_below`` asks pybullet instead); pybullet for other obstacle shapes.
:meth:`PybulletWorld.min_distance` and :meth:`PybulletWorld.in_collision` stay pybullet's
answers: the model only chooses which link pairs pybullet is asked about.
``PybulletWorld(compiled_distances=False)`` asks pybullet everything.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import pybullet as pb
import trimesh
from numpy.typing import NDArray

from vasim.core.errors import ConfigError
from vasim.mrcp import dh
from vasim.mrcp._distance_kernels import (
    swept_distances,
    swept_distances_many,
    swept_nearest_many,
    swept_pair_bounds,
    swept_pair_bounds_bodies,
)
from vasim.mrcp.arm import _Client, _load_robot, _quat, pose_matrix
from vasim.mrcp.dh import RobotModel
from vasim.mrcp.interfaces import FloatArray, Proximity
from vasim.mrcp.urdf import model_key
from vasim.mrcp.world_sweeps import (
    _UNIT,
    HULL_MARGIN,
    _link_spheres,
    _robot_sweep,
    _sphere_sweep,
    _Sweep,
)

_NAN3 = np.full(3, np.nan)


_SELF_PAIRS: dict[str, tuple[tuple[int, int], ...]] = {}   # per model content
#: Bodies the compiled model puts nearer than this [m] are queried in pybullet (exact);
#: ``-inf`` (default): never; a penetration is then the model's value, a lower bound
#: (its error grows with the depth: 1.1 mm at 7 cm, 2.6 mm at 15 cm measured) or ``-inf``
#: where the key-point hulls of two links meet (no estimate). ``0.0`` refines every
#: penetration to pybullet's depth.
REFINE_BELOW = -math.inf
#: Direction improvements of the compiled model per link pair (see _distance_kernels).
DIRECTION_ITERATIONS = 1
#: The compiled model's distances are never above pybullet's by more than 1e-5 m and,
#: where pybullet finds no penetration, never below by more than this [m] (a conservative
#: lower bound; measured: 0.82 mm, from the polytope's support direction and pybullet's
#: 0.97-1.0 mm margin). In penetration the error grows with the depth (1.09 mm at 7 cm,
#: 2.6 mm at 15 cm measured); it stays a lower bound there, and pruning allows the whole
#: depth (``_min_distance_among``); held by
#: tests/mrcp/test_world_distances.py and test_world_review.py.
COMPILED_TOLERANCE = 1e-3
#: The compiled model is never more than this [m] above pybullet's distance.
_ABOVE = 1e-5
_PAIRS: dict[tuple[int, int], NDArray[np.int64]] = {}
_SELF_PAIR_ARRAYS: dict[tuple[tuple[int, int], ...], NDArray[np.int64]] = {}


def _self_pair_array(pairs: tuple[tuple[int, int], ...]) -> NDArray[np.int64]:
    """Self-collision pairs (pybullet link indices) as model link indices ``(P, 2)``."""
    if pairs not in _SELF_PAIR_ARRAYS:
        _SELF_PAIR_ARRAYS[pairs] = np.array(pairs, dtype=np.int64).reshape(-1, 2) + 1
    return _SELF_PAIR_ARRAYS[pairs]


_THRESHOLDS = (0.01, 0.04, 0.16, 0.48)    # [m] the growing searches of _closest


@dataclass
class _Robot:
    model: RobotModel
    body: int
    base: FloatArray
    q: FloatArray
    self_pairs: tuple[tuple[int, int], ...]
    frames: FloatArray | None = None     # link frames at q (compiled model), lazily
    sweep: _Sweep | None = None          # its compiled distance model, looked up once


class PybulletWorld:
    """A station: named robots and obstacles in one private pybullet client; implements
    :class:`~vasim.mrcp.interfaces.ProximityWorld`.

    Link indices in :class:`Proximity` are pybullet's: ``-1`` the base (DH link 0), ``k - 1``
    DH link ``k``; the TCP link (index ``n``) has no geometry.

    Self-collision checks skip adjacent links and the pairs that touch in every one of 200
    sampled configurations (the "always in collision" rule of MoveIt's set-up assistant:
    e.g. the wrist housings, which overlap by construction).
    """

    def __init__(self, compiled_distances: bool = True,
                 refine_below: float = REFINE_BELOW) -> None:
        self._client = _Client()
        self._cid = self._client.id
        self._robots: dict[str, _Robot] = {}
        self._obstacles: dict[str, int] = {}
        self.compiled_distances = compiled_distances
        self.refine_below = float(refine_below)
        # sphere obstacles for the compiled model: name -> (model, (1, 4, 4) frame)
        self._sphere_obstacles: dict[str, tuple[_Sweep, FloatArray]] = {}
        self._packs: dict[tuple[str, ...], tuple[FloatArray, ...]] = {}

    # -- building ----------------------------------------------------------------------
    def _check_new(self, name: str) -> None:
        if name in self._robots or name in self._obstacles:
            raise ConfigError(f"a body named {name!r} already exists", field="name")

    def add_robot(self, name: str, robot: RobotModel, base: FloatArray | None = None,
                  q: FloatArray | None = None) -> int:
        """Adds an arm at ``base`` (``(4, 4)`` world-from-base) posed at ``q`` (default home)."""
        self._check_new(name)
        base = pose_matrix() if base is None else np.array(base, dtype=float)
        body = _load_robot(self._cid, robot, base)
        entry = _Robot(robot, body, base, np.zeros(robot.n_joints), ())   # as loaded
        self._robots[name] = entry
        entry.self_pairs = self._self_pairs(name)
        self.set_configuration(name, robot.home if q is None else q)
        return body

    def _self_pairs(self, name: str, samples: int = 200) -> tuple[tuple[int, int], ...]:
        r = self._robots[name]
        key = model_key(r.model)
        if key in _SELF_PAIRS:
            return _SELF_PAIRS[key]
        n = r.model.n_joints
        cand = [(a, b) for a in range(-1, n) for b in range(a + 2, n)]
        rng = np.random.default_rng(0)
        qs = rng.uniform(r.model.lower, r.model.upper, size=(samples, n))
        always = dict.fromkeys(cand, True)
        for q in qs:
            self.set_configuration(name, q)
            for pair in cand:
                if always[pair] and not self._links_touch(r.body, pair[0], r.body, pair[1]):
                    always[pair] = False
        _SELF_PAIRS[key] = tuple(p for p in cand if not always[p])
        return _SELF_PAIRS[key]

    def add_box(self, name: str, half_extents: FloatArray, position: FloatArray,
                rotation: FloatArray | None = None) -> int:
        """Adds a static box obstacle (half extents ``(3,)`` [m])."""
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=[float(v) for v in
                                                                   half_extents],
                                        physicsClientId=self._cid)
        return self._add_obstacle(name, shape, position, rotation)

    def add_sphere(self, name: str, radius: float, position: FloatArray) -> int:
        """Adds a static sphere obstacle."""
        shape = pb.createCollisionShape(pb.GEOM_SPHERE, radius=float(radius),
                                        physicsClientId=self._cid)
        body = self._add_obstacle(name, shape, position, None)
        self._sphere_obstacles[name] = (_sphere_sweep(radius),
                                        pose_matrix(np.asarray(position, float))[None])
        return body

    def add_convex(self, name: str, vertices: FloatArray, position: FloatArray | None = None,
                   rotation: FloatArray | None = None) -> int:
        """Adds a static obstacle: the convex hull (trimesh) of ``vertices`` ``(m, 3)``, body
        frame [m]."""
        hull = trimesh.convex.convex_hull(np.asarray(vertices, dtype=float))
        shape = pb.createCollisionShape(pb.GEOM_MESH,
                                        vertices=[list(map(float, v)) for v in hull.vertices],
                                        physicsClientId=self._cid)
        return self._add_obstacle(name, shape, np.zeros(3) if position is None else position,
                                  rotation)

    def _add_obstacle(self, name: str, shape: int, position: FloatArray,
                      rotation: FloatArray | None) -> int:
        self._check_new(name)
        body = pb.createMultiBody(baseMass=0.0, baseCollisionShapeIndex=shape,
                                  basePosition=[float(v) for v in position],
                                  baseOrientation=_quat(np.eye(3) if rotation is None
                                                        else np.asarray(rotation)),
                                  physicsClientId=self._cid)
        self._obstacles[name] = body
        return body

    def set_obstacle_pose(self, name: str, position: FloatArray,
                          rotation: FloatArray | None = None) -> None:
        """Moves an obstacle (e.g. the seed's moving obstacle with a hole)."""
        body = self._obstacles[self._known(name, obstacle=True)]
        if name in self._sphere_obstacles:
            self._sphere_obstacles[name] = (self._sphere_obstacles[name][0],
                                            pose_matrix(np.asarray(position, float))[None])
        pb.resetBasePositionAndOrientation(
            body, [float(v) for v in position],
            _quat(np.eye(3) if rotation is None else np.asarray(rotation)),
            physicsClientId=self._cid)

    # -- ProximityWorld ----------------------------------------------------------------
    def robot_names(self) -> list[str]:
        return list(self._robots)

    def obstacle_names(self) -> list[str]:
        return list(self._obstacles)

    def robot_model(self, name: str) -> RobotModel:
        return self._robots[self._known(name, robot=True)].model

    def robot_base(self, name: str) -> FloatArray:
        return self._robots[self._known(name, robot=True)].base.copy()

    def body_id(self, name: str) -> int:
        """The pybullet body of a named robot or obstacle (for backend-level tools)."""
        if name in self._robots:
            return self._robots[name].body
        return self._obstacles[self._known(name)]

    @property
    def client_id(self) -> int:
        return self._cid

    def _known(self, name: str, robot: bool = False, obstacle: bool = False) -> str:
        if (name in self._robots and (robot or not obstacle)) or \
                (name in self._obstacles and (obstacle or not robot)):
            return name
        names = (list(self._robots) if robot or not obstacle else []) + \
                (list(self._obstacles) if obstacle or not robot else [])
        raise KeyError(f"unknown body {name!r} (known: {', '.join(names) or 'none'})")

    def set_configuration(self, robot: str, q: FloatArray) -> None:
        r = self._robots[self._known(robot, robot=True)]
        q = np.asarray(q, dtype=float)
        if q.shape != (r.model.n_joints,):
            raise ValueError(f"{robot}: q must have shape ({r.model.n_joints},), got {q.shape}")
        if not np.all(np.isfinite(q)):      # pybullet would drop the arm from every query
            raise ValueError(f"{robot}: q must be finite, got {q!r}")
        changed = np.flatnonzero(q != r.q)
        if changed.size:
            pb.resetJointStatesMultiDof(r.body, [int(j) for j in changed],
                                        targetValues=[[float(q[j])] for j in changed],
                                        physicsClientId=self._cid)
        r.q = q.copy()
        r.q.setflags(write=False)
        if changed.size:
            r.frames = None

    def configuration(self, robot: str) -> FloatArray:
        return self._robots[self._known(robot, robot=True)].q.copy()

    def joint_view(self, robot: str) -> FloatArray:
        """The robot's current joints without a copy (read-only; for hot query loops)."""
        return self._robots[robot].q

    def min_distance(self, a: str, b: str, max_distance: float = 1.0) -> Proximity:
        """Closest approach between two named bodies (signed, < 0 = penetration), or
        ``distance = max_distance`` with NaN witnesses when farther than ``max_distance``.

        Branch and bound over link pairs: each link's bounding sphere gives a lower bound of
        the pair's distance; pairs are queried in pybullet in increasing bound order, with
        the best distance so far as the threshold, until the next bound exceeds it. Exact
        (the same minimum as one whole-body query) at a fraction of the cost.
        """
        if a == b:
            raise ValueError(f"min_distance needs two different bodies, got {a!r} twice "
                             "(self-proximity: in_collision / self_collision_pairs)")
        if self.compiled_distances:
            pairs = self._all_pairs(a, b)
            bounds = None if pairs is None else self._pair_bounds(
                a, b, pairs, max_distance + _ABOVE, COMPILED_TOLERANCE + _ABOVE)
            if pairs is not None and bounds is not None and not np.any(np.isneginf(bounds)):
                return self._min_distance_among(a, b, pairs, bounds, max_distance)
        spheres_a, spheres_b = self._spheres(a), self._spheres(b)
        body_a, body_b = self.body_id(a), self.body_id(b)
        ca, ra, la = spheres_a
        cb, rb, lb = spheres_b
        bound = (np.linalg.norm(ca[:, None, :] - cb[None, :, :], axis=2)
                 - ra[:, None] - rb[None, :])
        order = np.argsort(bound, axis=None)
        best = Proximity(float(max_distance), _NAN3.copy(), _NAN3.copy())
        flat = bound.ravel()
        for idx in order:
            if flat[idx] >= best.distance:
                break
            i, j = divmod(int(idx), len(lb))
            pts = pb.getClosestPoints(body_a, body_b, best.distance, linkIndexA=int(la[i]),
                                      linkIndexB=int(lb[j]), physicsClientId=self._cid)
            if pts:
                p = min(pts, key=lambda x: x[8])
                if p[8] < best.distance:
                    best = Proximity(float(p[8]), np.array(p[5]), np.array(p[6]), int(p[3]),
                                     int(p[4]))
        return best

    def min_distances(self, robot: str, configs: FloatArray, bodies: Sequence[str],
                      max_distance: float = 1.0) -> FloatArray:
        """``(N, B)`` minimum distances from ``robot`` posed at each of ``configs`` ``(N, n)``
        to each of ``bodies`` (other robots at their current configurations, obstacles),
        capped at ``max_distance``: the values of posing the robot and calling
        :meth:`min_distance` per body, within :data:`COMPILED_TOLERANCE`.

        **Decision** (cost: the kernel makes hundreds of these queries per 18 ms cycle):
        robots and sphere obstacles are answered by the compiled sphere-swept model of the
        link hulls (``vasim.mrcp._distance_kernels``, a few µs per query, no pybullet call);
        a pair the model puts nearer than ``refine_below`` (default ``-inf``: none), and
        every other kind of obstacle, is queried in pybullet with the robot posed (exact).
        A penetration is reported as the model's (lower) value, or ``-inf`` where the model
        has no estimate: callers take any value below 0 as a collision.
        ``compiled_distances=False`` queries everything in pybullet. The robot's pose in
        the world is unchanged on return.
        """
        r, qs = self._checked_configs(robot, configs)
        names = list(bodies)
        out = np.full((qs.shape[0], len(names)), float(max_distance))
        exact: list[tuple[int, int]] = []
        if self.compiled_distances:
            sweep_a = _robot_sweep(r.model)
            frames_a = np.ascontiguousarray(dh.frames_many(r.model, qs, r.base)[:, :-1])
            models = [self._sweep_of(name) for name in names]
            modelled = [j for j, m in enumerate(models) if m is not None]
            exact = [(i, j) for j in range(len(names)) if models[j] is None
                     for i in range(qs.shape[0])]
            if modelled:
                packed = self._packed([names[j] for j in modelled])
                frames_b = np.concatenate([models[j][1] for j in modelled])  # type: ignore[index]  # model
                dist = np.empty((qs.shape[0], len(modelled)))
                swept_distances(frames_a, sweep_a.pts, sweep_a.count, sweep_a.scale,
                                sweep_a.ball, sweep_a.centre, sweep_a.radius, frames_b,
                                *packed, _UNIT[0], _UNIT[1], float(max_distance),
                                DIRECTION_ITERATIONS, dist)
                # Refined below refine_below only. A penetration stays the model's value
                # (a lower bound: more negative than pybullet's, by up to 2.6 mm at 15 cm
                # depth) or -inf when the key-point hulls meet (no estimate): the indices
                # need the sign, not the depth (CR counts both as an impact), and refining
                # every penetration doubled the 4-robot cycle (15.5 vs 7.7 ms).
                threshold = self.refine_below
                for col, j in enumerate(modelled):
                    for i in range(qs.shape[0]):
                        if dist[i, col] < threshold:
                            exact.append((i, j))
                        else:
                            out[i, j] = min(float(dist[i, col]), max_distance)
        else:
            exact = [(i, j) for i in range(qs.shape[0]) for j in range(len(names))]
        self._fill_exact(robot, qs, names, exact, max_distance, out)
        return out

    def _fill_exact(self, robot: str, qs: FloatArray, names: Sequence[str],
                    exact: Sequence[tuple[int, int]], max_distance: float,
                    out: FloatArray) -> None:
        """``out[i, j]``: pybullet's distance from ``robot`` posed at ``qs[i]`` to body
        ``names[j]`` for each ``(i, j)`` of ``exact`` (the robot's pose restored)."""
        if not exact:
            return
        saved = self._robots[robot].q
        try:
            for i in sorted({i for i, _ in exact}):
                self.set_configuration(robot, qs[i])
                for ii, j in exact:
                    if ii == i:
                        out[i, j] = min(self.min_distance(robot, names[j],
                                                          max_distance).distance,
                                        max_distance)
        finally:
            self.set_configuration(robot, saved)

    def _checked_configs(self, robot: str, configs: FloatArray) -> tuple[_Robot, FloatArray]:
        r = self._robots[self._known(robot, robot=True)]
        qs = np.atleast_2d(np.asarray(configs, dtype=float))
        if qs.shape[1:] != (r.model.n_joints,):
            raise ValueError(f"{robot}: configs must have shape (N, {r.model.n_joints}), "
                             f"got {qs.shape}")
        if not np.all(np.isfinite(qs)):     # NaN joints: the arm vanishes from the checks
            bad = int(np.flatnonzero(~np.all(np.isfinite(qs), axis=1))[0])
            raise ValueError(f"{robot}: configs must be finite, row {bad} is {qs[bad]!r}")
        return r, qs

    def min_distances_many(self, queries: Sequence[tuple[str, FloatArray, Sequence[str]]],
                           max_distance: float = 1.0) -> list[FloatArray]:
        """:meth:`min_distances` for several robots at once: per query ``(robot, configs
        (N, n), bodies)`` the ``(N, B)`` array ``min_distances(robot, configs, bodies,
        max_distance)`` returns, bit for bit, from one compiled call per robot model
        (``swept_distances_many``: the robots' link frames and every distance) instead of
        one call per robot.

        **Decision** (issue #17 §4, cost): the kernel's distance queries of a cycle — every
        robot at every trajectory point against every other body — are one compiled call;
        the bodies' world geometry at the current poses is computed once and shared by all
        query robots (per robot it was recomputed for each), and the per-call Python
        (frames, packing, argument checks, the per-value refine loop) is paid once. The
        arithmetic per (configuration, body) is :func:`swept_distances`'s (the same
        compiled steps), so every value is unchanged; a body the model does not cover, a
        value below ``refine_below`` and ``compiled_distances=False`` go to pybullet exactly
        as in :meth:`min_distances`.

        Raises:
            KeyError: an unknown robot or body name.
            ValueError: configurations of the wrong shape or not finite.
        """
        checked = [(robot, *self._checked_configs(robot, configs), list(bodies))
                   for robot, configs, bodies in queries]
        outs = [np.full((qs.shape[0], len(names)), float(max_distance))
                for _, _, qs, names in checked]
        if not self.compiled_distances:
            for (robot, _, qs, names), out in zip(checked, outs, strict=True):
                self._fill_exact(robot, qs, names, [(i, j) for i in range(qs.shape[0])
                                                     for j in range(len(names))],
                                 max_distance, out)
            return outs
        # every body with a compiled model, in world order, stacked once
        stacked = [n for n in (*self._robots, *self._obstacles) if self._sweep_of(n) is not None]
        column = {n: k for k, n in enumerate(stacked)}
        exact: list[list[tuple[int, int]]] = []
        for _, _, qs, names in checked:
            for name in names:
                self._known(name)
            exact.append([(i, j) for j, name in enumerate(names) if name not in column
                          for i in range(qs.shape[0])])
        values: list[FloatArray | None] = [None] * len(checked)
        groups: dict[str, list[int]] = {}
        for qi, (_, r, qs, names) in enumerate(checked):
            if qs.shape[0] and any(name in column for name in names):
                groups.setdefault(model_key(r.model), []).append(qi)
        if groups:
            packed = self._packed(stacked)
            frames_b = np.concatenate([self._sweep_of(n)[1] for n in stacked])  # type: ignore[index]  # stacked: modelled
        for members in groups.values():
            model = checked[members[0]][1].model
            sweep_a = _robot_sweep(model)
            wanted = np.zeros((len(members), len(stacked)), dtype=np.bool_)
            for row, qi in enumerate(members):
                for name in checked[qi][3]:
                    if name in column:
                        wanted[row, column[name]] = True
            qs_all = np.ascontiguousarray(np.concatenate([checked[qi][2] for qi in members]))
            row_query = np.repeat(np.arange(len(members), dtype=np.int64),
                                  [checked[qi][2].shape[0] for qi in members])
            bases = np.ascontiguousarray([checked[qi][1].base for qi in members],
                                         dtype=np.float64)
            dist = np.full((qs_all.shape[0], len(stacked)), np.nan)
            swept_distances_many(model.table, model.tcp, bases, qs_all, row_query, wanted,
                                 sweep_a.pts, sweep_a.count, sweep_a.scale, sweep_a.ball,
                                 sweep_a.centre, sweep_a.radius, frames_b, *packed,
                                 _UNIT[0], _UNIT[1], float(max_distance),
                                 DIRECTION_ITERATIONS, dist)
            start = 0
            for qi in members:
                count = checked[qi][2].shape[0]
                values[qi] = dist[start:start + count]
                start += count
        threshold = self.refine_below
        for qi, (robot, _, qs, names) in enumerate(checked):
            block = values[qi]
            out = outs[qi]
            if block is not None:
                cols = [j for j, name in enumerate(names) if name in column]
                sub = block[:, [column[names[j]] for j in cols]]
                # min(value, max_distance) as min_distances takes it; below refine_below
                # (default -inf: never) the pair goes to pybullet
                refine = sub < threshold
                out[:, cols] = np.where(refine, out[:, cols], np.minimum(sub, max_distance))
                exact[qi].extend((int(i), cols[int(k)]) for i, k in zip(*np.nonzero(refine),
                                                                          strict=True))
            self._fill_exact(robot, qs, names, exact[qi], max_distance, out)
        return outs

    def nearest_distances_many(self, queries: Sequence[tuple[str, FloatArray,
                                                             Sequence[Sequence[str]]]],
                               max_distances: Sequence[float]) -> list[FloatArray]:
        """The nearest body of each group: per query ``(robot, configs (N, n), groups)``
        an ``(N, G)`` array whose column ``g`` is, bit for bit, the row minimum of
        ``min_distances(robot, configs, groups[g], max_distances[g])`` (``max_distances[g]``
        for an empty group); one compiled call per robot model for all queries.

        **Decision** (issue #17 §4, cost): an index that reads only the nearest of a set of
        bodies (CR: every body but the ignored; visibility: the view cone) is answered by
        one branch and bound over the link pairs of the whole set
        (``swept_nearest_many``): the best value so far prunes the pairs of every body of
        the set, not only those of the body it came from, so most bodies' pairs are never
        refined (2.4x fewer operations for 7 RX60B neighbours, measured). The minimum is
        the one of the same full pair values either way, so every value is unchanged. A
        body without a compiled model is asked in pybullet as in :meth:`min_distances`;
        with ``refine_below`` above ``-inf`` or ``compiled_distances=False`` every group
        is :meth:`min_distances`' row minimum.

        Raises:
            KeyError: an unknown robot or body name.
            ValueError: configurations of the wrong shape or not finite, or a group count
                that is not ``len(max_distances)``.
        """
        caps = [float(v) for v in max_distances]
        checked = [(robot, *self._checked_configs(robot, configs), [list(g) for g in groups])
                   for robot, configs, groups in queries]
        for robot, _, _, groups in checked:
            if len(groups) != len(caps):
                raise ValueError(f"nearest_distances_many: {robot}: {len(groups)} groups for "
                                 f"{len(caps)} max_distances")
            for group in groups:
                for name in group:
                    self._known(name)
        outs = [np.empty((qs.shape[0], len(caps))) for _, _, qs, _ in checked]
        if not self.compiled_distances or self.refine_below > -math.inf:
            for (robot, _, qs, groups), out in zip(checked, outs, strict=True):
                for col, (names, cap) in enumerate(zip(groups, caps, strict=True)):
                    out[:, col] = (self.min_distances(robot, qs, names, cap).min(axis=1)
                                   if names else cap)
            return outs
        stacked = [n for n in (*self._robots, *self._obstacles) if self._sweep_of(n) is not None]
        column = {n: k for k, n in enumerate(stacked)}
        by_model: dict[str, list[int]] = {}
        for qi, (_, r, qs, _) in enumerate(checked):
            if qs.shape[0]:
                by_model.setdefault(model_key(r.model), []).append(qi)
        if by_model:
            packed = self._packed(stacked)
            frames_b = np.concatenate([self._sweep_of(n)[1] for n in stacked])  # type: ignore[index]  # stacked: modelled
            cutoffs = np.array(caps, dtype=np.float64)
        for members in by_model.values():
            model = checked[members[0]][1].model
            sweep_a = _robot_sweep(model)
            mask = np.zeros((len(members), len(caps), len(stacked)), dtype=np.bool_)
            for row, qi in enumerate(members):
                for col, names in enumerate(checked[qi][3]):
                    for name in names:
                        if name in column:
                            mask[row, col, column[name]] = True
            qs_all = np.ascontiguousarray(np.concatenate([checked[qi][2] for qi in members]))
            row_query = np.repeat(np.arange(len(members), dtype=np.int64),
                                  [checked[qi][2].shape[0] for qi in members])
            bases = np.ascontiguousarray([checked[qi][1].base for qi in members],
                                         dtype=np.float64)
            got = np.empty((qs_all.shape[0], len(caps)))
            swept_nearest_many(model.table, model.tcp, bases, qs_all, row_query, mask,
                               cutoffs, sweep_a.pts, sweep_a.count, sweep_a.scale,
                               sweep_a.ball, sweep_a.centre, sweep_a.radius, frames_b,
                               *packed, _UNIT[0], _UNIT[1], DIRECTION_ITERATIONS, got)
            start = 0
            for qi in members:
                count = checked[qi][2].shape[0]
                outs[qi][:] = got[start:start + count]
                start += count
        for (robot, _, qs, groups), out in zip(checked, outs, strict=True):
            for col, (names, cap) in enumerate(zip(groups, caps, strict=True)):
                others = [name for name in names if name not in column]
                if others and qs.shape[0]:      # bodies without a model: pybullet
                    exact = np.full((qs.shape[0], len(others)), cap)
                    self._fill_exact(robot, qs, others, [(i, j) for j in range(len(others))
                                                         for i in range(qs.shape[0])],
                                     cap, exact)
                    out[:, col] = np.minimum(out[:, col], exact.min(axis=1))
        return outs

    def _sweep_of(self, name: str) -> tuple[_Sweep, FloatArray] | None:
        """The compiled model of a body and its link frames, None if it has none."""
        if name in self._robots:
            o = self._robots[name]
            if o.frames is None:
                o.frames = np.ascontiguousarray(dh.frames_one(o.model, o.q, o.base)[:-1])
            if o.sweep is None:
                o.sweep = _robot_sweep(o.model)
            return o.sweep, o.frames
        self._known(name)
        return self._sphere_obstacles.get(name)

    def _packed(self, names: list[str]) -> tuple[FloatArray, ...]:
        """The static compiled-model arrays of several bodies stacked (key points, counts,
        scales, balls, bounding centres and radii), their link starts and margins."""
        key = tuple(names)
        if key not in self._packs:
            sweeps = [self._sweep_of(n)[0] for n in names]  # type: ignore[index]  # names
            counts = [s.pts.shape[0] for s in sweeps]
            self._packs[key] = (
                np.concatenate([s.pts for s in sweeps]),
                np.concatenate([s.count for s in sweeps]),
                np.concatenate([s.scale for s in sweeps]),
                np.concatenate([s.ball for s in sweeps]),
                np.concatenate([s.centre for s in sweeps]),
                np.concatenate([s.radius for s in sweeps]),
                np.concatenate([[0], np.cumsum(counts)]).astype(np.int64),
                np.array([HULL_MARGIN + (HULL_MARGIN if n in self._robots else 0.0)
                          for n in names]))
        return self._packs[key]

    def _pair_bounds(self, a: str, b: str, pairs: NDArray[np.int64], cutoff: float,
                     window: float = math.inf) -> FloatArray | None:
        """Compiled-model distances ``(P,)`` of the link pairs ``pairs`` ``(P, 2)`` (model
        link indices) of two bodies at their current poses (``inf``: surely ``>= cutoff`` or
        more than ``window`` above the smallest); None when a body has no model."""
        sa, sb = self._sweep_of(a), self._sweep_of(b)
        if sa is None or sb is None:
            return None
        (ma, fa), (mb, fb) = sa, sb
        margin = sum(HULL_MARGIN for n in (a, b) if n in self._robots)
        out = np.empty(pairs.shape[0])
        swept_pair_bounds(fa, ma.pts, ma.count, ma.scale, ma.ball, ma.centre, ma.radius, fb,
                          mb.pts, mb.count, mb.scale, mb.ball, mb.centre, mb.radius, _UNIT[0],
                          _UNIT[1], margin, float(cutoff), float(window), DIRECTION_ITERATIONS,
                          np.ascontiguousarray(pairs[:, 0]), np.ascontiguousarray(pairs[:, 1]),
                          out)
        return out

    def _pair_bounds_each(self, a: str, names: Sequence[str], cutoff: float,
                          window: float = math.inf) -> dict[str, FloatArray]:
        """:meth:`_pair_bounds` of all link pairs (:meth:`_all_pairs`) of body ``a`` with
        each body of ``names`` that has a compiled model, in one compiled call
        (``swept_pair_bounds_bodies``: the values of one call per body, bit for bit).

        **Decision** (issue #17 §4, cost): :meth:`in_collision` takes the bounds of every
        other body in one call (8 RX60B: 0.50 -> 0.42 ms for one check of each robot,
        measured). :meth:`min_distance` stays one body a call: the planner's per-body
        queries batched this way measured no gain (1.17 vs 1.17 ms for every robot to every
        body: the cost is the pybullet queries and the Python around them, not the
        bounds), and the query of ``b`` to ``a`` cannot reuse the one of ``a`` to ``b`` at
        the same poses: pybullet's answers are not symmetric bit for bit (1/3 of 1,701
        close pairs of 8 RX60B differ, by up to 3.4 µm, the witness points almost always),
        so reuse would change the planner's steps."""
        sa = self._sweep_of(a)
        modelled = [n for n in dict.fromkeys(names) if n != a and self._sweep_of(n) is not None]
        if sa is None or not modelled:
            return {}
        ma, fa = sa
        packed = self._packed(modelled)
        starts = packed[6]
        frames_b = np.concatenate([self._sweep_of(n)[1] for n in modelled])  # type: ignore[index]  # modelled
        margins = np.array([sum(HULL_MARGIN for n in (a, b) if n in self._robots)
                            for b in modelled])
        out = np.empty(fa.shape[0] * int(starts[-1]))
        swept_pair_bounds_bodies(fa, ma.pts, ma.count, ma.scale, ma.ball, ma.centre, ma.radius,
                                 frames_b, *packed[:6], starts, margins, _UNIT[0], _UNIT[1],
                                 float(cutoff), float(window), DIRECTION_ITERATIONS, out)
        la = fa.shape[0]
        return {n: out[la * int(starts[k]):la * int(starts[k + 1])]
                for k, n in enumerate(modelled)}

    def _all_pairs(self, a: str, b: str) -> NDArray[np.int64] | None:
        sa, sb = self._sweep_of(a), self._sweep_of(b)
        if sa is None or sb is None:
            return None
        la, lb = sa[1].shape[0], sb[1].shape[0]
        key = (la, lb)
        if key not in _PAIRS:
            _PAIRS[key] = np.array([(i, j) for i in range(la) for j in range(lb)],
                                   dtype=np.int64).reshape(-1, 2)
        return _PAIRS[key]

    def _min_distance_among(self, a: str, b: str, pairs: NDArray[np.int64],
                            bounds: FloatArray, max_distance: float) -> Proximity:
        """Exact :meth:`min_distance` from pybullet queries of only the link pairs that can
        hold the minimum: the model's value of a pair is at most ``_ABOVE`` above pybullet's
        and, where it finds no penetration, at most ``COMPILED_TOLERANCE`` below it. In
        penetration the model's error grows with the depth, so the pruning slack does too:
        pairs are queried up to ``max(smallest, 0) + COMPILED_TOLERANCE`` (a model value
        ``< 0`` still means pybullet's is below ``COMPILED_TOLERANCE``)."""
        best = Proximity(float(max_distance), _NAN3.copy(), _NAN3.copy())
        if bounds.size == 0 or float(bounds.min()) >= max_distance + _ABOVE:
            return best
        body_a, body_b = self.body_id(a), self.body_id(b)
        limit = max(float(bounds.min()), 0.0) + COMPILED_TOLERANCE + _ABOVE
        for p in np.argsort(bounds):
            if bounds[p] > limit or bounds[p] >= best.distance + _ABOVE:
                break
            pts = pb.getClosestPoints(body_a, body_b, best.distance,
                                      linkIndexA=int(pairs[p, 0]) - 1,   # pybullet: k - 1
                                      linkIndexB=int(pairs[p, 1]) - 1,
                                      physicsClientId=self._cid)
            if pts:
                q = min(pts, key=lambda x: x[8])
                if q[8] < best.distance:
                    best = Proximity(float(q[8]), np.array(q[5]), np.array(q[6]), int(q[3]),
                                     int(q[4]))
        return best

    def _spheres(self, name: str) -> tuple[FloatArray, FloatArray, NDArray[np.int64]]:
        """World centres ``(L, 3)``, radii ``(L,)`` and pybullet link indices of spheres
        bounding each link of a body (hull + pybullet's margin)."""
        if name in self._robots:
            r = self._robots[name]
            centres, radii = _link_spheres(r.model)
            frames = dh.frames_one(r.model, r.q, r.base)[:-1]
            world = np.einsum("kij,kj->ki", frames[:, :3, :3], centres) + frames[:, :3, 3]
            return world, radii, np.arange(-1, r.model.n_joints)
        body = self.body_id(name)
        lo, hi = (np.array(v) for v in pb.getAABB(body, physicsClientId=self._cid))
        return (((lo + hi) / 2)[None], np.array([np.linalg.norm(hi - lo) / 2 + 1e-9]),
                np.array([-1]))

    def min_distance_links(self, robot: str, other: str, max_distance: float = 1.0
                           ) -> list[Proximity]:
        """One :class:`Proximity` per link of ``robot`` (base first) to the body ``other``
        (e.g. for the per-link impact times of the CR index)."""
        r = self._robots[self._known(robot, robot=True)]
        body_b = self.body_id(other)
        return [self._closest(r.body, body_b, max_distance, link_a=k)
                for k in range(-1, r.model.n_joints)]

    def _closest(self, body_a: int, body_b: int, max_distance: float,
                 link_a: int | None = None, link_b: int | None = None) -> Proximity:
        """The closest pair within ``max_distance``, searched with growing thresholds
        (pybullet's cost grows with the number of pairs within the threshold; every pair
        within a threshold is returned, so the first non-empty answer holds the minimum)."""
        kwargs: dict[str, int] = {"physicsClientId": self._cid}
        if link_a is not None:
            kwargs["linkIndexA"] = link_a
        if link_b is not None:
            kwargs["linkIndexB"] = link_b
        max_distance = float(max_distance)
        pts: tuple = ()
        for threshold in (*(t for t in _THRESHOLDS if t < max_distance), max_distance):
            pts = pb.getClosestPoints(body_a, body_b, threshold, **kwargs)
            if pts:
                break
        if not pts:
            return Proximity(max_distance, _NAN3.copy(), _NAN3.copy())
        best = min(pts, key=lambda p: p[8])
        return Proximity(float(best[8]), np.array(best[5]), np.array(best[6]),
                         int(best[3]), int(best[4]))

    def _links_touch(self, body_a: int, link_a: int, body_b: int, link_b: int) -> bool:
        pts = pb.getClosestPoints(body_a, body_b, 0.0, linkIndexA=link_a, linkIndexB=link_b,
                                  physicsClientId=self._cid)
        return any(p[8] <= 0.0 for p in pts)

    def links_in_collision(self, body_a: int, link_a: int, body_b: int, link_b: int) -> bool:
        """True if two links (pybullet indices) touch or overlap (signed distance <= 0)."""
        return self._links_touch(body_a, link_a, body_b, link_b)

    def in_collision(self, robot: str) -> bool:
        """True if the robot touches another body, or itself beyond adjacent links."""
        r = self._robots[self._known(robot, robot=True)]
        names = [n for n in (*self._robots, *self._obstacles) if n != robot]
        # the model's bounds of every other body in one compiled call (the values of one
        # call per body): a model value > _ABOVE means surely apart
        model = self._pair_bounds_each(robot, names, 2.0 * _ABOVE) \
            if self.compiled_distances else {}
        for name in names:
            bounds = model.get(name)
            if bounds is not None and float(bounds.min()) > _ABOVE:
                continue
            pts = pb.getClosestPoints(r.body, self.body_id(name), 0.0,
                                      physicsClientId=self._cid)
            if any(p[8] <= 0.0 for p in pts):
                return True
        self_pairs = r.self_pairs
        if self.compiled_distances and self_pairs:
            idx = _self_pair_array(self_pairs)
            bounds = self._pair_bounds(robot, robot, idx, 2.0 * _ABOVE)
            if bounds is not None:
                self_pairs = tuple(p for p, v in zip(self_pairs, bounds, strict=True)
                                   if v <= _ABOVE)
        return any(self._links_touch(r.body, a, r.body, b) for a, b in self_pairs)

    def self_collision_pairs(self, robot: str) -> tuple[tuple[int, int], ...]:
        """The link pairs (pybullet indices) checked for self-collision."""
        return self._robots[self._known(robot, robot=True)].self_pairs

    def close(self) -> None:
        self._client.close()
