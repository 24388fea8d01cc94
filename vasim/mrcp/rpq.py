"""Robot-aware proximity queries over pybullet: the seed's RPQ optimisations (appendix A).

The seed's RPQ library puts three robot-aware optimisations in front of a generic collision
engine (PQP there, pybullet here), so that "do these two robots collide?" needs as few exact
queries as possible. :class:`RPQ` answers that question for any two bodies of a
:class:`~vasim.mrcp.backend.PybulletWorld` (robots or obstacles) with:

1. **Multi-resolution models**, coarse to fine: the whole robot's axis-aligned box (L4), each
   link's oriented bounding box (L3; separating-axis test, compiled), then the link's convex
   hull, queried in pybullet (L2). The seed's finest level (L1, the 23,012-triangle CAD
   mesh) does not exist here: the convex hulls *are* the robots' collision geometry (spec §2),
   so L2 is exact and the chain ends there (**decision**).
2. **The weight matrix**: every link carries a collision probability ``P`` (initially higher
   for links farther along the chain, as the seed suggests), ``c_ij = P_i + P_j`` orders the
   link-pair queries, and the query stops at the first colliding pair. ``P`` is updated
   online: up after a pair is found colliding, down after a pair is found free
   (``P <- P + rate (1 - P)`` / ``P <- P (1 - rate)``; **decision**: the seed only says
   "increases ... and decreases otherwise").
3. **The collision matrix**: a binary matrix of the link pairs that can ever meet. Two links
   of robots on fixed bases can only meet if the balls they sweep (centre: the robot's
   shoulder, the first joint axis point; radius: a bound from the chain lengths and the
   hull) intersect; impossible pairs are never queried.

The seed's test bed (Table A.1) is :func:`seed_test_bed_pairs` at 400-800 mm
(:func:`facing_pair`). Its collision shares stay below the seed's (20.6/11.2/2.8/1.1/0.5 %
against 52.78/38.30/27.13/12.16/1.52 %); ``bench/mrcp_rpq`` measures why: the shares grow
with the links' bulk (every sphere radius +60 mm: 51.4/33.1/17.4/8.9/2.7 %, the seed's at
400, 500 and 800 mm) far more than with the sampling (a Halton sample over all twelve
joints: 12.9/5.5/2.8/1.0/0.2 %), so the gap is mostly the seed's 23,012-triangle CAD
housings against this model's radius-approximated hulls (``protocols/robots/rx60b.toml``),
which the MRCP scenarios keep.

Every culling test is conservative (the boxes contain the hulls grown by pybullet's margin),
so :meth:`RPQ.collide` returns exactly what :meth:`RPQ.brute_force` (every link pair queried
in pybullet) returns; the tests check that configuration by configuration.

Example:
    >>> import math
    >>> from vasim.mrcp.backend import PybulletWorld, pose_matrix
    >>> from vasim.mrcp.dh import load_robot, rot_z
    >>> world = PybulletWorld()
    >>> rx = load_robot("rx60b")
    >>> _ = world.add_robot("a", rx, pose_matrix([-0.4, 0, 0]))
    >>> _ = world.add_robot("b", rx, pose_matrix([0.4, 0, 0], rot_z(math.pi)))
    >>> rpq = RPQ(world)
    >>> rpq.collide("a", "b"), rpq.brute_force("a", "b")
    (False, False)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pybullet as pb
import trimesh
from numba import njit
from numpy.typing import NDArray

from vasim.core.config import check_number, expect
from vasim.mrcp import dh
from vasim.mrcp.backend import HULL_MARGIN, PybulletWorld
from vasim.mrcp.dh import _chain_kernel
from vasim.mrcp.interfaces import FloatArray
from vasim.mrcp.urdf import link_hulls, model_key

#: extra padding of every bounding box beyond pybullet's hull margin [m]
BOX_PAD = 1e-4


@dataclass
class QueryStats:
    """Counters of how :meth:`RPQ.collide` queries were resolved."""

    queries: int = 0             # robot-pair queries
    collisions: int = 0
    by_box: int = 0              # discarded by the whole-robot boxes (L4)
    pairs_in_matrix: int = 0     # link pairs the collision matrix allowed, summed
    pairs_skipped: int = 0       # link pairs the collision matrix discarded, summed
    obb_tests: int = 0           # link OBB tests run (L3)
    hull_tests: int = 0          # pybullet hull queries run (L2)

    def reset(self) -> None:
        for name in self.__dataclass_fields__:
            setattr(self, name, 0)


@dataclass
class _Body:
    name: str
    body: int
    links: NDArray[np.int64]          # pybullet link indices with geometry
    model: dh.RobotModel | None       # None: a static obstacle
    base: FloatArray
    obb_local: FloatArray             # (L, 4, 4) link-from-box
    half: FloatArray                  # (L, 3) half extents (padded)
    reach: FloatArray                 # (L,) radius of the ball each link sweeps
    p: FloatArray                     # (L,) collision probabilities
    centre: FloatArray = field(default_factory=lambda: np.zeros(3))   # of the reach balls


def _obb_of(vertices: FloatArray) -> tuple[FloatArray, FloatArray]:
    """Link-from-box transform and padded half extents of a vertex cloud's OBB."""
    to_origin, extents = trimesh.bounds.oriented_bounds(vertices)
    return np.linalg.inv(to_origin), np.asarray(extents) / 2.0 + HULL_MARGIN + BOX_PAD


def _chain_reach(model: dh.RobotModel, hull_vertices: list[FloatArray]) -> FloatArray:
    """For each link, a bound on the distance of its points from the shoulder point (frame
    1's origin, on the first joint axis): the chain lengths up to the link's frame plus the
    hull's extent around the frame origin (triangle inequality), plus the margins."""
    out = np.empty(len(hull_vertices))
    chain = 0.0
    shoulder = dh.joint_origin(model.joints[0])[:3, 3]
    for k, verts in enumerate(hull_vertices):
        if k == 0:      # the base is fixed: its actual distance from the shoulder
            out[k] = float(np.max(np.linalg.norm(verts - shoulder, axis=1)))
            continue
        if k >= 2:
            chain += float(np.linalg.norm(dh.joint_origin(model.joints[k - 1])[:3, 3]))
        out[k] = chain + float(np.max(np.linalg.norm(verts, axis=1)))
    return out + HULL_MARGIN + BOX_PAD


_MODEL_BOXES: dict[str, tuple[FloatArray, FloatArray, FloatArray]] = {}


def _model_boxes(model: dh.RobotModel) -> tuple[FloatArray, FloatArray, FloatArray]:
    """Link-from-box transforms ``(L, 4, 4)``, padded half extents ``(L, 3)`` and reach
    bounds ``(L,)`` of a model's links (computed once per model content)."""
    key = model_key(model)
    if key not in _MODEL_BOXES:
        hulls = link_hulls(model)
        obbs = [_obb_of(np.asarray(h.vertices)) for h in hulls]
        _MODEL_BOXES[key] = (np.ascontiguousarray([o[0] for o in obbs]),
                             np.ascontiguousarray([o[1] for o in obbs]),
                             _chain_reach(model, [np.asarray(h.vertices) for h in hulls]))
    return _MODEL_BOXES[key]


@njit(cache=True, nogil=True, fastmath=False)
def _obb_overlap(ta: FloatArray, ea: FloatArray, tb: FloatArray, eb: FloatArray
                 ) -> bool:  # pragma: no cover - compiled
    """Separating-axis test of two oriented boxes (world-from-box ``(4, 4)``, half extents
    ``(3,)``); True if they overlap (Gottschalk et al. 1996, 15 axes)."""
    r = np.empty((3, 3))               # b's axes in a's frame
    t = np.empty(3)
    for i in range(3):
        t[i] = (ta[0, i] * (tb[0, 3] - ta[0, 3]) + ta[1, i] * (tb[1, 3] - ta[1, 3])
                + ta[2, i] * (tb[2, 3] - ta[2, 3]))
        for j in range(3):
            r[i, j] = ta[0, i] * tb[0, j] + ta[1, i] * tb[1, j] + ta[2, i] * tb[2, j]
    absr = np.abs(r) + 1e-12
    for i in range(3):
        if abs(t[i]) > ea[i] + eb[0] * absr[i, 0] + eb[1] * absr[i, 1] + eb[2] * absr[i, 2]:
            return False
    for j in range(3):
        s = t[0] * r[0, j] + t[1] * r[1, j] + t[2] * r[2, j]
        if abs(s) > eb[j] + ea[0] * absr[0, j] + ea[1] * absr[1, j] + ea[2] * absr[2, j]:
            return False
    for i in range(3):
        i1 = (i + 1) % 3
        i2 = (i + 2) % 3
        for j in range(3):
            j1 = (j + 1) % 3
            j2 = (j + 2) % 3
            lhs = abs(t[i2] * r[i1, j] - t[i1] * r[i2, j])
            rhs = (ea[i1] * absr[i2, j] + ea[i2] * absr[i1, j]
                   + eb[j1] * absr[i, j2] + eb[j2] * absr[i, j1])
            if lhs > rhs:
                return False
    return True


@njit(cache=True, nogil=True, fastmath=False)
def _robot_boxes(table: FloatArray, tcp: FloatArray, base: FloatArray, q: FloatArray,
                 obb_local: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """World-from-box transforms ``(n + 1, 4, 4)`` of a robot's links at ``q``."""
    frames = np.empty((q.shape[0] + 2, 4, 4))
    _chain_kernel(table, tcp, base, q, frames)
    out = np.empty_like(obb_local)
    for k in range(obb_local.shape[0]):
        out[k] = frames[k] @ obb_local[k]
    return out


@njit(cache=True, nogil=True, fastmath=False)
def _aabb(boxes: FloatArray, half: FloatArray) -> FloatArray:  # pragma: no cover - compiled
    """``(2, 3)`` min/max corners of the axis-aligned box around oriented boxes."""
    out = np.empty((2, 3))
    out[0, :] = np.inf
    out[1, :] = -np.inf
    for k in range(boxes.shape[0]):
        for ax in range(3):
            ext = (abs(boxes[k, ax, 0]) * half[k, 0] + abs(boxes[k, ax, 1]) * half[k, 1]
                   + abs(boxes[k, ax, 2]) * half[k, 2])
            c = boxes[k, ax, 3]
            out[0, ax] = min(out[0, ax], c - ext)
            out[1, ax] = max(out[1, ax], c + ext)
    return out


@njit(cache=True, nogil=True, fastmath=False)
def _robot_pair_boxes(table_a: FloatArray, tcp_a: FloatArray, base_a: FloatArray,
                      qa: FloatArray, obb_a: FloatArray, half_a: FloatArray,
                      table_b: FloatArray, tcp_b: FloatArray, base_b: FloatArray,
                      qb: FloatArray, obb_b: FloatArray, half_b: FloatArray
                      ) -> tuple[FloatArray, FloatArray, bool]:  # pragma: no cover
    """Both robots' link boxes (world) and whether their whole-robot boxes are apart (L4),
    in one compiled call.

    **Decision** (issue #29 item 5, twelve parameters kept): each robot's six arrays are
    passed one by one, not grouped. numba cannot take a dataclass, and grouping them as two
    tuples cost 14-20 % per call (20.3-20.9 us -> 23.3-25.1 us a call on the shared CI
    machine, 2,000 configurations, median of 7; /tmp bench of this commit) in the RPQ's
    hottest call, for no change in what it computes.
    """
    boxes_a = _robot_boxes(table_a, tcp_a, base_a, qa, obb_a)
    boxes_b = _robot_boxes(table_b, tcp_b, base_b, qb, obb_b)
    aa = _aabb(boxes_a, half_a)
    ab = _aabb(boxes_b, half_b)
    apart = False
    for ax in range(3):
        if aa[1, ax] < ab[0, ax] or ab[1, ax] < aa[0, ax]:
            apart = True
    return boxes_a, boxes_b, apart


@njit(cache=True, nogil=True, fastmath=False)
def _obb_pass(order: NDArray[np.int64], boxes_a: FloatArray, half_a: FloatArray,
              boxes_b: FloatArray, half_b: FloatArray) -> NDArray[np.bool_]:  # pragma: no cover
    """Which of the ordered link pairs ``(P, 2)`` have overlapping OBBs."""
    out = np.zeros(order.shape[0], dtype=np.bool_)
    for p in range(order.shape[0]):
        i, j = order[p, 0], order[p, 1]
        out[p] = _obb_overlap(boxes_a[i], half_a[i], boxes_b[j], half_b[j])
    return out


class RPQ:
    """Robot-pair collision queries with the seed's three optimisations (module docstring).

    Args:
        world: the station; bodies are read at their current poses in it.
        rate: learning rate of the collision probabilities, in [0, 1].
        use_box, use_obb, use_weights, use_matrix: switch each optimisation off to measure
            its effect (results never change, only the work done).
    """

    def __init__(self, world: PybulletWorld, *, rate: float = 0.05, use_box: bool = True,
                 use_obb: bool = True, use_weights: bool = True, use_matrix: bool = True
                 ) -> None:
        check_number(rate, "rate", ge=0.0, le=1.0)
        self.world = world
        self.rate = rate
        self.use_box, self.use_obb = use_box, use_obb
        self.use_weights, self.use_matrix = use_weights, use_matrix
        self.stats = QueryStats()
        self._bodies: dict[str, _Body] = {}
        self._matrices: dict[tuple[str, str], NDArray[np.bool_]] = {}
        self._pairs: dict[tuple[str, str], tuple[NDArray[np.int64], NDArray[np.int64]]] = {}
        self._cid = world.client_id
        for name in world.robot_names():     # the models' boxes and reaches, once
            self._body(name)

    # -- bodies --------------------------------------------------------------------------
    def _body(self, name: str) -> _Body:
        if name in self._bodies:
            return self._bodies[name]
        if name in self.world.robot_names():
            model = self.world.robot_model(name)
            obb_local, half, reach = _model_boxes(model)
            n = model.n_joints
            p0 = 0.5 * (np.arange(n + 1) + 1.0) / (n + 1)   # distal links first
            base = self.world.robot_base(name)
            shoulder = base @ dh.joint_origin(model.joints[0])
            entry = _Body(name, self.world.body_id(name), np.arange(-1, n), model, base,
                          obb_local, half, reach, p0, shoulder[:3, 3].copy())
        else:
            body = self.world.body_id(name)
            entry = _Body(name, body, np.array([-1]), None, np.eye(4), np.eye(4)[None],
                          np.zeros((1, 3)), np.zeros(1), np.full(1, 0.5))
        self._bodies[name] = entry
        return entry

    def _boxes(self, b: _Body) -> tuple[FloatArray, FloatArray]:
        """World-from-box transforms ``(L, 4, 4)`` and half extents ``(L, 3)``."""
        if b.model is None:     # obstacle: its (world) AABB as a box, re-read every query
            lo, hi = (np.array(v) for v in pb.getAABB(b.body, physicsClientId=self._cid))
            t = np.eye(4)[None].copy()
            t[0, :3, 3] = (lo + hi) / 2
            half = ((hi - lo) / 2 + BOX_PAD)[None]
            b.centre = t[0, :3, 3].copy()
            b.reach = np.array([float(np.linalg.norm(half))])
            return t, half
        return _robot_boxes(b.model.table, b.model.tcp, b.base,
                            self.world.joint_view(b.name), b.obb_local), b.half

    def collision_matrix(self, a: str, b: str) -> NDArray[np.bool_]:
        """``(La, Lb)`` True where link i of ``a`` and link j of ``b`` can ever meet."""
        key = (a, b)
        ba, bb = self._body(a), self._body(b)
        if ba.model is None or bb.model is None or key not in self._matrices:
            if ba.model is None:
                self._boxes(ba)
            if bb.model is None:
                self._boxes(bb)
            gap = float(np.linalg.norm(ba.centre - bb.centre))
            mat = ba.reach[:, None] + bb.reach[None, :] >= gap
            if ba.model is not None and bb.model is not None:
                self._matrices[key] = mat
            return mat
        return self._matrices[key]

    def weight_matrix(self, a: str, b: str) -> FloatArray:
        """``(La, Lb)`` query-order weights ``c_ij = P_i + P_j``."""
        return self._body(a).p[:, None] + self._body(b).p[None, :]

    # -- queries -------------------------------------------------------------------------
    def _candidate_pairs(self, a: str, b: str, ba: _Body, bb: _Body
                         ) -> tuple[NDArray[np.int64], NDArray[np.int64]]:
        static = ba.model is not None and bb.model is not None
        if static and (a, b) in self._pairs:
            return self._pairs[(a, b)]
        if self.use_matrix:
            ii, jj = np.nonzero(self.collision_matrix(a, b))
        else:
            ii, jj = np.divmod(np.arange(len(ba.links) * len(bb.links)), len(bb.links))
        if static:
            self._pairs[(a, b)] = (ii, jj)
        return ii, jj

    def _hull_pair(self, ba: _Body, i: int, bb: _Body, j: int) -> bool:
        self.stats.hull_tests += 1
        pts = pb.getClosestPoints(ba.body, bb.body, 0.0, linkIndexA=int(ba.links[i]),
                                  linkIndexB=int(bb.links[j]), physicsClientId=self._cid)
        return any(p[8] <= 0.0 for p in pts)

    def collide(self, a: str, b: str) -> bool:
        """True if bodies ``a`` and ``b`` (at their current poses) touch or overlap."""
        ba, bb = self._body(a), self._body(b)
        st = self.stats
        st.queries += 1
        if ba.model is not None and bb.model is not None:     # two robots: one compiled call
            ma, mb = ba.model, bb.model
            boxes_a, boxes_b, apart = _robot_pair_boxes(
                ma.table, ma.tcp, ba.base, self.world.joint_view(a),
                ba.obb_local, ba.half, mb.table, mb.tcp, bb.base,
                self.world.joint_view(b), bb.obb_local, bb.half)
            half_a, half_b = ba.half, bb.half
        else:
            boxes_a, half_a = self._boxes(ba)
            boxes_b, half_b = self._boxes(bb)
            aa, ab = _aabb(boxes_a, half_a), _aabb(boxes_b, half_b)
            apart = bool(np.any(aa[1] < ab[0]) or np.any(ab[1] < aa[0]))
        if self.use_box and apart:
            st.by_box += 1
            return False
        n_pairs = len(ba.links) * len(bb.links)
        ii, jj = self._candidate_pairs(a, b, ba, bb)
        st.pairs_in_matrix += len(ii)
        st.pairs_skipped += n_pairs - len(ii)
        if self.use_weights:
            w = ba.p[ii] + bb.p[jj]
            idx = np.argsort(-w, kind="stable")
            ii, jj = ii[idx], jj[idx]
        order = np.stack([ii, jj], axis=1).astype(np.int64)
        if self.use_obb:
            overlap = _obb_pass(order, boxes_a, half_a, boxes_b, half_b)
            st.obb_tests += len(order)
            order = order[overlap]
        hit = False
        for i, j in order:
            hit = self._hull_pair(ba, int(i), bb, int(j))
            if self.use_weights:
                self._learn(ba, int(i), hit)
                self._learn(bb, int(j), hit)
            if hit:
                break
        st.collisions += int(hit)
        return hit

    def _learn(self, body: _Body, k: int, hit: bool) -> None:
        if hit:
            body.p[k] += self.rate * (1.0 - body.p[k])
        else:
            body.p[k] *= 1.0 - self.rate

    def brute_force(self, a: str, b: str) -> bool:
        """Every link pair queried in pybullet, no culling, no early exit: the reference."""
        ba, bb = self._body(a), self._body(b)
        hit = False
        for i in range(len(ba.links)):
            for j in range(len(bb.links)):
                pts = pb.getClosestPoints(ba.body, bb.body, 0.0, linkIndexA=int(ba.links[i]),
                                          linkIndexB=int(bb.links[j]),
                                          physicsClientId=self._cid)
                hit = any(p[8] <= 0.0 for p in pts) or hit
        return hit


# ------------------------------------------------------------------ the seed's test bed

#: Seed Table A.1: share of the 9,216 configurations in collision [%] per base distance [mm].
SEED_TABLE_A1 = {400: 52.78, 500: 38.30, 600: 27.13, 700: 12.16, 800: 1.52}
#: Grid points per joint (θ1, θ2, θ3) of each robot's test-bed configurations.
TEST_BED_GRID = (4, 4, 6)


def seed_test_bed_configurations(model: dh.RobotModel) -> FloatArray:
    """``(96, n)`` configurations of one robot for the seed's test bed (appendix A).

    **Decision** (the seed says only that "9216 different joint positions are used to
    generate robot configurations"): 9,216 = 96², so each robot takes 96 configurations and
    the test bed is every pair of them. The 96 are a grid over the arm joints that place the
    links — 4 values of θ1, 4 of θ2, 6 of θ3, each spanning its imposed range end to end —
    with the wrist (θ4..θ6) at the documented home, because the wrist moves only the last
    ~10 cm of the arm and a pair's collision is decided by where the arms are. Measured
    alternatives (``bench/mrcp_rpq``): a scrambled Halton sample over both robots' twelve
    joints collides less at every distance (12.9 % at 400 mm against the grid's 20.6 %).

    Example:
        >>> seed_test_bed_configurations(dh.load_robot("rx60b")).shape
        (96, 6)
    """
    n = model.n_joints
    expect(n >= len(TEST_BED_GRID), n, f"an arm with >= {len(TEST_BED_GRID)} joints (the "
           f"RPQ test bed; {model.name!r})", field="joints")
    axes = [np.linspace(model.lower[j], model.upper[j], k)
            for j, k in enumerate(TEST_BED_GRID)]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(len(axes), -1).T
    rest = np.tile(np.asarray(model.home)[len(axes):], (len(grid), 1))
    return np.hstack([grid, rest])


def seed_test_bed_pairs(model: dh.RobotModel) -> FloatArray:
    """``(9216, 2, n)``: every pair of :func:`seed_test_bed_configurations` (robot a's
    configuration, robot b's), a's index the slower one."""
    one = seed_test_bed_configurations(model)
    m = len(one)
    return np.stack([np.repeat(one, m, axis=0), np.tile(one, (m, 1))], axis=1)


def facing_pair(model: dh.RobotModel, distance: float) -> PybulletWorld:
    """The seed's test bed: robots ``a`` and ``b`` facing each other, bases ``distance``
    [m] apart on the world x axis (a at -distance/2 facing +x, b turned by 180°)."""
    check_number(distance, "distance", gt=0.0)
    world = PybulletWorld()
    world.add_robot("a", model, _pose_x(-distance / 2, 0.0))
    world.add_robot("b", model, _pose_x(distance / 2, np.pi))
    return world


def _pose_x(x: float, yaw: float) -> FloatArray:
    out = np.eye(4)
    out[:3, :3] = dh.rot_z(yaw)
    out[0, 3] = x
    return out


def inflated(model: dh.RobotModel, extra: float) -> dh.RobotModel:
    """``model`` with every link's sphere radius grown by ``extra`` [m] (a bulkier arm: the
    seed's test bed used 23,012-triangle CAD models, this model radius-approximated hulls)."""
    from dataclasses import replace

    if extra == 0.0:
        return model
    return replace(model, name=f"{model.name}_plus{round(extra * 1000)}mm",
                   links=tuple(replace(lk, radius=lk.radius + extra) for lk in model.links))


def collision_share(model: dh.RobotModel, distance: float, pairs: FloatArray) -> float:
    """Share [%] of ``pairs`` ``(N, 2, n)`` in collision at ``distance`` [m], by pybullet's
    whole-body query (the same answers as :meth:`RPQ.collide`, which the bench checks)."""
    world = facing_pair(model, distance)
    try:
        ba, bb, cid = world.body_id("a"), world.body_id("b"), world.client_id
        hits = 0
        for qa, qb in pairs:
            world.set_configuration("a", qa)
            world.set_configuration("b", qb)
            hits += any(p[8] <= 0.0 for p in pb.getClosestPoints(ba, bb, 0.0,
                                                                 physicsClientId=cid))
    finally:
        world.close()
    return 100.0 * hits / max(1, len(pairs))
