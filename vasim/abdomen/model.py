"""Mass-spring organ models: constants (:class:`OrganModel`) apart from state (:class:`OrganState`).

As brax splits ``System`` from ``State``: an :class:`OrganModel` is frozen (topology, rest
shape, stiffness, masses, anchors; its arrays are read-only), an :class:`OrganState` holds what
changes (positions, velocities, time) and is updated in place by
:class:`vasim.abdomen.integrate.OrganSolver`.

**decision** (spec §1, "structural + bending/shear springs, optional volume preservation,
nodes anchored to the abdominal wall/ligaments, damping, gravity"): :func:`build_organ` turns
a closed triangle surface into

* structural springs on every mesh edge (stiffness ``stiffness``);
* bending springs across every edge, between the two vertices opposite it (``bending_stiffness``;
  they resist folding about the edge, the usual mass-spring bending/shear term);
* optional volume preservation by *interior nodes and spokes*: every surface vertex casts a
  ray inward along its normal to the opposite surface; the midpoints (the medial surface or,
  for a tube, its centre line) are clustered on a grid of spacing ``volume_spacing``; each
  cluster becomes an interior node, each surface vertex is tied to its cluster's node by a
  spoke spring and interior nodes within 1.75 spacings of each other are tied together
  (``volume_stiffness``). A closed membrane without such a term collapses under gravity (the
  massspring guide); spokes keep the thickness of thin tubes and thick organs alike, which a
  uniform interior lattice does not (it misses the 6 mm vessel) and a pressure term would
  couple every node to every other one;
* lumped masses: the organ's total mass ``mass`` split in proportion to each surface vertex's
  area (a third of its faces' area); with volume nodes, to the prism under that area down to
  the medial surface, half to the vertex and half to its interior node (``"area"``), or
  equally (``"uniform"``, as Bullet's ``setTotalMass``);
* anchors: the union of :class:`AnchorRule` selections of surface vertices (nodes near a
  plane, a point or the abdominal wall), or every node for a kinematic body (the wall).

Damping model: every node feels a viscous force ``-c (v_i - v_frame(x_i))`` with ``c =
damping`` [N s/m] per node, toward the velocity of the *moving frame* (the physiological
motion the organ rides on, see :mod:`vasim.abdomen.motion`), so breathing is not damped, only
deformation. It is integrated implicitly (it can only dissipate).

Example:
    >>> import trimesh
    >>> mesh = trimesh.creation.icosphere(subdivisions=1, radius=0.03)
    >>> params = OrganParams(stiffness=100.0, mass=0.2, volume=False,
    ...                      anchors=(AnchorRule(to="point", point=(0.0, 0.0, -0.03),
    ...                                          fraction=0.1),))
    >>> model = build_organ(mesh, params, name="ball")
    >>> model.n_nodes, len(model.springs), len(model.anchors)
    (42, 240, 4)
    >>> round(float(model.mass.sum()), 6)
    0.2
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
import trimesh
from numpy.typing import NDArray
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from vasim.abdomen import _kernels
from vasim.core.bounds import (
    ANCHOR_DISTANCE_M,
    COORDINATE_M,
    DIRECTION,
    ORGAN_DAMPING_NS_PER_M,
    ORGAN_EXTENT_M,
    ORGAN_MASS_KG,
    ORGAN_STIFFNESS_N_PER_M,
    Bound,
)
from vasim.core.config import (
    check_bool,
    check_choice,
    check_number,
    check_type,
    check_vec3,
    expect,
)
from vasim.core.errors import ConfigError

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

SPRING_STRUCTURAL = 0
"""Value of :attr:`OrganModel.spring_type` for a mesh-edge spring."""
SPRING_BENDING = 1
"""Value of :attr:`OrganModel.spring_type` for a spring across an edge."""
SPRING_VOLUME = 2
"""Value of :attr:`OrganModel.spring_type` for a spoke or an interior-interior spring."""

DEFAULT_GRAVITY = (0.0, 0.0, -9.81)
"""Gravity [m/s²] in the scene frame (``z`` up, toward the abdominal wall)."""

AnchorTarget = Literal["plane", "point", "wall"]
MassDistribution = Literal["area", "uniform"]
_ANCHOR_TARGETS = ("plane", "point", "wall")
_MASS_DISTRIBUTIONS = ("area", "uniform")
_VOLUME_LINK_RADIUS = 1.75
"""Interior nodes closer than this many ``volume_spacing`` are tied by a spring."""


def _vec3(value: object, *, field_name: str, unit: bool = False,
          bound: Bound | None = None) -> tuple[float, float, float]:
    """Three finite numbers (within ``bound``), normalised if ``unit`` (the core toolkit's
    :func:`vasim.core.config.check_vec3`)."""
    if isinstance(value, np.ndarray):
        value = value.tolist()
    v = check_vec3(value, field_name, bound=bound, nonzero=unit)
    if unit:
        norm = math.hypot(*v)
        v = (v[0] / norm, v[1] / norm, v[2] / norm)
    return v


def _number(value: object, *, field_name: str, low: float | None = None,
            low_open: bool = False, high: float | None = None,
            bound: Bound | None = None) -> float:
    """A finite number in the given range (the core toolkit's
    :func:`vasim.core.config.check_number`)."""
    return check_number(value, field_name, bound=bound,
                        gt=low if low_open else None, ge=None if low_open else low, le=high)


@dataclass(frozen=True)
class AnchorRule:
    """Selects anchored surface vertices (attachments to the wall, ligaments, the back).

    Exactly one of ``within`` and ``fraction`` is given: the vertices whose distance to the
    target is at most ``within`` [m], or the ``fraction`` of the surface vertices nearest to
    it (at least one vertex).

    Attributes:
        to: ``"plane"`` (distance = signed distance ``normal . (x - point)``: vertices on the
            far side count as within), ``"point"`` (Euclidean distance to ``point``) or
            ``"wall"`` (distance to the abdominal wall's surface; the scene supplies it).
        point: (3,) a point of the plane, or the point [m], scene frame.
        normal: (3,) plane normal (normalised on construction), for ``to = "plane"``.
        within: distance [m].
        fraction: in (0, 1].
    """

    to: AnchorTarget
    point: tuple[float, float, float] | None = None
    normal: tuple[float, float, float] | None = None
    within: float | None = None
    fraction: float | None = None

    def __post_init__(self) -> None:
        check_choice(self.to, "to", _ANCHOR_TARGETS)
        expect((self.within is None) != (self.fraction is None),
                {"within": self.within, "fraction": self.fraction},
                "exactly one of 'within' [m] and 'fraction'", field="within")
        if self.within is not None:
            _number(self.within, field_name="within", low=0.0, bound=ANCHOR_DISTANCE_M)
        if self.fraction is not None:
            _number(self.fraction, field_name="fraction", low=0.0, low_open=True, high=1.0)
        if self.to in ("plane", "point"):
            expect(self.point is not None, None, f"a point (an anchor to a {self.to} needs "
                    "'point')", field="point")
            object.__setattr__(self, "point", _vec3(self.point, field_name="point",
                                                    bound=COORDINATE_M))
        if self.to == "plane":
            expect(self.normal is not None, None, "a normal (an anchor to a plane needs "
                    "'normal')", field="normal")
            object.__setattr__(self, "normal", _vec3(self.normal, field_name="normal",
                                                     unit=True, bound=DIRECTION))


@dataclass(frozen=True)
class OrganParams:
    """Physical parameters of one organ (what a scene file sets; see :func:`build_organ`).

    Attributes:
        stiffness: structural (mesh-edge) spring stiffness [N/m], >= 0.
        bending_stiffness: stiffness of the springs across each edge [N/m], >= 0.
        mass: total mass [kg], > 0.
        damping: viscous damping per node [N s/m], >= 0, toward the moving frame.
        volume: add interior nodes and spokes (volume preservation).
        volume_stiffness: stiffness of spokes and interior springs [N/m], >= 0.
        volume_spacing: grid spacing [m] of the interior nodes; ``None``: twice the mean edge
            length of the surface.
        mass_distribution: ``"area"`` or ``"uniform"`` (see the module docstring).
        anchors: anchor selections (their union is anchored).
        kinematic: every node is anchored (it moves only with the physiological motion; used
            for the abdominal wall).
    """

    stiffness: float = 100.0
    bending_stiffness: float = 10.0
    mass: float = 1.0
    damping: float = 0.01
    volume: bool = True
    volume_stiffness: float = 50.0
    volume_spacing: float | None = None
    mass_distribution: MassDistribution = "area"
    anchors: tuple[AnchorRule, ...] = field(default_factory=tuple)
    kinematic: bool = False

    def __post_init__(self) -> None:
        _number(self.stiffness, field_name="stiffness", bound=ORGAN_STIFFNESS_N_PER_M)
        _number(self.bending_stiffness, field_name="bending_stiffness",
                bound=ORGAN_STIFFNESS_N_PER_M)
        _number(self.mass, field_name="mass", bound=ORGAN_MASS_KG)
        _number(self.damping, field_name="damping", bound=ORGAN_DAMPING_NS_PER_M)
        _number(self.volume_stiffness, field_name="volume_stiffness",
                bound=ORGAN_STIFFNESS_N_PER_M)
        if self.volume_spacing is not None:
            _number(self.volume_spacing, field_name="volume_spacing", low=0.0, low_open=True,
                    bound=ORGAN_EXTENT_M)
        check_bool(self.volume, "volume")
        check_bool(self.kinematic, "kinematic")
        check_choice(self.mass_distribution, "mass_distribution", _MASS_DISTRIBUTIONS)
        anchors = tuple(self.anchors)
        for i, rule in enumerate(anchors):
            check_type(rule, f"anchors[{i}]", AnchorRule, "an AnchorRule")
        object.__setattr__(self, "anchors", anchors)


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.ascontiguousarray(a).copy()
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class OrganModel:
    """The constants of one mass-spring organ (arrays are read-only).

    Attributes:
        name: unique organ name.
        rest: (n, 3) rest node positions [m], scene frame. Nodes ``[0, n_surface)`` are the
            surface mesh vertices in mesh order; interior nodes follow.
        faces: (f, 3) surface triangles (indices < ``n_surface``), outward.
        n_surface: number of surface nodes.
        springs: (s, 2) node index pairs.
        rest_length: (s,) [m], > 0.
        stiffness: (s,) [N/m], >= 0.
        mass: (n,) [kg], > 0.
        damping: viscous damping per node [N s/m] toward the moving frame (module docstring).
        anchors: (a,) anchored node indices, sorted and unique.
        gravity: (3,) [m/s²].
        delicate: contact counts as damage (the vessel).
        kind: tissue class (``vasim.abdomen.anatomy.OrganKind``).
        color: RGB in [0, 1].
        spring_type: (s,) :data:`SPRING_STRUCTURAL`, :data:`SPRING_BENDING` or
            :data:`SPRING_VOLUME`.
    """

    name: str
    rest: FloatArray
    faces: IntArray
    n_surface: int
    springs: IntArray
    rest_length: FloatArray
    stiffness: FloatArray
    mass: FloatArray
    damping: float
    anchors: IntArray
    gravity: FloatArray
    delicate: bool = False
    kind: str = "parenchyma"
    color: tuple[float, float, float] = (0.8, 0.4, 0.4)
    spring_type: IntArray | None = None

    def __post_init__(self) -> None:
        def fail(fld: str, msg: str) -> ConfigError:
            return ConfigError(f"organ {self.name!r}: {msg}", field=fld)

        rest = np.asarray(self.rest, dtype=np.float64)
        if rest.ndim != 2 or rest.shape[1] != 3 or len(rest) == 0:
            raise fail("rest", f"must have shape (n, 3), got {rest.shape}")
        if not np.all(np.isfinite(rest)):
            raise fail("rest", "has non-finite coordinates")
        n = len(rest)
        if not 0 < int(self.n_surface) <= n:
            raise fail("n_surface", f"must be in [1, {n}], got {self.n_surface!r}")
        faces = np.asarray(self.faces, dtype=np.int64).reshape(-1, 3)
        if faces.size and (faces.min() < 0 or faces.max() >= self.n_surface):
            raise fail("faces", f"indices must be in [0, {self.n_surface}), got "
                                f"[{faces.min()}, {faces.max()}]")
        springs = np.asarray(self.springs, dtype=np.int64).reshape(-1, 2)
        s = len(springs)
        if s and (springs.min() < 0 or springs.max() >= n):
            raise fail("springs", f"indices must be in [0, {n}), got "
                                  f"[{springs.min()}, {springs.max()}]")
        if s and np.any(springs[:, 0] == springs[:, 1]):
            i = int(np.flatnonzero(springs[:, 0] == springs[:, 1])[0])
            raise fail(f"springs[{i}]", f"connects node {springs[i, 0]} to itself")
        arrays = {}
        for fld, shape in (("rest_length", (s,)), ("stiffness", (s,)), ("mass", (n,))):
            a = np.asarray(getattr(self, fld), dtype=np.float64)
            if a.shape != shape:
                raise fail(fld, f"must have shape {shape}, got {a.shape}")
            bad = ~np.isfinite(a) | ((a <= 0.0) if fld != "stiffness" else (a < 0.0))
            if np.any(bad):
                i = int(np.flatnonzero(bad)[0])
                rel = ">= 0" if fld == "stiffness" else "> 0"
                raise fail(f"{fld}[{i}]", f"must be finite and {rel}, got {a[i]!r}")
            arrays[fld] = a
        damping = _number(self.damping, field_name="damping", low=0.0)
        anchors = np.asarray(self.anchors, dtype=np.int64).reshape(-1)
        if anchors.size and (anchors.min() < 0 or anchors.max() >= n):
            raise fail("anchors", f"indices must be in [0, {n}), got "
                                  f"[{anchors.min()}, {anchors.max()}]")
        if len(np.unique(anchors)) != len(anchors):
            raise fail("anchors", "has repeated node indices")
        gravity = np.asarray(_vec3(self.gravity, field_name="gravity"), dtype=np.float64)
        stype = (np.zeros(s, dtype=np.int64) if self.spring_type is None
                 else np.asarray(self.spring_type, dtype=np.int64))
        if stype.shape != (s,):
            raise fail("spring_type", f"must have shape ({s},), got {stype.shape}")
        setattr_ = object.__setattr__
        setattr_(self, "rest", _readonly(rest))
        setattr_(self, "faces", _readonly(faces))
        setattr_(self, "n_surface", int(self.n_surface))
        setattr_(self, "springs", _readonly(springs))
        for fld, a in arrays.items():
            setattr_(self, fld, _readonly(a))
        setattr_(self, "damping", damping)
        setattr_(self, "anchors", _readonly(np.sort(anchors)))
        setattr_(self, "gravity", _readonly(gravity))
        setattr_(self, "spring_type", _readonly(stype))
        setattr_(self, "color", tuple(float(c) for c in self.color))

    @property
    def n_nodes(self) -> int:
        """Number of nodes (surface and interior)."""
        return len(self.rest)

    @property
    def free(self) -> NDArray[np.bool_]:
        """(n,) True for simulated (not anchored) nodes."""
        mask = np.ones(self.n_nodes, dtype=bool)
        mask[self.anchors] = False
        return mask

    @property
    def total_mass(self) -> float:
        """Sum of the node masses [kg]."""
        return float(self.mass.sum())


@dataclass
class OrganState:
    """What changes: node positions, velocities, time (updated in place by the solver).

    Attributes:
        x: (n, 3) node positions [m], scene frame.
        v: (n, 3) node velocities [m/s].
        t: simulated time [s].
    """

    x: FloatArray
    v: FloatArray
    t: float = 0.0

    def copy(self) -> OrganState:
        """A deep copy (a snapshot)."""
        return OrganState(self.x.copy(), self.v.copy(), self.t)


# ---------------------------------------------------------------------------------------
# Building


def _bending_pairs(mesh: trimesh.Trimesh) -> IntArray:
    """(e, 2) the two vertices opposite each interior edge (across adjacent faces)."""
    adj = mesh.face_adjacency
    if len(adj) == 0:
        return np.zeros((0, 2), dtype=np.int64)
    edges = mesh.face_adjacency_edges
    faces = mesh.faces

    def opposite(face_idx: IntArray) -> IntArray:
        f = faces[face_idx]
        mask = (f != edges[:, :1]) & (f != edges[:, 1:2])
        # exactly one vertex per face is off the shared edge
        return f[np.arange(len(f)), mask.argmax(axis=1)]

    return np.column_stack([opposite(adj[:, 0]), opposite(adj[:, 1])]).astype(np.int64)


def _unique_springs(pairs: Sequence[IntArray], stiffness: Sequence[float],
                    types: Sequence[int]) -> tuple[IntArray, FloatArray, IntArray]:
    """Concatenates spring groups, dropping repeated node pairs (the first group wins)."""
    allp, allk, allt = [], [], []
    for group, k_group, t_group in zip(pairs, stiffness, types, strict=True):
        g = np.asarray(group, dtype=np.int64).reshape(-1, 2)
        allp.append(g)
        allk.append(np.full(len(g), float(k_group)))
        allt.append(np.full(len(g), t_group, dtype=np.int64))
    p = np.vstack(allp)
    k = np.concatenate(allk)
    t = np.concatenate(allt)
    key = np.sort(p, axis=1)
    _, first = np.unique(key, axis=0, return_index=True)
    first = np.sort(first)
    keep = first[p[first, 0] != p[first, 1]]
    return p[keep], k[keep], t[keep]


def _vertex_areas(mesh: trimesh.Trimesh) -> FloatArray:
    areas = np.zeros(len(mesh.vertices))
    np.add.at(areas, mesh.faces.ravel(), np.repeat(mesh.area_faces / 3.0, 3))
    return areas


def _interior(mesh: trimesh.Trimesh, spacing: float) -> tuple[FloatArray, IntArray, FloatArray]:
    """Interior nodes from the inward medial points (see the module docstring).

    Returns:
        (c, 3) interior node positions, (n_surface,) cluster index of each surface vertex and
        (n_surface,) inward depth [m] of each vertex.
    """
    v = np.ascontiguousarray(mesh.vertices, dtype=np.float64)
    normals = np.ascontiguousarray(mesh.vertex_normals, dtype=np.float64)
    faces = np.ascontiguousarray(mesh.faces, dtype=np.int64)
    eps = 1e-6 * float(np.linalg.norm(mesh.extents))
    depth = _kernels.inward_depth(v, normals, faces, eps)
    ok = depth > 0.0
    fallback = float(np.median(depth[ok])) if ok.any() else 0.5 * float(min(mesh.extents))
    depth = np.where(ok, depth, fallback)
    medial = v - 0.5 * depth[:, None] * normals
    cell = np.floor(medial / spacing).astype(np.int64)
    _, cluster, counts = np.unique(cell, axis=0, return_inverse=True, return_counts=True)
    cluster = cluster.reshape(-1)
    nodes = np.zeros((len(counts), 3))
    np.add.at(nodes, cluster, medial)
    nodes /= counts[:, None]
    return nodes, cluster.astype(np.int64), depth


def _wall_distance(points: FloatArray, wall: trimesh.Trimesh) -> FloatArray:
    """Distance [m] from points to the wall surface, to ~1 mm (dense surface samples)."""
    n = max(20000, 4 * len(wall.vertices))
    samples, _ = trimesh.sample.sample_surface(wall, n, seed=0)
    tree = cKDTree(np.vstack([samples, wall.vertices]))
    dist, _ = tree.query(points)
    return dist


def select_anchors(surface: FloatArray, rules: Sequence[AnchorRule], *,
                   wall: trimesh.Trimesh | None = None, name: str = "") -> IntArray:
    """Surface vertex indices selected by the union of ``rules``.

    Args:
        surface: (m, 3) surface vertex positions [m].
        rules: anchor selections.
        wall: the abdominal wall surface, needed by ``to = "wall"`` rules.
        name: organ name for error messages.

    Returns:
        (a,) sorted unique indices.

    Raises:
        ConfigError: a wall rule without a wall.
    """
    chosen: list[IntArray] = []
    for i, rule in enumerate(rules):
        if rule.to == "plane":
            dist = (surface - np.asarray(rule.point)) @ np.asarray(rule.normal)
        elif rule.to == "point":
            dist = np.linalg.norm(surface - np.asarray(rule.point), axis=1)
        else:
            if wall is None:
                raise ConfigError(f"organ {name!r}: an anchor to the wall needs the wall mesh",
                                  field=f"anchors[{i}].to")
            dist = _wall_distance(surface, wall)
        if rule.within is not None:
            chosen.append(np.flatnonzero(dist <= rule.within))
        else:
            assert rule.fraction is not None  # AnchorRule: exactly one of within, fraction
            count = max(1, round(float(rule.fraction) * len(surface)))
            chosen.append(np.argsort(dist, kind="stable")[:count])
    if not chosen:
        return np.zeros(0, dtype=np.int64)
    return np.unique(np.concatenate(chosen)).astype(np.int64)


def build_organ(
    mesh: trimesh.Trimesh,
    params: OrganParams,
    *,
    name: str,
    kind: str = "parenchyma",
    color: tuple[float, float, float] = (0.8, 0.4, 0.4),
    delicate: bool = False,
    gravity: Sequence[float] = DEFAULT_GRAVITY,
    wall: trimesh.Trimesh | None = None,
) -> OrganModel:
    """Builds the mass-spring model of one organ from its closed surface (module docstring).

    Args:
        mesh: watertight triangle surface [m], scene frame, outward faces.
        params: physical parameters.
        name, kind, color, delicate: copied into the model.
        gravity: (3,) [m/s²].
        wall: the abdominal wall surface, for anchor rules ``to = "wall"``.

    Returns:
        The model; its first ``len(mesh.vertices)`` nodes are the mesh vertices in order.

    Raises:
        ConfigError: the mesh is not closed, or the anchor rules select no node.
    """
    if not mesh.is_watertight:
        raise ConfigError(f"organ {name!r}: the surface mesh must be closed (watertight)",
                          field="mesh")
    verts = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.faces, dtype=np.int64)
    m = len(verts)
    if params.kinematic:
        # Only drawn and moved: no springs, every node anchored.
        springs = np.zeros((0, 2), dtype=np.int64)
        k = np.zeros(0)
        stype = np.zeros(0, dtype=np.int64)
        rest = verts
        mass = np.full(m, params.mass / m)
        return OrganModel(name=name, rest=rest, faces=faces, n_surface=m, springs=springs,
                          rest_length=np.zeros(0), stiffness=k, mass=mass,
                          damping=params.damping, anchors=np.arange(m),
                          gravity=np.asarray(gravity, dtype=np.float64),
                          delicate=delicate, kind=kind, color=color, spring_type=stype)
    edges = np.asarray(mesh.edges_unique, dtype=np.int64)
    groups = [edges]
    ks = [params.stiffness]
    types = [SPRING_STRUCTURAL]
    if params.bending_stiffness > 0.0:
        groups.append(_bending_pairs(mesh))
        ks.append(params.bending_stiffness)
        types.append(SPRING_BENDING)
    areas = _vertex_areas(mesh)
    rest = verts
    if params.volume:
        mean_edge = float(mesh.edges_unique_length.mean())
        spacing = params.volume_spacing or 2.0 * mean_edge
        nodes, cluster, depth = _interior(mesh, spacing)
        rest = np.vstack([verts, nodes])
        spokes = np.column_stack([np.arange(m), m + cluster])
        groups.append(spokes)
        ks.append(params.volume_stiffness)
        types.append(SPRING_VOLUME)
        if len(nodes) > 1:
            links = cKDTree(nodes).query_pairs(_VOLUME_LINK_RADIUS * spacing, output_type="ndarray")
            groups.append(m + np.asarray(links, dtype=np.int64).reshape(-1, 2))
            ks.append(params.volume_stiffness)
            types.append(SPRING_VOLUME)
        share = areas * depth / 4.0
        weights = np.concatenate([share, np.bincount(cluster, weights=share,
                                                     minlength=len(nodes))])
    else:
        weights = areas.copy()
    if params.mass_distribution == "uniform":
        weights = np.ones(len(rest))
    weights = np.maximum(weights, 1e-6 * weights.max())
    mass = params.mass * weights / weights.sum()
    springs, k, stype = _unique_springs(groups, ks, types)
    rest_length = np.linalg.norm(rest[springs[:, 0]] - rest[springs[:, 1]], axis=1)
    keep = rest_length > 1e-9
    springs, k, stype, rest_length = springs[keep], k[keep], stype[keep], rest_length[keep]
    anchors = select_anchors(verts, params.anchors, wall=wall, name=name)
    if params.anchors and anchors.size == 0:
        raise ConfigError(f"organ {name!r}: the anchor rules select no node", field="anchors")
    _check_parts_anchored(m, edges, anchors, name)
    return OrganModel(name=name, rest=rest, faces=faces, n_surface=m, springs=springs,
                      rest_length=rest_length, stiffness=k, mass=mass, damping=params.damping,
                      anchors=anchors, gravity=np.asarray(gravity, dtype=np.float64),
                      delicate=delicate, kind=kind,
                      color=color, spring_type=stype)


def _check_parts_anchored(n_surface: int, edges: IntArray, anchors: IntArray,
                          name: str) -> None:
    """a deformable organ with no anchor (or a mesh part with none) only falls
    under gravity and resets; every connected part of the surface needs an anchored node.

    Raises:
        ConfigError: naming the organ and the unanchored part (its size and a vertex).
    """
    graph = coo_matrix((np.ones(len(edges)), (edges[:, 0], edges[:, 1])),
                       shape=(n_surface, n_surface))
    n_parts, label = connected_components(graph, directed=False)
    held = np.zeros(n_parts, dtype=bool)
    held[label[anchors]] = True
    if held.all():
        return
    part = int(np.flatnonzero(~held)[0])
    verts = np.flatnonzero(label == part)
    which = "the organ has no anchor" if n_parts == 1 else (
        f"part {part} of {n_parts} connected parts of the mesh ({len(verts)} vertices, e.g. "
        f"vertex {int(verts[0])}) has no anchored node")
    raise ConfigError(f"organ {name!r}: {which}; a deformable organ needs at least one anchor "
                      "([[anchors]] rule) per connected part, else it falls and resets",
                      field="anchors")


__all__ = [
    "DEFAULT_GRAVITY",
    "SPRING_BENDING",
    "SPRING_STRUCTURAL",
    "SPRING_VOLUME",
    "AnchorRule",
    "FloatArray",
    "IntArray",
    "OrganModel",
    "OrganParams",
    "OrganState",
    "build_organ",
    "select_anchors",
]
