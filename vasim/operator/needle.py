"""The needle-through-targets task of the MRCP study (spec/study.md §§4-5, seed chapter 5).

A straight suture needle is carried through target rings placed on the organs of the
virtual abdomen, alternately on the patient's right and left, by two laparoscopic tool
robots (``vasim.mrcp.toolstation``). A ring is passed when the needle's centre comes within
``ring_radius`` of the ring's centre. The instrument on one side cannot work on the far side
(its orientation cone), so every change of side is a needle transfer between the tools:
the operator's own job in standard teleoperation (StdT), the MRCP kernel's in MRCP.

Geometry (world frame of the scene, metres):

* Needle: a rigid straight needle of length ``2 * NEEDLE_HALF`` along the world x axis,
  held at one of two grasp points ``centre ∓ NEEDLE_HALF e_x``: the right instrument
  (patient's right, x < 0) holds the -x end, the left one the +x end, so the jaws never
  meet. Its pre-grasp pose is ``APPROACH_OFFSET`` further out and above.
* Rings (``RING_SITES``): on the tops of four bowel loops (the ones under the working
  trocars' reach, left and right of the midline); each ring's
  centre is ``clearance`` (8 mm) above the organ surface straight under its (x, y) site, on
  the rest shape of ``vasim.abdomen.anatomy``. In a trial the rings are bound to the tissue
  (``Abdomen.bind_targets``): they ride with breathing and are displaced when the tools
  push the organs.

Skill model of a manual transfer (StdT, **decision**: the seed reports misaligned
transfers and re-grasps without a rate model; the rates come from the scripted operator's
own skill model, ``vasim.operator.scripted`` §1). When the operator closes the receiving
jaw, the jaw's placement error across the needle is the tool tip's offset from the grasp
point (y and z: along the needle the jaw slides) plus the operator's perceptual
misjudgement, a 2-D normal draw with

    sigma_grasp = perception_noise * (1 + SKILL_NOISE (1 - s)) * (1 + P) ** -alpha

(the same noise the person's vision has when aiming). An error above ``GRASP_TOLERANCE``
(4 mm) misses the needle: the operator re-opens, backs off to the pre-grasp pose and tries
again (a re-grasp). An error between ``ALIGN_TOLERANCE`` (1.5 mm) and 4 mm grasps it
off-centre: the jaw drags the needle by that error as it closes (a misaligned transfer;
the needle jumps). For the intermediate preset (s = 0.5, P = 0) sigma_grasp = 2.25 mm: a
miss per attempt with probability exp(-(4 / 2.25)^2 / 2) = 0.21 when the tip itself is on
the point; an expert (s = 0.9, 1.65 mm) misses with 0.05, and practice lowers both.

Example:
    >>> task = needle_task(4)
    >>> task.sides
    ('right', 'left', 'right', 'left')
    >>> classify_grasp(0.001), classify_grasp(0.002), classify_grasp(0.005)
    ('clean', 'misaligned', 'missed')
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from typing import Literal

import numpy as np

from vasim.core.config import check_choice, check_int, check_number, expect
from vasim.mrcp.interfaces import FloatArray
from vasim.operator.scripted import SKILL_NOISE, OperatorProfile, power_law
from vasim.tasks.base import Task

Side = Literal["right", "left"]
GraspOutcome = Literal["clean", "misaligned", "missed"]

NEEDLE_HALF = 0.010
"""Half length of the needle [m] (a 20 mm straight needle); grasp points at ±NEEDLE_HALF."""

APPROACH_OFFSET = 0.008
"""Pre-grasp offset [m]: outward along the needle and up, from the grasp point."""

RING_RADIUS = 0.005
"""A ring is passed when the needle centre is within this distance of its centre [m]."""

RING_CLEARANCE = 0.008
"""Height of a ring's centre above the organ surface [m]."""

GRASP_TOLERANCE = 0.004
"""A jaw placed farther than this from the grasp point misses the needle [m] (about half
the opening of a 5 mm needle driver's jaws)."""

ALIGN_TOLERANCE = 0.0015
"""A jaw placed farther than this (and within ``GRASP_TOLERANCE``) drags the needle [m]."""

RING_SITES: tuple[tuple[str, str, float, float], ...] = (
    ("right", "intestine_3", -0.062, -0.032),
    ("left", "intestine_5", 0.062, -0.034),
    ("right", "intestine_0", -0.059, -0.057),
    ("left", "intestine_2", 0.059, -0.058),
    ("right", "intestine_3", -0.072, -0.028),
    ("left", "intestine_5", 0.069, -0.030),
)
"""(side, organ, x, y) of the rings, in visiting order (the sides alternate)."""

VIA_HEIGHT = 0.015
"""Height of the route's via points (and StdT's hand-over points) above the higher of the
two rings they join [m] (:func:`needle_route`)."""

START_OFFSET = np.array([-0.02, 0.0, 0.02])
"""The needle starts this far from the first ring [m] (in the right instrument's jaw)."""


def side_sign(side: Side) -> float:
    """-1 for the right instrument (x < 0), +1 for the left."""
    return -1.0 if side == "right" else 1.0


def grasp_offset(side: Side) -> FloatArray:
    """``(3,)`` the grasp point of ``side``'s instrument relative to the needle centre."""
    return np.array([side_sign(side) * NEEDLE_HALF, 0.0, 0.0])


def pregrasp_offset(side: Side) -> FloatArray:
    """``(3,)`` the pre-grasp point relative to the needle centre (out and up)."""
    return grasp_offset(side) + np.array([side_sign(side) * APPROACH_OFFSET, 0.0,
                                          0.75 * APPROACH_OFFSET])


@cache
def _surface_point(organ: str, x: float, y: float) -> tuple[FloatArray, FloatArray]:
    from vasim.abdomen.anatomy import default_anatomy

    meshes = {o.name: o.mesh for o in default_anatomy()}
    check_choice(organ, "organ", tuple(meshes))
    mesh = meshes[organ]
    locs, _, tri = mesh.ray.intersects_location(np.array([[x, y, 0.5]]),
                                                np.array([[0.0, 0.0, -1.0]]))
    expect(len(locs) > 0, (x, y), f"a site (x, y) above the surface of {organ!r}",
           field="site")
    top = int(np.argmax(locs[:, 2]))
    normal = np.asarray(mesh.face_normals[tri[top]], dtype=float)
    return np.asarray(locs[top], dtype=float), normal


@dataclass(frozen=True, eq=False)
class NeedleTask:
    """The rings to pass, in order, and where the needle starts.

    Attributes:
        rings: ``(n, 3)`` ring centres at rest [m]. normals: ``(n, 3)`` organ normals there.
        sides: the instrument that can work at each ring. organs: organ under each ring.
        ring_radius: pass radius [m]. start: ``(3,)`` needle centre at start [m].
    """

    rings: FloatArray
    normals: FloatArray
    sides: tuple[Side, ...]
    organs: tuple[str, ...]
    ring_radius: float
    start: FloatArray

    @property
    def n_rings(self) -> int:
        return len(self.sides)

    @property
    def n_transfers(self) -> int:
        """Side changes needed (the needle starts on the first ring's side)."""
        return sum(a != b for a, b in zip(self.sides, self.sides[1:], strict=False))

    def operator_task(self, points: FloatArray, start: FloatArray,
                      reach_radius: float | None = None) -> Task:
        """A ``vasim.tasks`` path for the scripted operator through ``points`` (n, 3)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 3)
        return Task(name="needle", kind="trajectory", variant=0, points=pts, normals=None,
                    reach_radius=self.ring_radius if reach_radius is None else reach_radius,
                    scale=0.05, start=np.asarray(start, dtype=float).copy())


def needle_task(n_rings: int = len(RING_SITES), *, clearance: float = RING_CLEARANCE,
                ring_radius: float = RING_RADIUS) -> NeedleTask:
    """The first ``n_rings`` rings of ``RING_SITES`` (module docstring).

    Raises:
        ConfigError: ``n_rings`` outside 1..len(RING_SITES), or a bad clearance / radius.
    """
    check_int(n_rings, "n_rings", lo=1, hi=len(RING_SITES))
    for name, v in (("clearance", clearance), ("ring_radius", ring_radius)):
        check_number(v, name, gt=0)
    rings, normals = [], []
    for _, organ, x, y in RING_SITES[:n_rings]:
        p, n = _surface_point(organ, x, y)
        rings.append(p + np.array([0.0, 0.0, clearance]))
        normals.append(n)
    r = np.array(rings)
    sides: tuple[Side, ...] = tuple(s for s, *_ in RING_SITES[:n_rings])  # type: ignore[misc]  # RING_SITES rows start with a Side
    return NeedleTask(rings=r, normals=np.array(normals), sides=sides,
                      organs=tuple(o for _, o, *_ in RING_SITES[:n_rings]),
                      ring_radius=ring_radius, start=r[0] + START_OFFSET)


def handover_point(a: FloatArray, b: FloatArray) -> FloatArray:
    """Where a manual transfer happens between rings at ``a`` and ``b``: above the
    midpoint at the midline, ``VIA_HEIGHT`` (1.5 cm) above the higher ring (in both
    instruments' cones). It is also the via point of the needle route (:func:`needle_route`)
    in every mode."""
    a, b = np.asarray(a, dtype=float), np.asarray(b, dtype=float)
    mid = 0.5 * (a + b)
    return np.array([0.0, mid[1], max(a[2], b[2]) + VIA_HEIGHT])


def needs_via(sides: tuple[Side, ...], i: int) -> bool:
    """True if the route to ring ``i`` passes the via point after ring ``i - 1`` (the
    rings are on different sides: the needle crosses the midline)."""
    return 1 <= i < len(sides) and sides[i] != sides[i - 1]


def needle_route(rings: FloatArray, sides: tuple[Side, ...]) -> tuple[FloatArray, tuple[int, ...]]:
    """The needle's route through ``rings`` (n, 3) [m], the same in every mode.

    **Decision** (issue #7 §4, the route rule): the scripted operator carries the needle
    along the same waypoints whatever the mode, so that the modes differ only in how the
    needle changes hands. From the start straight to the first ring; between consecutive
    rings on different sides through the via point :func:`handover_point` (midline,
    ``VIA_HEIGHT`` above the higher ring: the needle crosses over the bowel at this
    clearance, never at ring height), then down to the next ring; between rings on the
    same side straight. A waypoint is reached within the ring radius, and a ring counts
    only after its via point. In StdT the operator's own hand-over happens at the via
    point; in MRCP the needle passes it while the kernel transfers it wherever its indices
    decide. Before this rule StdT crossed at the hand-over height and MRCP went straight
    from ring to ring at ring height, 8 mm above the loops, and its tool tips touched
    them: Q compared the operator's paths, not the modes.

    Returns:
        ``(m, 3)`` waypoints in visiting order, and for each the index of its ring, or
        -1 for a via point (the via point before ring ``i`` uses rings ``i - 1`` and ``i``).

    Example:
        >>> t = needle_task(3)
        >>> needle_route(t.rings, t.sides)[1]
        (0, -1, 1, -1, 2)
    """
    r = np.asarray(rings, dtype=float).reshape(-1, 3)
    expect(len(r) == len(sides), len(sides), f"one side per ring ({len(r)} rings)",
           field="sides")
    pts: list[FloatArray] = []
    kind: list[int] = []
    for i in range(len(r)):
        if needs_via(sides, i):
            pts.append(handover_point(r[i - 1], r[i]))
            kind.append(-1)
        pts.append(r[i])
        kind.append(i)
    return np.array(pts), tuple(kind)


def grasp_sigma(profile: OperatorProfile, practice: int) -> float:
    """Std of the jaw placement misjudgement per lateral axis [m] (module docstring).

    Example:
        >>> round(grasp_sigma(OperatorProfile.intermediate(), 0) * 1e3, 3)
        2.25
    """
    kn = 1.0 + SKILL_NOISE * (1.0 - profile.skill)
    return float(profile.perception_noise * kn * power_law(practice, profile.learning_rate,
                                                               profile.asymptote))


def classify_grasp(error: float, grasp_tolerance: float = GRASP_TOLERANCE,
                   align_tolerance: float = ALIGN_TOLERANCE) -> GraspOutcome:
    """Outcome of closing a jaw ``error`` [m] away from the grasp point."""
    if error > grasp_tolerance:
        return "missed"
    if error > align_tolerance:
        return "misaligned"
    return "clean"


def lateral_error(rng: np.random.Generator, sigma: float) -> FloatArray:
    """``(3,)`` a jaw misjudgement across the needle (y and z; the needle lies along x)."""
    e = rng.normal(0.0, sigma, 2)
    return np.array([0.0, float(e[0]), float(e[1])])


__all__ = [
    "ALIGN_TOLERANCE",
    "APPROACH_OFFSET",
    "GRASP_TOLERANCE",
    "NEEDLE_HALF",
    "RING_CLEARANCE",
    "RING_RADIUS",
    "RING_SITES",
    "VIA_HEIGHT",
    "NeedleTask",
    "classify_grasp",
    "grasp_offset",
    "grasp_sigma",
    "handover_point",
    "lateral_error",
    "needle_route",
    "needle_task",
    "needs_via",
    "pregrasp_offset",
]
