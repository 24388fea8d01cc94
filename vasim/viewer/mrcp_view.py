"""The slave station in the viewer's 3-D scene: robots, obstacles, the task and its grasp
points, and which robot holds the task (issue 6, MRCP bullet; the seed's Figs. 4.22-4.28).

Pure part: :func:`station_geometry` reads a built scenario (:class:`~vasim.mrcp.scenarios.
base.Setup`) once — each robot's link hulls (:func:`vasim.mrcp.urdf.link_hulls`, the same
convex hulls the collision world uses), each obstacle's shape as pybullet holds it, the
task object's shape — and :func:`station_frame` turns the world's state after one cycle
into poses (:class:`StationFrame`). Shell: :class:`StationView` owns the viser handles; the
meshes are uploaded once and every frame only sets ``.position`` / ``.wxyz`` (and a colour
or a label when the roles change).

**Decision** (the task's shape): a :class:`Setup` carries the task's grasp points, not its
body; the viewer draws the body the scenario module describes (the cube of
``cube_rotation`` / ``cube_translation``, the bar of ``obstacle_hole``, the rod of
``laparoscopic_rings``, the three-spoke wheel of ``faucet``; read from their module
constants), and for any other scenario the convex hull of the grasp points.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from vasim.core.errors import ConfigError
from vasim.core.geometry import (
    from_xyzw,
    homogeneous,
    matrix_from_quat,
    quat_from_matrix,
    rot_y,
    rot_z,
)

FloatArray = NDArray[np.float64]
Rgb = tuple[int, int, int]

#: Colours: the robot holding the task (RSel), the other holder during a hand-over, the
#: receiving candidate (RCnt), another kernel robot, a robot outside the task (a camera).
COLOR_RSEL: Rgb = (235, 120, 30)
COLOR_HOLDER: Rgb = (240, 185, 80)
COLOR_RCNT: Rgb = (60, 140, 230)
COLOR_IDLE: Rgb = (175, 178, 188)
COLOR_OTHER: Rgb = (110, 110, 115)
COLOR_TASK: Rgb = (200, 40, 60)
COLOR_OBSTACLE: Rgb = (120, 150, 110)
COLOR_SENSING: Rgb = (250, 220, 90)


@dataclass(frozen=True, eq=False)
class RobotShape:
    """A robot of the station: its model, base and link hulls (link ``k`` frame, [m]).

    Attributes:
        in_task: True for the kernel's robots (those that may hold the task).
    """

    name: str
    model: Any
    base: FloatArray
    hulls: tuple[trimesh.Trimesh, ...]
    in_task: bool


@dataclass(frozen=True, eq=False)
class BodyShape:
    """An obstacle (body frame, [m]); ``sensing``: seen by distance queries only (a camera's
    view cone), drawn translucent."""

    name: str
    mesh: trimesh.Trimesh
    sensing: bool = False


@dataclass(frozen=True, eq=False)
class StationGeometry:
    """Everything drawn once: robots, obstacles, the task body and grasp points (task
    frame, ``(m, 3)`` [m]), and where the task starts (``(3,)`` [m], world frame)."""

    scenario: str
    robots: tuple[RobotShape, ...]
    obstacles: tuple[BodyShape, ...]
    task: trimesh.Trimesh
    task_points: FloatArray
    task_start: FloatArray = dataclasses.field(default_factory=lambda: np.zeros(3))

    @property
    def robot_names(self) -> tuple[str, ...]:
        return tuple(r.name for r in self.robots)


@dataclass(frozen=True, eq=False)
class StationFrame:
    """Poses after one cycle; a pose is ``(7,)`` = position [m] then quaternion ``wxyz``.

    Attributes:
        links: robot -> ``(n + 1, 7)`` poses of links 0 (base) .. n, world frame.
        obstacles: obstacle -> pose.
        task: the task body's pose.
        rsel, cutp: who holds the task (RSel) and at which grasp point (CuTP).
        holders: every robot grasping the task (two during a hand-over).
        rcnt: the receiving candidate (None outside a transfer).
        state: the kernel's mode (``"TOp"``, ``"TT"``, ...).
    """

    links: Mapping[str, FloatArray]
    obstacles: Mapping[str, FloatArray]
    task: FloatArray
    rsel: str
    cutp: int
    holders: tuple[str, ...]
    rcnt: str | None
    state: str


# ------------------------------------------------------------------------------ pure
def pose7(matrix: FloatArray) -> FloatArray:
    """``(..., 4, 4)`` transforms -> ``(..., 7)`` poses (position, quaternion ``wxyz``).

    Example:
        >>> pose7(np.eye(4)).tolist()
        [0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    """
    m = np.asarray(matrix, dtype=float)
    wxyz = quat_from_matrix(m[..., :3, :3].reshape(-1, 3, 3))
    out = np.concatenate([m[..., :3, 3].reshape(-1, 3), wxyz], axis=1)
    return out.reshape(*m.shape[:-2], 7)


def link_poses(model: Any, base: FloatArray, q: FloatArray) -> FloatArray:
    """``(n + 1, 7)`` world poses of links 0..n (DH frames) of ``model`` at ``q``."""
    from vasim.mrcp.dh import link_frames

    return pose7(link_frames(model, np.asarray(q, dtype=float), base)[:-1])


def task_pose(position: FloatArray, rotation: FloatArray | None) -> FloatArray:
    """The task body's ``(7,)`` pose (a position-only task keeps the identity rotation)."""
    m = np.eye(4)
    if rotation is not None:
        m[:3, :3] = rotation
    m[:3, 3] = position
    return pose7(m)


def _pybullet_worlds(world: Any) -> list[tuple[Any, bool]]:
    """The pybullet worlds behind a station: ``(world, sensing)`` pairs."""
    if hasattr(world, "physical") and hasattr(world, "sensing"):   # scenarios.world.Station
        return [(world.physical, False), (world.sensing, True)]
    if hasattr(world, "client_id") and hasattr(world, "body_id"):
        return [(world, False)]
    raise ConfigError(f"the viewer cannot draw a station of type {type(world).__name__} "
                      "(it needs a PybulletWorld or a scenarios Station)", field="world")


def obstacle_mesh(client: int, body: int, name: str = "?") -> trimesh.Trimesh:
    """An obstacle's collision shape as pybullet holds it (body frame): box, sphere,
    cylinder, capsule or convex mesh."""
    import pybullet as pb

    data = pb.getCollisionShapeData(body, -1, physicsClientId=client)
    if not data:
        raise ConfigError(f"obstacle {name!r} has no collision shape", field="world")
    _, _, kind, dims, _, local_pos, local_orn = data[0][:7]
    if kind == pb.GEOM_BOX:
        mesh = trimesh.creation.box(extents=[float(v) for v in dims])
    elif kind == pb.GEOM_SPHERE:
        mesh = trimesh.creation.icosphere(subdivisions=2, radius=float(dims[0]))
    elif kind in (pb.GEOM_CYLINDER, pb.GEOM_CAPSULE):
        make = trimesh.creation.cylinder if kind == pb.GEOM_CYLINDER else \
            trimesh.creation.capsule
        mesh = make(radius=float(dims[1]), height=float(dims[0]))
    elif kind == pb.GEOM_MESH:
        _, verts = pb.getMeshData(body, -1, physicsClientId=client)
        mesh = trimesh.convex.convex_hull(np.asarray(verts, dtype=float))
    else:
        raise ConfigError(f"obstacle {name!r}: pybullet shape type {kind} is not drawable",
                          field="world")
    local = np.eye(4)
    local[:3, :3] = matrix_from_quat(from_xyzw(local_orn))  # pybullet: xyzw
    local[:3, 3] = local_pos
    if not np.allclose(local, np.eye(4)):
        mesh.apply_transform(local)
    return mesh


def obstacle_poses(world: Any) -> dict[str, FloatArray]:
    """Every obstacle's ``(7,)`` pose (read from pybullet: moving obstacles included)."""
    import pybullet as pb

    out: dict[str, FloatArray] = {}
    for w, _ in _pybullet_worlds(world):
        for name in w.obstacle_names():
            pos, xyzw = pb.getBasePositionAndOrientation(w.body_id(name),
                                                         physicsClientId=w.client_id)
            out[name] = np.array([*pos, *from_xyzw(xyzw)])
    return out


def task_shape(scenario: str, points: FloatArray) -> trimesh.Trimesh:
    """The task body in the task frame (see the module's decision)."""
    from vasim.mrcp.scenarios import (
        cube_rotation,
        cube_translation,
        faucet,
        laparoscopic_rings,
        obstacle_hole,
    )

    if scenario == "cube_rotation":
        return trimesh.creation.box(extents=[2 * cube_rotation.HALF] * 3)
    if scenario == "cube_translation":
        return trimesh.creation.box(extents=[2 * cube_translation.HALF] * 3)
    if scenario == "obstacle_hole":
        return trimesh.creation.box(extents=[0.02, 2 * obstacle_hole.HALF_BAR, 0.02])
    if scenario == "laparoscopic_rings":
        rod = trimesh.creation.cylinder(radius=0.004, height=2 * laparoscopic_rings.HALF_ROD)
        rod.apply_transform(homogeneous(rot_y(math.pi / 2)))
        return rod
    if scenario == "suture_combined":
        return needle_mesh()
    if scenario == "faucet":
        parts = [trimesh.creation.cylinder(radius=0.02, height=0.03)]
        for k in range(3):
            a = 2 * math.pi * k / 3
            spoke = trimesh.creation.cylinder(radius=0.008, height=faucet.RADIUS)
            spoke.apply_transform(homogeneous(rot_y(math.pi / 2)))
            spoke.apply_translation([faucet.RADIUS / 2, 0.0, 0.0])
            spoke.apply_transform(homogeneous(rot_z(a)))
            parts.append(spoke)
        wheel = trimesh.util.concatenate(parts)
        assert isinstance(wheel, trimesh.Trimesh)  # Trimesh parts concatenate to one Trimesh
        return wheel
    pts = np.asarray(points, dtype=float)
    try:
        return trimesh.convex.convex_hull(pts)
    except Exception:  # fewer than 4 points or coplanar: a small ball at their centre
        ball = trimesh.creation.icosphere(subdivisions=1, radius=0.015)
        ball.apply_translation(pts.mean(axis=0) if len(pts) else np.zeros(3))
        return ball


def needle_mesh(radius: float = 0.0006) -> trimesh.Trimesh:
    """The suture's curved needle (needle frame): short cylinders along its arc."""
    from vasim.mrcp.scenarios.suture_geometry import needle_points

    pts = needle_points(19)
    parts = [trimesh.creation.cylinder(radius=radius, segment=np.array([a, b]))
             for a, b in itertools.pairwise(pts)]
    out = trimesh.util.concatenate(parts)
    assert isinstance(out, trimesh.Trimesh)  # Trimesh parts concatenate to one Trimesh
    return out


def subtask_text(sample: Any) -> str | None:
    """The suture's subtask line (``"stitch 2 · pass_through · MRCP"``), None for a
    scenario without subtasks.

    Example:
        >>> class S: subtask, mode, scene = "insertion", "MRCP", {"stitch": 2}
        >>> subtask_text(S())
        'stitch 2 · insertion · MRCP'
    """
    sub = getattr(sample, "subtask", None)
    if sub is None:
        return None
    scene = getattr(sample, "scene", None) or {}
    stitch = scene.get("stitch")
    head = f"stitch {stitch} · " if stitch and sub not in ("pre_suture", "knot_tying") else ""
    return f"{head}{sub} · {getattr(sample, 'mode', None) or '?'}"


class SubtaskView:
    """The suture's extra scene nodes (``/mrcp/suture``): the thread as line segments
    (its free chain and the pinned path through the stitches) and a label with the current
    subtask and pairing mode. Created by the app for a run whose samples carry a subtask."""

    def __init__(self, server: viser.ViserServer):
        scene = server.scene
        empty = np.zeros((1, 2, 3), dtype=np.float32)
        self.thread = scene.add_line_segments("/mrcp/suture/thread", empty,
                                              (30, 30, 160), thickness=0.0008)
        self.pinned = scene.add_line_segments("/mrcp/suture/pinned", empty,
                                              (90, 60, 160), thickness=0.0008)
        self.label = scene.add_label("/mrcp/suture/subtask", "subtask", anchor="bottom-left",
                                     font_screen_scale=1.2)
        self.updates = 0

    def node_names(self) -> list[str]:
        return sorted([self.thread.name, self.pinned.name, self.label.name])

    @staticmethod
    def segments(points: Any) -> NDArray[np.float32]:
        """``(n, 3)`` polyline -> ``(n - 1, 2, 3)`` segments (one degenerate for n < 2)."""
        p = np.asarray(points, dtype=np.float32).reshape(-1, 3)
        if len(p) < 2:
            return np.zeros((1, 2, 3), dtype=np.float32)
        return np.stack([p[:-1], p[1:]], axis=1)

    def update(self, sample: Any) -> None:
        """Draws the thread and the subtask label of one sample (inside ``atomic()``)."""
        scene = getattr(sample, "scene", None) or {}
        if "thread" in scene:
            self.thread.points = self.segments(scene["thread"])
        if "pinned" in scene:
            self.pinned.points = self.segments(scene["pinned"])
        text = subtask_text(sample)
        if text is not None and self.label.text != text:
            self.label.text = text
        pos = np.asarray(sample.task_position, dtype=np.float64)
        self.label.position = pos + np.array([0.0, 0.0, 0.05])
        self.updates += 1


def station_geometry(scenario: str, setup: Any) -> StationGeometry:
    """What :class:`StationView` draws, read from a built scenario (before it runs)."""
    from vasim.mrcp.urdf import link_hulls

    worlds = _pybullet_worlds(setup.world)
    physical = worlds[0][0]
    robots = tuple(RobotShape(r, physical.robot_model(r), physical.robot_base(r),
                              link_hulls(physical.robot_model(r)), r in setup.arms)
                   for r in physical.robot_names())
    obstacles = tuple(BodyShape(o, obstacle_mesh(w.client_id, w.body_id(o), o), sensing)
                      for w, sensing in worlds for o in w.obstacle_names())
    points = np.array([tp.position for tp in setup.task_points], dtype=float).reshape(-1, 3)
    start = np.asarray(setup.operator(0.0)[0], dtype=float)
    return StationGeometry(scenario, robots, obstacles, task_shape(scenario, points), points,
                           start)


def station_frame(geometry: StationGeometry, world: Any, sample: Any) -> StationFrame:
    """The poses after one cycle: robots at the world's configurations (every robot of the
    station, also those outside the task), obstacles where pybullet has them, the task at
    the sample's achieved pose (``sample``: a runner :class:`~vasim.mrcp.scenarios.runner.
    Sample`)."""
    from vasim.mrcp.dh import frames_one

    # **Decision** (issue #17 §5, cost: this runs on the scenario thread every cycle): every
    # robot's link frames by the compiled chain and one quaternion conversion for all of
    # them (0.7 -> 0.2 ms a cycle for 8 robots); the same poses as :func:`link_poses`
    frames = [frames_one(r.model, world.configuration(r.name), r.base)[:-1]
              for r in geometry.robots]
    poses = pose7(np.concatenate(frames)) if frames else np.zeros((0, 7))
    links, start = {}, 0
    for r, f in zip(geometry.robots, frames, strict=True):
        links[r.name] = poses[start:start + len(f)]
        start += len(f)
    return StationFrame(links, obstacle_poses(world),
                        task_pose(sample.task_position, sample.task_rotation),
                        sample.rsel, int(sample.cutp), tuple(sample.holders), sample.rcnt,
                        str(sample.state))


def robot_role(name: str, frame: StationFrame, in_task: bool) -> str:
    """``"rsel"``, ``"holder"`` (the other grasping robot in a hand-over), ``"rcnt"``,
    ``"idle"`` (a kernel robot waiting) or ``"other"`` (outside the task)."""
    if name == frame.rsel:
        return "rsel"
    if name in frame.holders:
        return "holder"
    if name == frame.rcnt:
        return "rcnt"
    return "idle" if in_task else "other"


ROLE_COLOR: dict[str, Rgb] = {"rsel": COLOR_RSEL, "holder": COLOR_HOLDER,
                              "rcnt": COLOR_RCNT, "idle": COLOR_IDLE, "other": COLOR_OTHER}
ROLE_TEXT: dict[str, str] = {"rsel": "holds the task", "holder": "grasping (hand-over)",
                             "rcnt": "receiving (RCnt)", "idle": "waiting", "other": ""}


def holder_text(frame: StationFrame) -> str:
    """The holder label: who holds the task, at which point, and a hand-over in progress.

    Example:
        >>> f = StationFrame({}, {}, np.zeros(7), "R1", 0, ("R1",), "R0", "TT")
        >>> holder_text(f)
        'task: R1 @ point 0 → R0'
    """
    text = f"task: {frame.rsel} @ point {frame.cutp}"
    if frame.rcnt is not None and frame.rcnt != frame.rsel:
        text += f" → {frame.rcnt}"
    return text


# ------------------------------------------------------------------------------ shell
class StationView:
    """The station's scene nodes under ``/mrcp``: per robot one mesh per link
    (``/mrcp/robots/<R>/link<k>``) and a label, the obstacles, the task body, its grasp
    points (CuTP in red) and the holder label (``/mrcp/task/holder``).

    Meshes are uploaded once; :meth:`update` sets poses, and colours / label texts only
    when a robot's role changes.
    """

    def __init__(self, server: viser.ViserServer, geometry: StationGeometry):
        scene = server.scene
        self.geometry = geometry
        self.links: dict[str, list[Any]] = {}
        self.labels: dict[str, Any] = {}
        self._roles: dict[str, str] = {}
        for r in geometry.robots:
            color = COLOR_IDLE if r.in_task else COLOR_OTHER
            self.links[r.name] = [
                scene.add_mesh_simple(f"/mrcp/robots/{r.name}/link{k}",
                                      np.asarray(h.vertices, dtype=np.float32),
                                      np.asarray(h.faces, dtype=np.uint32), color=color,
                                      flat_shading=False)
                for k, h in enumerate(r.hulls)]
            self.labels[r.name] = scene.add_label(
                f"/mrcp/robots/{r.name}/label", r.name,
                position=np.asarray(r.base[:3, 3] + np.array([0, 0, 0.42]), dtype=np.float64),
                anchor="bottom-center")
        self.obstacles: dict[str, Any] = {}
        for o in geometry.obstacles:
            self.obstacles[o.name] = scene.add_mesh_simple(
                f"/mrcp/obstacles/{o.name}", np.asarray(o.mesh.vertices, dtype=np.float32),
                np.asarray(o.mesh.faces, dtype=np.uint32),
                color=COLOR_SENSING if o.sensing else COLOR_OBSTACLE,
                opacity=0.25 if o.sensing else None, side="double" if o.sensing else "front",
                cast_shadow=not o.sensing)
        self.task = scene.add_mesh_simple(
            "/mrcp/task/body", np.asarray(geometry.task.vertices, dtype=np.float32),
            np.asarray(geometry.task.faces, dtype=np.uint32), color=COLOR_TASK)
        n = len(geometry.task_points)
        self.points = scene.add_point_cloud(
            "/mrcp/task/points", geometry.task_points.astype(np.float32),
            np.tile(np.array([[40, 40, 40]], dtype=np.uint8), (max(n, 1), 1))[:n],
            point_size=0.012, point_shape="circle")
        self.holder = scene.add_label("/mrcp/task/holder", "task", anchor="bottom-left",
                                      font_screen_scale=1.2)
        self._cutp = -1
        self._obstacle_poses: dict[str, FloatArray] = {}
        self.updates = 0

    def node_names(self) -> list[str]:
        """Names of the scene nodes this view owns."""
        names = [h.name for hs in self.links.values() for h in hs]
        names += [h.name for h in self.labels.values()]
        names += [h.name for h in self.obstacles.values()]
        return sorted([*names, self.task.name, self.points.name, self.holder.name])

    def update(self, frame: StationFrame) -> None:
        """Poses every node from ``frame`` (call inside ``server.atomic()``)."""
        for r in self.geometry.robots:
            poses = frame.links[r.name]
            for h, p in zip(self.links[r.name], poses, strict=True):
                h.position = tuple(float(v) for v in p[:3])
                h.wxyz = tuple(float(v) for v in p[3:])
            role = robot_role(r.name, frame, r.in_task)
            if self._roles.get(r.name) != role:
                self._roles[r.name] = role
                for h in self.links[r.name]:
                    h.color = ROLE_COLOR[role]
                text = ROLE_TEXT[role]
                self.labels[r.name].text = f"{r.name}: {text}" if text else r.name
        for name, pose in frame.obstacles.items():
            h = self.obstacles.get(name)
            last = self._obstacle_poses.get(name)
            if h is None or (last is not None and np.array_equal(last, pose)):
                continue
            self._obstacle_poses[name] = pose
            h.position = tuple(float(v) for v in pose[:3])
            h.wxyz = tuple(float(v) for v in pose[3:])
        pos, wxyz = frame.task[:3], frame.task[3:]
        self.task.position = np.asarray(pos, dtype=np.float64)
        self.task.wxyz = np.asarray(wxyz, dtype=np.float64)
        rot = matrix_from_quat(wxyz)
        pts = self.geometry.task_points @ rot.T + pos
        self.points.points = pts.astype(np.float32)
        if frame.cutp != self._cutp and len(pts):
            self._cutp = frame.cutp
            colors = np.tile(np.array([[40, 40, 40]], dtype=np.uint8), (len(pts), 1))
            if 0 <= frame.cutp < len(pts):
                colors[frame.cutp] = COLOR_TASK
            self.points.colors = colors
        text = holder_text(frame)
        if self.holder.text != text:
            self.holder.text = text
        self.holder.position = np.asarray(pos + np.array([0.0, 0.0, 0.08]), dtype=np.float64)
        self.updates += 1


__all__ = [
    "BodyShape",
    "RobotShape",
    "StationFrame",
    "StationGeometry",
    "StationView",
    "SubtaskView",
    "holder_text",
    "link_poses",
    "needle_mesh",
    "obstacle_mesh",
    "obstacle_poses",
    "pose7",
    "robot_role",
    "station_frame",
    "station_geometry",
    "subtask_text",
    "task_pose",
]
