"""Laparoscopic tools through a fulcrum (the trocar: a remote centre of motion, spec §2).

A straight tool of length ``L`` is held by the robot at its mount (the robot's TCP, the
tool's axis along the TCP's z axis) and passes through the fulcrum ``f`` in the abdominal
wall. For a tip target ``p`` the pose is fixed up to the roll about the shaft:

    z = (p - f) / |p - f|          (the shaft direction, into the body)
    insertion = |p - f|            (shaft length inside the body)
    mount = f - (L - insertion) z  (where the robot holds the tool)

:func:`tool_pose_through_fulcrum` is that pure map; :class:`LaparoscopicArm` wraps any
:class:`~vasim.mrcp.interfaces.ArmKinematics` so that its TCP *is the tool tip* with the
fulcrum constraint built in (IK of a tip target = IK of the mount pose), which is what the
kernel needs to move a task held by a laparoscopic tool. :func:`fulcrum_offset` checks the
constraint against the geometry: the distance from the fulcrum to the shaft's line. An
endoscope-holding robot is the same construction with the camera at the tip
(:func:`endoscope_view` gives its viewing direction).

Frames and units: world frame, metres, radians; the wall normal points out of the body.

Example:
    >>> f = Fulcrum(point=np.zeros(3), normal=np.array([0.0, 0.0, 1.0]))
    >>> pose = tool_pose_through_fulcrum(np.array([0.0, 0.05, -0.1]), f, LaparoscopicTool(0.3))
    >>> round(pose.insertion, 4), round(fulcrum_offset(pose.mount, pose.rotation, f.point), 12)
    (0.1118, 0.0)
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from vasim.core.config import check_array, check_number, expect
from vasim.core.geometry import frame_z_x, vector_norm
from vasim.mrcp.interfaces import ArmKinematics, FloatArray


def _unit(v: FloatArray, what: str) -> FloatArray:
    v = np.asarray(v, dtype=float)
    n = float(np.linalg.norm(v))
    expect(v.shape == (3,) and math.isfinite(n) and n >= 1e-12, v, "a non-zero 3-vector",
           field=what)
    return v / n


@dataclass(frozen=True, eq=False)
class Fulcrum:
    """A trocar: its point in the abdominal wall and the wall's outward normal (world)."""

    point: FloatArray
    normal: FloatArray

    def __post_init__(self) -> None:
        p = check_array(self.point, "point", shape=(3,), what="3 finite numbers")
        object.__setattr__(self, "point", p)
        object.__setattr__(self, "normal", _unit(self.normal, "normal"))


@dataclass(frozen=True)
class LaparoscopicTool:
    """A straight tool: ``length`` from the robot's mount to the tip [m]; at least
    ``min_outside`` of it stays outside the fulcrum (the trocar and the mount's clearance)."""

    length: float
    min_outside: float = 0.05

    def __post_init__(self) -> None:
        check_number(self.length, "length", gt=0)
        check_number(self.min_outside, "min_outside", ge=0, lt=self.length)

    @property
    def max_insertion(self) -> float:
        return self.length - self.min_outside


@dataclass(frozen=True, eq=False)
class ToolPose:
    """A tool posed through its fulcrum."""

    mount: FloatArray      # (3,) where the robot holds the tool (the robot's TCP) [m]
    rotation: FloatArray   # (3, 3) tool frame, z along the shaft toward the tip
    tip: FloatArray        # (3,) [m]
    insertion: float       # shaft length past the fulcrum, inside the body [m]


_WORLD_X = np.array([1.0, 0.0, 0.0])
"""The default x hint (read only: ``frame_z_x`` does not write its arguments)."""


def _frame(z: FloatArray, x_hint: FloatArray) -> FloatArray:
    """Rotation with z axis ``z`` and x axis the part of ``x_hint`` orthogonal to it (any
    orthogonal axis if ``x_hint`` is parallel to ``z``): ``core.geometry.frame_z_x``."""
    return frame_z_x(z, x_hint, any_x=True)


def tool_pose_through_fulcrum(tip: FloatArray, fulcrum: Fulcrum, tool: LaparoscopicTool,
                              x_hint: FloatArray | None = None) -> ToolPose:
    """The tool pose reaching ``tip`` through ``fulcrum`` (module docstring).

    Args:
        tip: ``(3,)`` tip target [m], world frame, inside the body.
        fulcrum: the trocar.
        tool: the tool.
        x_hint: ``(3,)`` preferred direction of the tool's x axis (sets the roll; default:
            world x): its part orthogonal to the shaft is used.

    Raises:
        ValueError: the tip is outside the body (not below the wall), at the fulcrum, or
            deeper than the tool's ``max_insertion``.
    """
    tip = np.asarray(tip, dtype=float)
    u = tip - fulcrum.point
    insertion = vector_norm(u)     # np.linalg.norm's value, without its overhead
    if insertion < 1e-9:
        raise ValueError(f"the tip {tip.tolist()} is at the fulcrum: the shaft is undefined")
    z = u / insertion
    if float(z @ fulcrum.normal) >= 0.0:
        raise ValueError(f"the tip {tip.tolist()} is not inside the body (on the outer side "
                         f"of the wall at the fulcrum {fulcrum.point.tolist()})")
    if insertion > tool.max_insertion:
        raise ValueError(f"the tip is {insertion:.4f} m past the fulcrum; the tool reaches "
                         f"{tool.max_insertion:.4f} m")
    rot = _frame(z, _WORLD_X if x_hint is None else np.asarray(x_hint, dtype=float))
    mount = fulcrum.point - (tool.length - insertion) * z
    return ToolPose(mount, rot, tip.copy(), insertion)


def fulcrum_offset(mount: FloatArray, rotation: FloatArray, point: FloatArray) -> float:
    """Distance [m] from ``point`` (the fulcrum) to the shaft's line (through ``mount`` along
    ``rotation[:, 2]``): 0 when the tool passes through the fulcrum."""
    r = np.asarray(point, dtype=float) - np.asarray(mount, dtype=float)
    z = np.asarray(rotation, dtype=float)[:, 2]
    return vector_norm(r - float(r @ z) * z)    # np.linalg.norm's value, faster


def polar_azimuth(shaft: FloatArray, fulcrum: Fulcrum, reference: FloatArray | None = None
                  ) -> tuple[float, float]:
    """Polar angle of the shaft from the inward wall normal, and its azimuth [rad]: the
    angle of the shaft's projection on the wall, right-handed about the outward normal.

    Args:
        shaft: ``(3,)`` shaft direction (into the body).
        fulcrum: gives the normal.
        reference: ``(3,)`` direction of azimuth 0 (its part orthogonal to the normal;
            default world x).

    Returns:
        ``(alpha, theta)``: ``alpha`` in [0, π], ``theta`` in (-π, π] (the angles of the
        tool orientation cone, spec §4).
    """
    s = _unit(shaft, "shaft")
    inward = -fulcrum.normal
    alpha = math.acos(max(-1.0, min(1.0, float(s @ inward))))
    frame = _frame(fulcrum.normal, np.array([1.0, 0.0, 0.0]) if reference is None
                   else np.asarray(reference, dtype=float))
    theta = math.atan2(float(s @ frame[:, 1]), float(s @ frame[:, 0]))
    return alpha, theta


def endoscope_view(rotation: FloatArray, optics_angle: float = 0.0) -> FloatArray:
    """Viewing direction ``(3,)`` of an endoscope held as a :class:`LaparoscopicTool` (the
    camera at the tip): the shaft axis for 0° optics, tilted by ``optics_angle`` [rad]
    toward the tool's x axis for angled optics (e.g. the common 30° scope); the roll about
    the shaft turns the view around it."""
    rot = np.asarray(rotation, dtype=float)
    return math.cos(optics_angle) * rot[:, 2] + math.sin(optics_angle) * rot[:, 0]


def _skew(v: FloatArray) -> FloatArray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


class LaparoscopicArm:
    """An arm holding a tool through a fulcrum, seen as an ArmKinematics whose TCP is the tip.

    Args:
        arm: the robot (its TCP is the tool mount; the shaft runs along the TCP's z axis).
        tool: the tool.
        fulcrum: the trocar the tool passes through.
        fulcrum_tol: largest accepted :func:`fulcrum_offset` of an IK solution [m].
    """

    def __init__(self, arm: ArmKinematics, tool: LaparoscopicTool, fulcrum: Fulcrum,
                 fulcrum_tol: float = 1e-6) -> None:
        self.arm = arm
        self.tool = tool
        self.fulcrum = fulcrum
        self.fulcrum_tol = fulcrum_tol
        self.name = arm.name

    @property
    def n_joints(self) -> int:
        return self.arm.n_joints

    @property
    def joint_lower(self) -> FloatArray:
        return self.arm.joint_lower

    @property
    def joint_upper(self) -> FloatArray:
        return self.arm.joint_upper

    @property
    def max_velocity(self) -> FloatArray:
        return self.arm.max_velocity

    @property
    def max_acceleration(self) -> FloatArray:
        return self.arm.max_acceleration

    @property
    def home(self) -> FloatArray | None:
        return getattr(self.arm, "home", None)

    def tcp_pose(self, q: FloatArray) -> tuple[FloatArray, FloatArray]:
        """Tip position ``(3,)`` and tool rotation ``(3, 3)``."""
        pos, rot = self.arm.tcp_pose(q)
        return pos + self.tool.length * rot[:, 2], rot

    def jacobian(self, q: FloatArray) -> FloatArray:
        """``(6, n)`` Jacobian of the tip: ``v_tip = v_mount + ω × (tip - mount)``."""
        jac = self.arm.jacobian(q)
        _, rot = self.arm.tcp_pose(q)
        r = self.tool.length * rot[:, 2]
        out = jac.copy()
        out[:3] -= _skew(r) @ jac[3:]
        return out

    def fulcrum_error(self, q: FloatArray) -> float:
        """Distance [m] from the fulcrum to the shaft's line at ``q``."""
        pos, rot = self.arm.tcp_pose(q)
        return fulcrum_offset(pos, rot, self.fulcrum.point)

    def insertion(self, q: FloatArray) -> float:
        """Shaft length past the fulcrum [m] at ``q`` (negative: the tip is outside)."""
        tip, rot = self.tcp_pose(q)
        return float((tip - self.fulcrum.point) @ rot[:, 2])

    def ik(self, position: FloatArray, rotation: FloatArray | None = None,
           q_seed: FloatArray | None = None) -> FloatArray | None:
        """Joints putting the tip at ``position`` through the fulcrum, or None.

        The shaft direction is fixed by the fulcrum; the roll comes from ``rotation``'s x
        axis if given (whose z axis must then be the shaft direction within 1e-6 rad,
        else None), otherwise it stays as at ``q_seed``. None also when the tip is outside
        the body or beyond the tool's reach, or the arm cannot reach the mount pose.
        """
        seed = self.home if q_seed is None else q_seed
        if rotation is not None:
            x_hint = np.asarray(rotation, dtype=float)[:, 0]
        elif seed is not None:
            x_hint = self.arm.tcp_pose(np.asarray(seed, dtype=float))[1][:, 0]
        else:
            x_hint = None
        try:
            pose = tool_pose_through_fulcrum(position, self.fulcrum, self.tool, x_hint)
        except ValueError:
            return None
        if rotation is not None:
            cos = float(np.asarray(rotation, dtype=float)[:, 2] @ pose.rotation[:, 2])
            if cos < math.cos(1e-6):
                return None
        q = self.arm.ik(pose.mount, pose.rotation, q_seed)
        if q is None or self.fulcrum_error(q) > self.fulcrum_tol:
            return None
        return q
