"""Geometry of the combined StdT/MRCP suture (seed sec. 5.5, Figs. 5.34-5.37): the tissue
with its incision, the curved needle, the stitch poses, the station's layout.

Frames: world frame as in ``laparoscopic_rings`` (abdominal wall at z = 0, the body
below, metres, radians). The incision runs along y; the needle crosses it along x.
The *tissue frame* is the world frame shifted by the breathing offset ``(0, 0, b(t))``:
entry and exit points and the thread's pinned points are kept in it, so they ride on the
breathing tissue.

The needle (the MRCP task) is a half circle of radius ``NEEDLE_RADIUS`` in its frame's x-z
plane: the point at arc angle ``φ`` is ``r (cos φ, 0, sin φ)``, the tail (where the thread
is swaged) at ``φ = -π``, the tip at ``φ = 0``. A stitch turns the needle about the world
y axis through the incision: with :func:`needle_rotation` ``(β)`` the point at ``φ`` is at
world angle ``α = φ + β`` in the x-z plane (measured from +x towards +z), so the tip is
at ``α = β`` and the tail at ``β - π``. The needle's centre stays ``NEEDLE_HEIGHT`` above
the tissue surface, so the arc enters the surface at ``α_e = π + asin(h / r)`` (left lip)
and leaves it at ``α_x = 2π - asin(h / r)`` (right lip).

**Decisions** (not in the extracted seed; the seed's phantom is a physical one):

* The tools are 5 mm instruments (``TOOL_RADIUS`` 2.5 mm; the rings scenario carries a
  10 mm one): a needle holder's jaws must fit between the needle and the tissue.
* The trocars sit ``TROCAR_BACK`` behind the stitch line (-y), so the shafts reach the
  needle from the side of its plane, as a surgeon's instruments do; in the needle's plane
  a shaft would lie along the arc.
* Grasp points: point 0 near the tail (R0's, ``TAIL_GRASP`` rad of arc from the tail),
  point 1 near the tip (R1's, ``TIP_GRASP`` from the tip); position-only (the fulcrum fixes
  the tool's axis). Each point's pre-grasp is ``APPROACH`` off the needle's plane on the
  trocars' side (:func:`approach_vector`): the kernel's planner does not see the needle
  (it is not a body), so a waiting tool must not wait in its plane, where the turning
  needle would sweep through it.
* The tool-orientation cones (spec §4, eq. 3.28-3.29) have semi-axes ``CONE_A`` along the
  incision's normal (x) and ``CONE_B`` along it (y): wide along y, where the trocars'
  offset lies, and such that neither tool can follow the needle far onto the other side
  of the incision.
"""

from __future__ import annotations

import math

import numpy as np

from vasim.core.geometry import rot_x, rot_y
from vasim.mrcp.interfaces import FloatArray

# ----------------------------------------------------------------------------- layout
TOOL_LENGTH = 0.35
TOOL_RADIUS = 0.0025
PATH_Y = -0.05                      # the incision's middle (y)
TROCAR_BACK = 0.07                  # trocars this far behind the stitch line (-y)
TROCARS = {"R0": np.array([-0.07, PATH_Y - TROCAR_BACK, 0.0]),
           "R1": np.array([0.07, PATH_Y - TROCAR_BACK, 0.0])}
BASES = {"R0": (np.array([-0.5, PATH_Y - TROCAR_BACK, 0.0]), 0.0),
         "R1": (np.array([0.5, PATH_Y - TROCAR_BACK, 0.0]), math.pi)}
CAMERA_TROCAR = np.array([0.0, PATH_Y + 0.11, 0.0])
CAMERA_BASE = (np.array([0.0, PATH_Y + 0.55, 0.0]), -math.pi / 2)
CAMERA_TIP = np.array([0.0, PATH_Y + 0.06, -0.08])
CONE_A = 0.8
CONE_B = 1.0

# ----------------------------------------------------------------------------- tissue
SURFACE_Z = -0.165                  # the tissue surface at rest
TISSUE_THICK = 0.02
TISSUE_HALF_X = 0.045               # each lip's extent across the incision
TISSUE_HALF_Y = 0.035
INCISION_GAP = 0.004                # the incision's width
BREATH_AMPLITUDE = 0.002            # vertical breathing motion [m], peak
BREATH_PERIOD = 4.0                 # [s] (15 breaths per minute)
STITCH_SPACING = 0.008
STITCH_Y = tuple(PATH_Y + STITCH_SPACING * k for k in (-1, 0, 1))
ANCHOR = np.array([0.013, PATH_Y - 2 * STITCH_SPACING, SURFACE_Z])   # the starting knot

# ----------------------------------------------------------------------------- needle
NEEDLE_RADIUS = 0.018
NEEDLE_HEIGHT = 0.009               # centre above the surface during a stitch
TAIL_GRASP = 0.15
TIP_GRASP = 0.15
APPROACH = 0.02
ENTRY_ANGLE = math.pi + math.asin(NEEDLE_HEIGHT / NEEDLE_RADIUS)
EXIT_ANGLE = 2 * math.pi - math.asin(NEEDLE_HEIGHT / NEEDLE_RADIUS)
BETA_START = ENTRY_ANGLE - 0.12             # the tip just above the entry point
#: The jaw length: needle points this close to a grasping tool's tip are in its jaws
#: (**decision**: a needle holder's jaws are 10-15 mm long; the shafts reach the needle
#: steeply, close to its plane, so the needle runs along the jaws near the grasp).
JAW = 0.010


def breathing(t: float) -> float:
    """The tissue's vertical offset [m] at ``t`` [s]."""
    return BREATH_AMPLITUDE * math.sin(2 * math.pi * t / BREATH_PERIOD)


def tissue_offset(t: float) -> FloatArray:
    return np.array([0.0, 0.0, breathing(t)])


def tissue_boxes() -> dict[str, tuple[FloatArray, FloatArray]]:
    """The two lips at rest: name -> (half extents, centre)."""
    half = np.array([(TISSUE_HALF_X - INCISION_GAP / 2) / 2, TISSUE_HALF_Y, TISSUE_THICK / 2])
    cx = INCISION_GAP / 2 + half[0]
    cz = SURFACE_Z - TISSUE_THICK / 2
    return {"tissue_left": (half, np.array([-cx, PATH_Y, cz])),
            "tissue_right": (half, np.array([cx, PATH_Y, cz]))}


def needle_rotation(beta: float) -> FloatArray:
    """The needle's rotation for the stitching angle ``β`` (tip at world angle β)."""
    return rot_y(-beta)


def knot_rotation(psi: float) -> FloatArray:
    """The needle held flat (its plane horizontal) pointing away along azimuth ``psi`` from
    the tail grasp point (for the knot tying)."""
    from vasim.core.geometry import rot_z

    beta = 2 * math.pi - TAIL_GRASP          # tail grasp at world angle π: centre at +x
    return rot_z(psi) @ rot_x(math.pi / 2) @ needle_rotation(beta)


def arc_point(phi: float) -> FloatArray:
    """The needle point at arc angle ``φ`` (needle frame)."""
    return NEEDLE_RADIUS * np.array([math.cos(phi), 0.0, math.sin(phi)])


def needle_points(n: int = 25) -> FloatArray:
    """``(n, 3)`` points along the needle from tail to tip (needle frame)."""
    phi = np.linspace(-math.pi, 0.0, n)
    return NEEDLE_RADIUS * np.column_stack([np.cos(phi), np.zeros(n), np.sin(phi)])


TAIL = arc_point(-math.pi)
TIP = arc_point(0.0)
GRASP_PHI = (-math.pi + TAIL_GRASP, -TIP_GRASP)


def stitch_centre(k: int) -> FloatArray:
    """The needle's centre for stitch ``k`` (tissue frame)."""
    return np.array([0.0, STITCH_Y[k], SURFACE_Z + NEEDLE_HEIGHT])


def entry_exit(k: int) -> tuple[FloatArray, FloatArray]:
    """The nominal entry and exit points of stitch ``k`` (tissue frame)."""
    c = stitch_centre(k)
    return (c + NEEDLE_RADIUS * np.array([math.cos(ENTRY_ANGLE), 0.0, math.sin(ENTRY_ANGLE)]),
            c + NEEDLE_RADIUS * np.array([math.cos(EXIT_ANGLE), 0.0, math.sin(EXIT_ANGLE)]))


def world_angle(position: FloatArray, centre: FloatArray) -> float:
    """A point's angle about the needle's axis (x-z plane, from +x towards +z), in
    ``[0, 2π)``."""
    d = np.asarray(position, float) - np.asarray(centre, float)
    return float(np.mod(math.atan2(d[2], d[0]), 2 * math.pi))


def below_surface(point: FloatArray, t: float) -> bool:
    """True when a world point is inside a lip (below the moving surface, within the lips'
    extent and outside the incision's gap)."""
    p = np.asarray(point, float) - tissue_offset(t)
    return bool(SURFACE_Z - TISSUE_THICK < p[2] < SURFACE_Z
                and INCISION_GAP / 2 < abs(p[0]) < TISSUE_HALF_X
                and abs(p[1] - PATH_Y) < TISSUE_HALF_Y)


def approach_vector() -> FloatArray:
    """The pre-grasp offset of a grasp point (needle frame): ``APPROACH`` off the needle's
    plane on the trocars' side (-y), so a waiting tool never stands in the needle's plane
    and its last approach crosses the plane at the grasp point only."""
    return np.array([0.0, -APPROACH, 0.0])


__all__ = [name for name in dir() if name.isupper()] + [
    "approach_vector", "arc_point", "below_surface", "breathing", "entry_exit",
    "knot_rotation", "needle_points", "needle_rotation", "stitch_centre", "tissue_boxes",
    "tissue_offset", "world_angle"]
