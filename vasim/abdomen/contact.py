"""Tool–tissue contact: a laparoscopic tool (shaft + tip) against deformable organ surfaces.

Pure functions of arrays, called by the physics shell at the physics rate and by the haptic
loop at 1 kHz. Nothing here holds state.

Tool geometry. The tool is a straight shaft entering the abdomen through a fulcrum (the
trocar, a remote centre of motion) and ending at the tip. Its surface is a capsule of radius
``r`` around the segment fulcrum → tip. The capsule is sampled by spheres of radius ``r``
centred on the axis at distances ``ℓ_j = j·spacing`` from the tip (``ℓ_0 = 0`` is the tip),
``spacing <= r`` so that consecutive spheres overlap and a triangle cannot slip between them.

Detection (at the physics rate). Broad phase: the surface nodes within ``r + h`` of the tool
axis (``h`` = longest surface edge). Narrow phase: for every sphere the closest point ``q``
on each candidate triangle (Ericson's region tests), keeping the nearest triangle per sphere
(the first in face order on a tie). The signed distance is ``s = ±|c - q|``, negative
when the centre is behind the triangle (``(c - q)·n_f < 0``); the penetration is
``δ = r - s``. The contact normal ``n`` points from the tissue to the tool: ``(c - q)/|c - q|``
when the centre is in front, else the face normal ``n_f`` (deep contacts keep a stable normal).
Both phases and everything below run in one compiled pass
(:mod:`vasim.abdomen._contact_kernels`, tested against a numpy/trimesh implementation).
Two faces sharing the closest edge or vertex are equally near; when the centre is behind one
of them, which one is "nearest" is decided by round-off, and the two give different contacts
(the model's own discontinuity: the numpy implementation and the kernel disagree there on
6 of 540 random poses at the default organs, and agree to 1e-12 everywhere else).

Contact law (**decision**, penalty method): the force on the tool is ``F_j = k_j δ_j n_j`` and
the opposite force acts on the tissue, spread over the triangle's three nodes with the
barycentric weights of ``q``. The tissue solver treats this force explicitly, so its
stiffness is bounded by the explicit stability limit of the contacted nodes:
``k_j = min(k_c, β · m_j / dt²)`` with ``m_j`` the barycentric mass of the triangle and
``β = 0.5`` (the limit is ``ω dt < 2``, i.e. ``k dt² / m < 4``; 0.5 keeps a margin of 8 and
no oscillation). A stiffer feel for the hand comes from the haptic coupling, not from the
tissue step.

Haptic patch (the 1 kHz side). Each detection also returns a :class:`ContactPatch`: the
active contact planes ``(q_j, n_j, k_j, ℓ_j)``. Between physics updates the tissue is taken as
still and the force for a moved tool is re-evaluated against these planes
(:func:`patch_force`). Sphere ``j`` sits at ``c_j = x - ℓ_j u`` with ``u = (x - p_f) / L``
(``L`` = fulcrum–tip distance), so when the tip moves by ``dx`` the sphere moves by
``J_j dx`` with ``J_j = (1 - a_j) I + a_j u uᵀ``, ``a_j = ℓ_j / L``: across the shaft by the
lever factor ``1 - a_j`` (the tool pivots about the trocar), along it by the full step (the
tool slides through the trocar). With ``δ_j(x) = r - (c_j(x) - q_j)·n_j`` and the tip-side
normal ``g_j = J_jᵀ n_j``, the force felt at the tip by virtual work is
``F_tip = Σ k_j max(δ_j, 0) g_j``. Its derivative has the material term
``-Σ_active k_j g_j g_jᵀ`` (negative semi-definite: springs pushing out) plus the geometric
term of the turning shaft, ``Σ_active k_j δ_j (a_j / L) (t_j uᵀ + u t_jᵀ + (u·n_j) P)`` with
``P = I - u uᵀ`` and ``t_j = P n_j`` (symmetric; of relative size ``δ a / L``, a few %).
This is the force and force derivative the servo loop extrapolates with (as OpenSurgSim's
coupler does).

Torque. The torque of the contact forces about the fulcrum, ``τ = Σ (c_j - p_f) × F_j``, is
what the surgeon's hand and the trocar feel; it accumulates in the quality metrics.

Example:
    >>> import numpy as np
    >>> # a flat 2 x 2 patch at z = 0 (normal +z), the tip 1 mm below its surface, r = 2.5 mm
    >>> x = np.array([[-.01, -.01, 0], [.01, -.01, 0], [.01, .01, 0], [-.01, .01, 0]])
    >>> faces = np.array([[0, 1, 2], [0, 2, 3]])
    >>> tool = ToolPose(fulcrum=np.array([0, 0, 0.1]), tip=np.array([0, 0, -0.001]))
    >>> c = detect_contacts(x, faces, np.full(4, 0.01), tool, ToolShape(), dt=0.004)
    >>> # k = min(350, 0.5 * 0.01 / 0.004**2) = 312.5 N/m; the tip sphere is 3.5 mm deep, the
    >>> # next one (2.5 mm up the shaft) 1 mm: F = 312.5 * (0.0035 + 0.001)
    >>> round(float(c.force[2]), 5), c.n_contacts
    (1.40625, 2)
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from vasim.abdomen._contact_kernels import patch_tip_force, tool_contacts
from vasim.core.config import check_int, check_number, expect
from vasim.core.kernel_args import readonly_c, writable_c

FloatArray = NDArray[np.float64]
IntArray = NDArray[np.int64]

STABILITY_FRACTION = 0.5
"""β: the contact stiffness is bounded by ``β m / dt²`` (explicit stability with margin 8)."""


@dataclass(frozen=True)
class ToolShape:
    """Geometry and contact material of the laparoscopic tool.

    Attributes:
        radius: capsule radius r [m] (a 5 mm instrument: 2.5 mm).
        contact_stiffness: penalty stiffness k_c per contact [N/m] before the stability bound.
        spacing: distance between the sampling spheres along the shaft [m]; <= radius.
        max_spheres: cap on the number of sampled spheres (the shaft beyond is ignored).
    """

    radius: float = 0.0025
    contact_stiffness: float = 350.0
    spacing: float = 0.0025
    max_spheres: int = 96

    def __post_init__(self) -> None:
        for name in ("radius", "contact_stiffness", "spacing"):
            check_number(getattr(self, name), f"tool.{name}", gt=0)
        expect(self.spacing <= self.radius, self.spacing,
                f"at most tool.radius ({self.radius}) so spheres overlap", field="tool.spacing")
        check_int(self.max_spheres, "tool.max_spheres", lo=1)


@dataclass(frozen=True)
class ToolPose:
    """Where the tool is: the fulcrum (trocar) point and the tip [m], world frame."""

    fulcrum: FloatArray
    tip: FloatArray

    @property
    def length(self) -> float:
        """Fulcrum–tip distance L [m]."""
        return float(np.linalg.norm(np.asarray(self.tip) - np.asarray(self.fulcrum)))


@dataclass(frozen=True, eq=False)
class ContactPatch:
    """The active contact planes, frozen at a physics update, for the 1 kHz force model.

    Attributes:
        points: (m, 3) closest points q_j on the tissue [m].
        normals: (m, 3) unit contact normals n_j, tissue → tool.
        stiffness: (m,) k_j [N/m] after the stability bound.
        offsets: (m,) ℓ_j, distance of sphere j from the tip along the shaft [m].
        radius: tool radius r [m].
    """

    points: FloatArray
    normals: FloatArray
    stiffness: FloatArray
    offsets: FloatArray
    radius: float

    def __post_init__(self) -> None:
        # One array type for the compiled 1 kHz kernel whatever the caller built the patch
        # from (a read-only or strided array would be another type, compiled on its first
        # call, inside the loop); and the kernel loaded now, off the loop (patch_force).
        for name in ("points", "normals", "stiffness", "offsets"):
            a = getattr(self, name)
            if not (type(a) is np.ndarray and a.dtype == np.float64 and a.flags.c_contiguous
                    and a.flags.writeable):
                object.__setattr__(self, name, np.array(a, dtype=np.float64))
        m = self.points.shape[0] if self.points.ndim == 2 else -1
        if (self.points.shape != (m, 3) or self.normals.shape != (m, 3)
                or self.stiffness.shape != (m,) or self.offsets.shape != (m,)):
            raise ValueError(f"a contact patch needs points (m, 3), normals (m, 3), stiffness "
                             f"(m,) and offsets (m,), got {self.points.shape}, "
                             f"{self.normals.shape}, {self.stiffness.shape} and "
                             f"{self.offsets.shape}")
        if not _KERNELS_LOADED:
            load_kernels()

    @property
    def size(self) -> int:
        return int(self.points.shape[0])

    @classmethod
    def empty(cls, radius: float) -> ContactPatch:
        z = np.zeros((0, 3))
        return cls(z, z.copy(), np.zeros(0), np.zeros(0), radius)

    @staticmethod
    def merge(patches: list[ContactPatch], radius: float) -> ContactPatch:
        """One patch from several organs' patches."""
        if not patches:
            return ContactPatch.empty(radius)
        return ContactPatch(
            np.concatenate([p.points for p in patches]),
            np.concatenate([p.normals for p in patches]),
            np.concatenate([p.stiffness for p in patches]),
            np.concatenate([p.offsets for p in patches]), radius)


@dataclass(frozen=True, eq=False)
class ContactResult:
    """The contacts of the tool with one organ at one physics update.

    Attributes:
        force: (3,) total contact force on the tool [N].
        force_tip: (3,) the force felt at the tip (virtual work through the lever) [N].
        torque: (3,) torque of the contact forces about the fulcrum [N·m].
        stiffness_tip: (3, 3) dF_tip/dx_tip [N/m] (negative semi-definite).
        node_index: (p,) tissue nodes receiving a reaction force.
        node_force: (p, 3) the reaction forces on those nodes [N] (sum = -force).
        n_contacts: number of active sphere–triangle contacts.
        max_penetration: largest δ [m] (0 without contact).
        patch: the contact planes for the haptic loop.
    """

    force: FloatArray
    force_tip: FloatArray
    torque: FloatArray
    stiffness_tip: FloatArray
    node_index: IntArray
    node_force: FloatArray
    n_contacts: int
    max_penetration: float
    patch: ContactPatch = field(repr=False)

    @property
    def in_contact(self) -> bool:
        return self.n_contacts > 0

    @classmethod
    def none(cls, radius: float) -> ContactResult:
        return cls(np.zeros(3), np.zeros(3), np.zeros(3), np.zeros((3, 3)),
                   np.zeros(0, dtype=np.int64), np.zeros((0, 3)), 0, 0.0,
                   ContactPatch.empty(radius))

    def external_forces(self, n_nodes: int) -> FloatArray:
        """(n_nodes, 3) array of the reaction forces, for the tissue solver [N]."""
        f = np.zeros((n_nodes, 3))
        np.add.at(f, self.node_index, self.node_force)
        return f


_KERNELS_LOADED = False


def load_kernels() -> None:
    """Loads the compiled contact kernels into this process (numba's disk cache, ~30 ms, plus
    numba's own start-up, ~1 s, when nothing compiled has run yet; the very first run of an
    install compiles them). Called when the first :class:`ContactPatch` is made, so that the
    1 kHz loop's first :func:`patch_force` costs no more than the others."""
    global _KERNELS_LOADED
    _KERNELS_LOADED = True
    z = np.zeros((0, 3))
    patch_tip_force(z, z, np.zeros(0), np.zeros(0), 0.0025, np.zeros(3),
                    np.array([0.0, 0.0, 0.1]), np.empty(3), np.empty((3, 3)))


def sphere_offsets(pose: ToolPose, shape: ToolShape) -> FloatArray:
    """(m,) distances ℓ_j of the sampling spheres from the tip [m], tip first.

    The spheres cover the shaft from the tip up to the fulcrum (the part inside the
    abdomen), at most ``shape.max_spheres`` of them.
    """
    length = pose.length
    m = min(int(np.floor(length / shape.spacing)) + 1, shape.max_spheres)
    return np.arange(m, dtype=np.float64) * shape.spacing


def point_segment_distance(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """(n,) distances of points (n, 3) to the segment a–b [m]."""
    ab = b - a
    denom = float(ab @ ab)
    ap = points - a
    t = np.clip(ap @ ab / denom, 0.0, 1.0) if denom > 0 else np.zeros(len(points))
    return np.linalg.norm(ap - t[:, None] * ab, axis=1)


def detect_contacts(
    x: FloatArray,
    faces: IntArray,
    mass: FloatArray,
    pose: ToolPose,
    shape: ToolShape,
    *,
    dt: float,
    max_edge: float | None = None,
) -> ContactResult:
    """Finds the tool's contacts with one organ surface and their forces.

    Args:
        x: (n, 3) node positions [m]; the nodes referenced by ``faces`` form the surface.
        faces: (f, 3) outward-oriented surface triangles.
        mass: (n,) node masses [kg] (for the stability bound of the contact stiffness).
        pose: tool fulcrum and tip [m].
        shape: tool radius, contact stiffness, sphere spacing.
        dt: the tissue solver's time step [s] (for the stability bound).
        max_edge: longest surface edge [m] (broad-phase margin); computed when None.

    Returns:
        The contact forces on the tool and on the tissue nodes, and the haptic patch.
    """
    r = shape.radius
    # one kernel type per argument (vasim.core.kernel_args): the organ's own faces and
    # masses are read-only, its positions writable
    x, faces, mass = writable_c(x), readonly_c(faces, np.int64), readonly_c(mass)
    if x.ndim != 2 or x.shape[1] != 3 or faces.ndim != 2 or faces.shape[1] != 3 \
            or mass.shape != (x.shape[0],):
        raise ValueError(f"detect_contacts needs x (n, 3), faces (f, 3) and mass (n,), got "
                         f"{x.shape}, {faces.shape} and {mass.shape}")
    # The whole detection runs in one compiled pass (vasim.abdomen._contact_kernels): the
    # spheres inside the organ's box grown by r + h, the nodes near the axis they span, per
    # sphere the nearest face with a node within r + h of its centre, then the forces.
    (count, max_pen, force, force_tip, torque, stiff, node_index, node_force, points,
     normals, k, ell) = tool_contacts(
        x, faces, mass, writable_c(pose.tip), writable_c(pose.fulcrum), float(r),
        float(shape.spacing), int(shape.max_spheres), float(shape.contact_stiffness),
        STABILITY_FRACTION, float(dt), -1.0 if max_edge is None else float(max_edge))
    if count <= 0:
        if count == -1:
            raise ValueError(f"the tool pose must be finite, got tip {pose.tip!r} and fulcrum "
                             f"{pose.fulcrum!r}")
        if count == -2:
            raise ValueError(f"faces index nodes outside 0..{x.shape[0] - 1}, got "
                             f"{int(faces.min())}..{int(faces.max())}")
        return ContactResult.none(r)
    patch = ContactPatch(points, normals, k, ell, r)
    return ContactResult(force, force_tip, torque, stiff, node_index, node_force, int(count),
                         float(max_pen), patch)




def patch_force(patch: ContactPatch, pose: ToolPose) -> tuple[FloatArray, FloatArray]:
    """Force felt at the tip for a moved tool, against the frozen contact planes (1 kHz).

    Args:
        patch: contact planes from the last physics update.
        pose: the current tool pose.

    Returns:
        (F_tip (3,) [N], dF_tip/dx (3, 3) [N/m]). Unilateral: a plane the tool has left
        pushes no more (and pulls never).

    Example:
        >>> import numpy as np
        >>> p = ContactPatch(np.zeros((1, 3)), np.array([[0., 0, 1]]), np.array([200.]),
        ...                  np.zeros(1), 0.0025)
        >>> f, k = patch_force(p, ToolPose(np.array([0, 0, .1]), np.array([0, 0, .0015])))
        >>> round(float(f[2]), 6), float(k[2, 2])
        (0.2, -200.0)
    """
    force = np.empty(3)
    stiff = np.empty((3, 3))
    patch_force_into(patch, pose.fulcrum, pose.tip, force, stiff)
    return force, stiff


def patch_force_into(patch: ContactPatch, fulcrum: FloatArray, tip: FloatArray,
                     force: FloatArray, stiff: FloatArray) -> int:
    """:func:`patch_force` into caller-owned arrays: the 1 kHz loop's path (no allocation).

    One compiled call (``vasim.abdomen._contact_kernels.patch_tip_force``), scalar code over
    the planes.

    Args:
        patch: contact planes from the last physics update.
        fulcrum, tip: (3,) tool pose [m] (float64 arrays; others are converted).
        force: (3,) float64 output, F_tip [N].
        stiff: (3, 3) float64 output, dF_tip/dx [N/m].

    Returns:
        The number of planes pushing on the tool.

    Example:
        >>> import numpy as np
        >>> p = ContactPatch(np.zeros((1, 3)), np.array([[0., 0, 1]]), np.array([200.]),
        ...                  np.zeros(1), 0.0025)
        >>> f, k = np.empty(3), np.empty((3, 3))
        >>> patch_force_into(p, np.array([0, 0, .1]), np.array([0, 0, .0015]), f, k)
        1
        >>> round(float(f[2]), 6)
        0.2
    """
    return int(patch_tip_force(patch.points, patch.normals, patch.stiffness, patch.offsets,
                               float(patch.radius), writable_c(tip), writable_c(fulcrum),
                               force, stiff))


__all__ = [
    "STABILITY_FRACTION",
    "ContactPatch",
    "ContactResult",
    "ToolPose",
    "ToolShape",
    "detect_contacts",
    "load_kernels",
    "patch_force",
    "patch_force_into",
    "point_segment_distance",
    "sphere_offsets",
]
