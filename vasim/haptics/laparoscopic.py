"""A laparoscopic instrument pivoting about its trocar: 4 degrees of freedom, pure math.

A straight instrument passes through a port (trocar) in the abdominal wall, which it cannot
leave. Its pose has four degrees of freedom (spec: a laparoscopic tool has "4 DOF" at the
fulcrum; seed ch. 2 on minimally invasive surgery):

* two angles of the shaft about the port: ``yaw`` (about the port frame's y axis) and
  ``pitch`` (about its x axis), measured from the port's neutral direction ``axis`` (the
  line from the port toward the working area);
* ``insertion``: the tip's distance beyond the fulcrum along the shaft [m];
* ``roll``: rotation of the instrument about its own shaft [rad].

The tip is ``fulcrum + insertion * d(yaw, pitch)``. The **fulcrum effect**: the surgeon's
hand is outside the body, on the other side of the pivot, so moving the handle right moves
the tip left. Input devices without a handle (a mouse, a keyboard, a gamepad) therefore
map a rightward motion to a *negative* angle change when the fulcrum effect is on (the
default, as in box trainers and the operating room) and to a positive one when it is off.

The angles are confined to a cone of half-angle ``max_angle_rad`` about ``axis``
(**decision**: 60 deg; a port in a ~1 cm wall allows about this before the shaft would
lever the wall) and the insertion to [``min_insertion_m``, ``max_insertion_m``]
(**decision**: 2-30 cm: the tip always stays inside the body, and the standard 33-36 cm
instruments leave a handle length outside).

Frames: world frame (the scene's: x to the patient's left, y cranial, z up). Quaternions
are (w, x, y, z) like every :class:`vasim.haptics.device.DeviceSample`.

Example:
    >>> import numpy as np
    >>> port = Port(fulcrum=(0.0, 0.0, 0.1), axis=(0.0, 0.0, -1.0))
    >>> pose = InstrumentPose(yaw=0.0, pitch=0.0, insertion=0.05, roll=0.0)
    >>> tip_position(port, pose).round(6).tolist()
    [0.0, 0.0, 0.05]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vasim.core import geometry
from vasim.core.config import check_number, expect

FloatArray = NDArray[np.float64]

MAX_ANGLE_RAD = math.radians(60.0)
MIN_INSERTION_M = 0.02
MAX_INSERTION_M = 0.30


def _unit(v: ArrayLike, name: str) -> FloatArray:
    a = np.asarray(v, dtype=float).reshape(3)
    n = float(np.linalg.norm(a))
    expect(np.isfinite(a).all() and n >= 1e-9, a.tolist(), "a finite non-zero 3-vector",
           field=name)
    return a / n


@dataclass(frozen=True, eq=False)
class Port:
    """A trocar: where the shaft pivots and which way it points at rest.

    Attributes:
        fulcrum: (3,) pivot point on the abdominal wall [m], world frame.
        axis: (3,) neutral shaft direction into the body (normalised on construction).
        max_angle_rad: half-angle of the cone the shaft may sweep about ``axis``.
        min_insertion_m, max_insertion_m: tip distance beyond the fulcrum [m].
    """

    fulcrum: FloatArray
    axis: FloatArray
    max_angle_rad: float = MAX_ANGLE_RAD
    min_insertion_m: float = MIN_INSERTION_M
    max_insertion_m: float = MAX_INSERTION_M
    frame: FloatArray = field(init=False, repr=False)
    """(3, 3) rotation from the port frame (z = ``axis``) to the world frame."""

    def __post_init__(self) -> None:
        f = np.asarray(self.fulcrum, dtype=float).reshape(3)
        expect(np.isfinite(f).all() and float(np.abs(f).max()) <= 10.0, f.tolist(),
               "a finite point within 10 m", field="fulcrum")
        z = _unit(self.axis, "axis")
        check_number(self.max_angle_rad, "max_angle_rad", gt=0.0, lt=math.pi / 2)
        expect(0.0 <= self.min_insertion_m < self.max_insertion_m <= 1.0,
               (self.min_insertion_m, self.max_insertion_m),
               "an insertion range 0 <= min < max <= 1 m", field="max_insertion_m")
        # Port frame: z along the shaft, x horizontal (world z cross shaft), y completing it.
        ref = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.95 else np.array([0.0, 1.0, 0.0])
        x = np.cross(ref, z)
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        object.__setattr__(self, "fulcrum", f)
        object.__setattr__(self, "axis", z)
        object.__setattr__(self, "frame", np.column_stack([x, y, z]))

    @classmethod
    def toward(cls, fulcrum: ArrayLike, target: ArrayLike, **limits: float) -> Port:
        """A port at ``fulcrum`` whose neutral direction points at ``target``."""
        f = np.asarray(fulcrum, dtype=float)
        return cls(fulcrum=f, axis=np.asarray(target, dtype=float) - f, **limits)


@dataclass(frozen=True)
class InstrumentPose:
    """The instrument's four degrees of freedom (angles [rad], insertion [m])."""

    yaw: float = 0.0
    pitch: float = 0.0
    insertion: float = 0.08
    roll: float = 0.0


def shaft_direction(port: Port, pose: InstrumentPose) -> FloatArray:
    """(3,) unit direction of the shaft, world frame: ``axis`` turned by yaw then pitch."""
    return port.frame @ _local_direction(pose.yaw, pose.pitch)


def tip_position(port: Port, pose: InstrumentPose) -> FloatArray:
    """(3,) tip position [m], world frame."""
    return port.fulcrum + pose.insertion * shaft_direction(port, pose)


def orientation(port: Port, pose: InstrumentPose) -> FloatArray:
    """(4,) unit quaternion (w, x, y, z) of the instrument: its z axis along the shaft, turned
    by ``roll`` about it (canonical, w >= 0: ``vasim.core.geometry``'s decision)."""
    return geometry.quat_from_frame_euler(port.frame, "YXZ",
                                          [pose.yaw, pose.pitch, pose.roll])


def _local_direction(yaw: float, pitch: float) -> FloatArray:
    return np.array([math.sin(yaw) * math.cos(pitch), -math.sin(pitch),
                     math.cos(yaw) * math.cos(pitch)])


def _angles(local: FloatArray) -> tuple[float, float]:
    """(yaw, pitch) of a unit direction in the port frame (inverse of the above)."""
    pitch = -math.asin(max(-1.0, min(1.0, float(local[1]))))
    return math.atan2(float(local[0]), float(local[2])), pitch


def clamp(port: Port, pose: InstrumentPose) -> InstrumentPose:
    """``pose`` brought inside the port's limits: a shaft outside the cone is turned back to
    its rim along the same azimuth, the insertion clipped, the roll wrapped to [-pi, pi]."""
    yaw, pitch = pose.yaw, pose.pitch
    local = _local_direction(yaw, pitch)
    if math.acos(max(-1.0, min(1.0, float(local[2])))) > port.max_angle_rad:
        h = math.hypot(float(local[0]), float(local[1]))
        rim = np.array([math.sin(port.max_angle_rad) * local[0] / h,
                        math.sin(port.max_angle_rad) * local[1] / h,
                        math.cos(port.max_angle_rad)])
        yaw, pitch = _angles(rim)
    insertion = min(max(pose.insertion, port.min_insertion_m), port.max_insertion_m)
    return InstrumentPose(yaw=yaw, pitch=pitch, insertion=insertion,
                          roll=math.remainder(pose.roll, 2 * math.pi))


@dataclass(frozen=True)
class Increment:
    """One batch of raw input from a page, in the units each input has.

    Attributes:
        dx_px, dy_px: pointer movement [CSS px] (pointer lock), + right / + down.
        wheel: wheel movement [lines], + away from the user (inserts).
        insert_s, roll_s: seconds a key pair was held (+ insert / + roll clockwise), or the
            gamepad's trigger/stick value integrated over the batch [s].
        stick_x_s, stick_y_s: a gamepad stick integrated over the batch [s] (full deflection
            for one second = 1), + right / + down.
    """

    dx_px: float = 0.0
    dy_px: float = 0.0
    wheel: float = 0.0
    insert_s: float = 0.0
    roll_s: float = 0.0
    stick_x_s: float = 0.0
    stick_y_s: float = 0.0

    def finite(self) -> bool:
        """True when every field is a finite number (a page can send anything)."""
        return all(math.isfinite(v) for v in (self.dx_px, self.dy_px, self.wheel,
                                               self.insert_s, self.roll_s, self.stick_x_s,
                                               self.stick_y_s))


@dataclass(frozen=True)
class InputMapping:
    """How raw input becomes instrument motion.

    Attributes:
        fulcrum_effect: True: a rightward/downward hand motion moves the tip left/up, as
            with a real instrument; False: the tip follows the hand.
        rad_per_px: shaft angle per pointer pixel (**decision**: 1.5 mrad/px: a 300 px
            mouse stroke sweeps ~26 deg, about the working cone of one task).
        m_per_line: insertion per wheel line (**decision**: 4 mm).
        insert_m_per_s: insertion speed while a key is held (**decision**: 5 cm/s, a
            deliberate advance).
        roll_rad_per_s: roll speed while a key is held (**decision**: 90 deg/s).
        stick_rad_per_s: shaft angular speed at full gamepad deflection (**decision**:
            45 deg/s).
        sensitivity: a factor on every gain (the trainee's setting, 0.1-5).
    """

    fulcrum_effect: bool = True
    rad_per_px: float = 1.5e-3
    m_per_line: float = 4e-3
    insert_m_per_s: float = 0.05
    roll_rad_per_s: float = math.radians(90.0)
    stick_rad_per_s: float = math.radians(45.0)
    sensitivity: float = 1.0

    def __post_init__(self) -> None:
        for name in ("rad_per_px", "m_per_line", "insert_m_per_s", "roll_rad_per_s",
                     "stick_rad_per_s"):
            check_number(getattr(self, name), name, gt=0)
        check_number(self.sensitivity, "sensitivity", ge=0.1, le=5.0)

    def apply(self, port: Port, pose: InstrumentPose, inc: Increment,
              screen: tuple[ArrayLike, ArrayLike] | None = None) -> InstrumentPose:
        """The pose after ``inc`` (clamped to the port's limits).

        Pointer and stick motion are *screen* motion: ``screen`` = (right, up), the view's
        axes in the world frame (the endoscope's; default: the port frame's x and y). The
        tip is moved along them — mirrored through the pivot when ``fulcrum_effect`` is on —
        by turning the shaft about the fulcrum; the part of the motion along the shaft is
        dropped (only insertion changes the depth). A non-finite increment changes nothing.
        """
        if not inc.finite():
            return pose
        k = self.sensitivity
        right, up = ((port.frame[:, 0], port.frame[:, 1]) if screen is None else
                     (np.asarray(screen[0], dtype=float), np.asarray(screen[1], dtype=float)))
        # Shaft angle wanted [rad] along screen right / up (pointer y grows downward).
        a_right = k * (self.rad_per_px * inc.dx_px + self.stick_rad_per_s * inc.stick_x_s)
        a_up = -k * (self.rad_per_px * inc.dy_px + self.stick_rad_per_s * inc.stick_y_s)
        # A single batch turns at most 45 deg (a runaway page cannot teleport the tool).
        a_right, a_up = (float(np.clip(v, -math.pi / 4, math.pi / 4)) for v in (a_right, a_up))
        move = a_right * right + a_up * up
        if self.fulcrum_effect:
            move = -move
        d = shaft_direction(port, pose)
        perp = move - float(move @ d) * d
        yaw, pitch = pose.yaw, pose.pitch
        angle = float(np.linalg.norm(perp))
        if angle > 0.0 and math.isfinite(angle):
            axis = np.cross(d, perp) / angle
            new_d = geometry.rotate_by_rotvec(axis * angle, d)
            yaw, pitch = _angles(port.frame.T @ new_d)
        d_ins = float(np.clip(k * (self.m_per_line * inc.wheel
                                   + self.insert_m_per_s * inc.insert_s), -0.1, 0.1))
        d_roll = float(np.clip(k * self.roll_rad_per_s * inc.roll_s, -math.pi / 2,
                               math.pi / 2))
        return clamp(port, replace(pose, yaw=yaw, pitch=pitch,
                                   insertion=pose.insertion + d_ins, roll=pose.roll + d_roll))


__all__ = [
    "MAX_ANGLE_RAD",
    "MAX_INSERTION_M",
    "MIN_INSERTION_M",
    "Increment",
    "InputMapping",
    "InstrumentPose",
    "Port",
    "clamp",
    "orientation",
    "shaft_direction",
    "tip_position",
]
