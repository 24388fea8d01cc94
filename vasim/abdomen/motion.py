"""Physiological motion: breathing and heartbeat, as prescribed displacements (pure functions).

**decision** (spec §1, "organs move periodically with breathing (~0.2–0.3 Hz, centimetre
scale) and heartbeat (~1–1.5 Hz, millimetre scale), parameterised per scene"): the motion is
*kinematic*. Each organ's anchors follow ``rest + offset(t)``, and its damping pulls toward the
frame velocity ``d offset / dt`` (so the organ rides on the motion and the springs carry it to
the free nodes, deforming a little where the motion varies in space). The offset of a point
``p`` at time ``t`` is

    offset(p, t) = A_b sin(2π f_b t + φ_b) + w(p) A_h sin(2π f_h t + φ_h),
    w(p) = exp(-|p - c|² / (2 s²))     (1 where ``falloff_m`` is None),

with the breathing amplitude vector ``A_b`` (mostly cranio-caudal, ``+y`` in the scene frame:
the diaphragm pushes the upper abdominal organs caudally on inspiration), the heartbeat
amplitude ``A_h`` fading with the distance from the heart's region ``c`` (under the diaphragm)
on the length scale ``s``. Sinusoids keep the period and amplitude exact and testable; a
breathing trace's asymmetry (longer exhalation, the Lujan model) is not modelled.

Example:
    >>> import numpy as np
    >>> m = PhysioMotion(Breathing(0.25, (0.0, 0.01, 0.0)), Heartbeat(1.0, (0.0, 0.0, 0.0)))
    >>> point_offsets(m, np.zeros((1, 3)), 1.0).round(6).tolist()  # a quarter period
    [[0.0, 0.01, 0.0]]
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vasim.abdomen.model import FloatArray, _number, _vec3
from vasim.core.config import check_type

BREATHING_HZ = 0.25
"""Default breathing rate [Hz] (15 breaths per minute; spec: ~0.2–0.3 Hz)."""
HEARTBEAT_HZ = 1.2
"""Default heart rate [Hz] (72 beats per minute; spec: ~1–1.5 Hz)."""
HEART_CENTRE = (0.0, 0.17, 0.05)
"""Default centre [m] of the region the heartbeat comes from (under the diaphragm, medial)."""


@dataclass(frozen=True)
class Breathing:
    """Breathing: a sinusoidal displacement, uniform over the organ.

    Attributes:
        frequency_hz: rate [Hz], >= 0.
        amplitude_m: (3,) peak displacement vector [m], scene frame (``+y`` cranial).
        phase: phase [rad] at t = 0.
    """

    frequency_hz: float = BREATHING_HZ
    amplitude_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    phase: float = 0.0

    def __post_init__(self) -> None:
        _number(self.frequency_hz, field_name="frequency_hz", low=0.0)
        object.__setattr__(self, "amplitude_m", _vec3(self.amplitude_m, field_name="amplitude_m"))
        _number(self.phase, field_name="phase")


@dataclass(frozen=True)
class Heartbeat:
    """Heartbeat: a sinusoidal displacement fading with the distance from the heart region.

    Attributes:
        frequency_hz: rate [Hz], >= 0.
        amplitude_m: (3,) peak displacement vector [m] at ``centre``.
        centre: (3,) centre of the region [m], scene frame.
        falloff_m: Gaussian length scale [m] of the fading, > 0; None: uniform.
        phase: phase [rad] at t = 0.
    """

    frequency_hz: float = HEARTBEAT_HZ
    amplitude_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    centre: tuple[float, float, float] = HEART_CENTRE
    falloff_m: float | None = 0.08
    phase: float = 0.0

    def __post_init__(self) -> None:
        _number(self.frequency_hz, field_name="frequency_hz", low=0.0)
        object.__setattr__(self, "amplitude_m", _vec3(self.amplitude_m, field_name="amplitude_m"))
        object.__setattr__(self, "centre", _vec3(self.centre, field_name="centre"))
        if self.falloff_m is not None:
            _number(self.falloff_m, field_name="falloff_m", low=0.0, low_open=True)
        _number(self.phase, field_name="phase")

    def weight(self, points: FloatArray) -> FloatArray:
        """(m,) amplitude factor in [0, 1] at ``points`` (m, 3) [m]."""
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if self.falloff_m is None:
            return np.ones(len(pts))
        d2 = np.sum((pts - np.asarray(self.centre)) ** 2, axis=1)
        return np.exp(-d2 / (2.0 * self.falloff_m**2))


@dataclass(frozen=True)
class PhysioMotion:
    """Breathing plus heartbeat of one organ (see the module docstring)."""

    breathing: Breathing = Breathing()
    heartbeat: Heartbeat = Heartbeat()

    def __post_init__(self) -> None:
        check_type(self.breathing, "breathing", Breathing, "a Breathing")
        check_type(self.heartbeat, "heartbeat", Heartbeat, "a Heartbeat")

    @property
    def is_static(self) -> bool:
        """True when both amplitudes are zero."""
        return not (any(self.breathing.amplitude_m) or any(self.heartbeat.amplitude_m))


def _sin_cos(freq: float, phase: float, t: float) -> tuple[float, float]:
    w = 2.0 * math.pi * freq
    return math.sin(w * t + phase), w * math.cos(w * t + phase)


def point_offsets(motion: PhysioMotion, points: FloatArray, t: float) -> FloatArray:
    """Displacement of the moving frame at rest positions ``points`` and time ``t``.

    Args:
        motion: the organ's motion.
        points: (m, 3) rest positions [m], scene frame.
        t: time [s].

    Returns:
        (m, 3) offsets [m].
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    b, h = motion.breathing, motion.heartbeat
    sb, _ = _sin_cos(b.frequency_hz, b.phase, t)
    sh, _ = _sin_cos(h.frequency_hz, h.phase, t)
    out = np.empty_like(pts)
    out[:] = sb * np.asarray(b.amplitude_m)
    if any(h.amplitude_m):
        out += (h.weight(pts) * sh)[:, None] * np.asarray(h.amplitude_m)[None, :]
    return out


def point_velocities(motion: PhysioMotion, points: FloatArray, t: float) -> FloatArray:
    """Velocity of the moving frame (time derivative of :func:`point_offsets`).

    Args:
        motion: the organ's motion.
        points: (m, 3) rest positions [m].
        t: time [s].

    Returns:
        (m, 3) velocities [m/s].
    """
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    b, h = motion.breathing, motion.heartbeat
    _, cb = _sin_cos(b.frequency_hz, b.phase, t)
    _, ch = _sin_cos(h.frequency_hz, h.phase, t)
    out = np.empty_like(pts)
    out[:] = cb * np.asarray(b.amplitude_m)
    if any(h.amplitude_m):
        out += (h.weight(pts) * ch)[:, None] * np.asarray(h.amplitude_m)[None, :]
    return out


class PointMotion:
    """:func:`point_offsets` and :func:`point_velocities` of fixed rest points, with the
    heartbeat's spatial weights computed once (for the per-step loop).

    Args:
        motion: the organ's motion.
        points: (m, 3) rest positions [m].

    Example:
        >>> import numpy as np
        >>> m = PhysioMotion(Breathing(0.25, (0.0, 0.01, 0.0)), Heartbeat(1.2, (0.0, 0.0, 1e-3)))
        >>> pts = np.random.default_rng(0).uniform(-0.1, 0.1, (5, 3))
        >>> bool(np.allclose(PointMotion(m, pts).offsets(0.3), point_offsets(m, pts, 0.3)))
        True
    """

    def __init__(self, motion: PhysioMotion, points: FloatArray) -> None:
        self.motion = motion
        self.points = np.array(points, dtype=np.float64).reshape(-1, 3)
        self._ab = np.asarray(motion.breathing.amplitude_m, dtype=np.float64)
        self._wh = (motion.heartbeat.weight(self.points)[:, None]
                    * np.asarray(motion.heartbeat.amplitude_m, dtype=np.float64)[None, :])
        self._has_heart = bool(any(motion.heartbeat.amplitude_m))

    def offsets(self, t: float) -> FloatArray:
        """(m, 3) offsets [m] at time ``t`` [s]."""
        b, h = self.motion.breathing, self.motion.heartbeat
        sb, _ = _sin_cos(b.frequency_hz, b.phase, t)
        out = np.empty_like(self.points)
        out[:] = sb * self._ab
        if self._has_heart:
            sh, _ = _sin_cos(h.frequency_hz, h.phase, t)
            out += sh * self._wh
        return out

    def velocities(self, t: float) -> FloatArray:
        """(m, 3) frame velocities [m/s] at time ``t`` [s]."""
        b, h = self.motion.breathing, self.motion.heartbeat
        _, cb = _sin_cos(b.frequency_hz, b.phase, t)
        out = np.empty_like(self.points)
        out[:] = cb * self._ab
        if self._has_heart:
            _, ch = _sin_cos(h.frequency_hz, h.phase, t)
            out += ch * self._wh
        return out


def anchor_offsets(motion: PhysioMotion, anchor_rest: FloatArray, t: float) -> FloatArray:
    """Offsets of the anchors: ``rest[anchors] + anchor_offsets(...)`` are their targets.

    Args:
        motion: the organ's motion.
        anchor_rest: (a, 3) rest positions of the anchors [m].
        t: time [s] (for a step from t to t + dt, pass t + dt).

    Returns:
        (a, 3) offsets [m].
    """
    return point_offsets(motion, anchor_rest, t)


__all__ = [
    "BREATHING_HZ",
    "HEARTBEAT_HZ",
    "HEART_CENTRE",
    "Breathing",
    "Heartbeat",
    "PhysioMotion",
    "PointMotion",
    "anchor_offsets",
    "point_offsets",
    "point_velocities",
]
