"""One class per visual of the browser viewer; each owns its viser handles.

Every view is built once against a ``viser.ViserServer`` and then fed immutable values
(a ``TrialFrame``'s fields, an ``Organ``) through ``update(...)``: views only read, they
never touch the simulation (style guide §10). ``update`` is cheap when nothing changed:
each view remembers what it last sent and skips redundant handle writes, because every
property write is a websocket message to every browser.

Scene node names (stable: browser tests look them up)::

    /organs/<organ name>           OrganView
    /tool/shaft, /tool/tip         ToolView
    /trajectory/points, /trajectory/path, /trajectory/goal, /trajectory/normal
                                   TrajectoryView
    /overlays/arrow_<i>            ArrowView (VG guidance and FF force arrows)
    /overlays/ghost                GhostView (MS ghost cone)

Frame: the scene's world frame, metres, ``z`` up (set on the server by the app).
"""

from __future__ import annotations

import logging
import math
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, Protocol

import numpy as np
import trimesh
import viser
from numpy.typing import NDArray

from vasim.abdomen.anatomy import Organ
from vasim.core.geometry import matrix_z_to
from vasim.fixtures.types import Arrow, CameraView
from vasim.viewer.camera_pose import CameraPose
from vasim.viewer.endoscope import tissue_patches

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]
Rgb = tuple[int, int, int]


def rgb255(color: Sequence[float]) -> Rgb:
    """RGB in [0, 1] -> integer RGB in [0, 255] (what viser takes)."""
    r, g, b = (min(255, max(0, round(float(c) * 255.0))) for c in color)
    return (r, g, b)


# ---------------------------------------------------------------------------------------
# Organs


def organ_style(organ: Organ) -> dict[str, object]:
    """Drawing options per organ kind.

    The wall is faint and drawn front faces only: its outer surface faces out of the body and
    its inner surface into the cavity, so a camera inside the cavity sees the ceiling, one
    outside sees a light veil, and one inside the wall slab itself (where Mag's dolly can put
    it) sees neither instead of a white-out.
    """
    if organ.kind == "wall":
        return {"opacity": 0.12, "side": "front", "flat_shading": True,
                "cast_shadow": False, "receive_shadow": False}
    return {"opacity": None, "side": "front", "flat_shading": False,
            "cast_shadow": True, "receive_shadow": True}


def set_gui_value(handle: Any, value: object) -> None:
    """Assigns a viser GUI input's value (synchronised to every client by viser).

    ``handle`` is any of viser's input handles (``GuiInputHandle`` subclasses, or the
    progress bar's handle, which viser does not export).

    viser 1.1 declares the ``value`` setter with a wider type than the getter, which mypy
    reports as a read-only property; the assignment is done here, once, instead.
    """
    setattr(handle, "value", value)  # noqa: B010 (see the docstring)


class SceneView(Protocol):
    """What every view owning scene nodes offers (for listing them, e.g. in tests)."""

    def node_names(self) -> list[str]:
        """Names of the scene nodes this view owns."""
        ...


class OrganView:
    """One organ surface (``/organs/<name>``); deformable in place.

    Args:
        server: the viser server.
        organ: the organ (mesh in metres, world frame).
    """

    def __init__(self, server: viser.ViserServer, organ: Organ, *, tones: bool = False):
        self.organ = organ
        self.name = f"/organs/{organ.name}"
        v = np.ascontiguousarray(organ.mesh.vertices, dtype=np.float32)
        f = np.ascontiguousarray(organ.mesh.faces, dtype=np.uint32)
        self.n_vertices = len(v)
        parts = [(f, rgb255(organ.color))]
        if tones and organ.kind != "wall":  # the endoscope's tissue look (endoscope.py)
            seed = int.from_bytes(organ.name.encode()[:8].ljust(8, b"_"), "little")
            parts = tissue_patches(organ.mesh.vertices, f, organ.color, seed=seed) or parts
        self.handle = server.scene.add_mesh_simple(
            self.name, v, parts[0][0], color=parts[0][1], **organ_style(organ)  # type: ignore[arg-type]  # viser
        )
        self.tones = [server.scene.add_mesh_simple(
            f"{self.name}/tone{i}", v, fi, color=ci, **organ_style(organ))  # type: ignore[arg-type]  # viser
            for i, (fi, ci) in enumerate(parts[1:], start=1)]

    def update(self, vertices: FloatArray) -> None:
        """Moves the vertices (deforming organs).

        Args:
            vertices: (n_vertices, 3) positions [m], world frame; same count as at creation
                (the browser updates its GPU buffer in place).

        Raises:
            ValueError: on a different shape.
        """
        v = np.asarray(vertices, dtype=np.float32)
        if v.shape != (self.n_vertices, 3):
            raise ValueError(
                f"{self.name}: expected vertices of shape ({self.n_vertices}, 3), got {v.shape}"
            )
        self.handle.vertices = v
        for h in self.tones:
            h.vertices = v

    def node_names(self) -> list[str]:
        return [self.name, *(f"{self.name}/tone{i}" for i in range(1, len(self.tones) + 1))]


# ---------------------------------------------------------------------------------------
# Tool


class ToolView:
    """A laparoscopic instrument: a shaft through its trocar ending at the tip, plus a tip
    marker (``/tool/shaft``, ``/tool/tip``).

    The shaft is redrawn by rewriting its vertices (one message per update; a position +
    orientation + scale update would be three, each ~2x dearer in viser).

    Args:
        server: the viser server.
        trocar: (3,) trocar (port) point the shaft passes through [m].
        shaft_radius: [m] (5 mm instruments: 2.5 mm).
        outside: length of shaft drawn beyond the trocar, outside the body [m].
        tip_radius: radius of the tip marker [m] (just over the shaft's: the tip reads as a
            golden end without swallowing the overlay arrows that start there).
        shaft_opacity: the shaft is drawn see-through (**decision**): Mag's camera looks
            down the instrument, and an opaque shaft hid the VG and FF arrows starting at the
            tip behind it.
    """

    def __init__(
        self,
        server: viser.ViserServer,
        trocar: FloatArray,
        *,
        shaft_radius: float = 0.0025,
        outside: float = 0.05,
        tip_radius: float = 0.0026,
        shaft_opacity: float = 0.55,
    ):
        self.trocar = np.asarray(trocar, dtype=np.float64).reshape(3)
        self.outside = float(outside)
        cyl = trimesh.creation.cylinder(radius=shaft_radius, height=1.0, sections=16)
        v = cyl.vertices.copy()
        v[:, 2] += 0.5  # unit shaft from z = 0 (tip) to z = 1 (stretched to length)
        self._template = v
        self.shaft = server.scene.add_mesh_simple(
            "/tool/shaft", self._placed(self.trocar - np.array([0.0, 0.0, 0.05])),
            cyl.faces.astype(np.uint32), color=(150, 155, 165), opacity=shaft_opacity,
            cast_shadow=False,
        )
        self.tip = server.scene.add_icosphere(
            "/tool/tip", radius=tip_radius, color=(255, 200, 40), subdivisions=2,
        )
        self._last: FloatArray | None = None

    def _placed(self, tip: FloatArray) -> NDArray[np.float32]:
        d = self.trocar - tip
        length = float(np.linalg.norm(d)) + self.outside
        local = self._template * np.array([1.0, 1.0, max(length, 1e-4)])
        return (local @ matrix_z_to(d).T + tip).astype(np.float32)

    def set_trocar(self, trocar: FloatArray) -> None:
        """Moves the pivot to another port (3,) [m]; takes effect at the next update."""
        self.trocar = np.asarray(trocar, dtype=np.float64).reshape(3)
        self._last = None

    def update(self, tip: FloatArray) -> None:
        """Places the tool with its tip at ``tip`` (3,) [m]."""
        p = np.asarray(tip, dtype=np.float64)
        if self._last is not None and np.array_equal(p, self._last):
            return
        self._last = p.copy()
        self.shaft.vertices = self._placed(p)
        self.tip.position = p

    def node_names(self) -> list[str]:
        return [self.shaft.name, self.tip.name]


# ---------------------------------------------------------------------------------------
# Trajectory / POIs

PENDING_RGB: Rgb = (255, 225, 90)
GOAL_RGB: Rgb = (60, 230, 110)
REACHED_RGB: Rgb = (130, 130, 130)
PATH_RGB: Rgb = (255, 235, 150)


class TrajectoryView:
    """The POIs as a point cloud and, for a trajectory, a spline through them; the current
    goal is highlighted (a translucent sphere of the reach radius) and reached points are
    greyed. For point targeting, the POI's surface normal is drawn as a short segment.

    A new task updates the existing nodes' properties instead of removing and re-adding
    them: removing a node and re-creating the same name while a browser was connected
    left the old node on screen (observed with viser 1.1.1 on trial changes).

    Args:
        server: the viser server.
        point_size: drawn POI size [m].
        normal_length: length of the drawn surface normal [m].
    """

    def __init__(self, server: viser.ViserServer, *, point_size: float = 0.0018,
                 normal_length: float = 0.03):
        self.server = server
        self.point_size = float(point_size)
        self.normal_length = float(normal_length)
        self.points: FloatArray = np.zeros((0, 3))
        self.cloud: viser.PointCloudHandle | None = None
        self.path: viser.SplineCatmullRomHandle | None = None
        self.normal: viser.LineSegmentsHandle | None = None
        self.goal = server.scene.add_icosphere(
            "/trajectory/goal", radius=1.0, color=GOAL_RGB, opacity=0.35, subdivisions=2,
            cast_shadow=False, receive_shadow=False, visible=False,
        )
        self._goal_index = -1

    def set_task(
        self,
        points: FloatArray,
        reach_radius: float,
        normals: FloatArray | None = None,
    ) -> None:
        """Shows a new task.

        Args:
            points: (N, 3) POIs in visiting order [m].
            reach_radius: radius of the goal sphere [m].
            normals: (N, 3) unit surface normals (point targeting) or None.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        self.points = pts
        colors = np.tile(np.array(PENDING_RGB, dtype=np.uint8), (len(pts), 1))
        scene = self.server.scene
        if self.cloud is None:
            self.cloud = scene.add_point_cloud(
                "/trajectory/points", pts.astype(np.float32), colors,
                point_size=self.point_size, point_shape="circle", precision="float32",
            )
        else:
            self.cloud.points = pts.astype(np.float32)
            self.cloud.colors = colors
        if len(pts) >= 2:
            if self.path is None:
                self.path = scene.add_spline_catmull_rom(
                    "/trajectory/path", pts, curve_type="centripetal", thickness=0.0012,
                    color=PATH_RGB,
                )
            else:
                self.path.points = pts.astype(np.float32)
                self.path.visible = True
        elif self.path is not None:
            self.path.visible = False
        if normals is not None:
            n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
            seg = np.stack([pts, pts + self.normal_length * n], axis=1).astype(np.float32)
            if self.normal is None:
                self.normal = scene.add_line_segments(
                    "/trajectory/normal", seg, (120, 200, 255), thickness=0.0008,
                )
            else:
                self.normal.points = seg
                self.normal.visible = True
        elif self.normal is not None:
            self.normal.visible = False
        self.goal.scale = float(reach_radius)
        self.goal.visible = True
        self._goal_index = -1

    def update(self, goal_index: int) -> None:
        """Highlights POI ``goal_index`` (== N when all are reached) and greys those before."""
        if goal_index == self._goal_index or self.cloud is None:
            return
        self._goal_index = goal_index
        n = len(self.points)
        colors = np.empty((n, 3), dtype=np.uint8)
        colors[:] = PENDING_RGB
        colors[: min(goal_index, n)] = REACHED_RGB
        if goal_index < n:
            colors[goal_index] = GOAL_RGB
            self.goal.position = self.points[goal_index]
            self.goal.visible = True
        else:
            self.goal.visible = False
        self.cloud.colors = colors

    def move(self, points: FloatArray, normals: FloatArray | None = None) -> None:
        """Moves the POIs of the current task (they ride on the breathing tissue).

        Args:
            points: (N, 3) current POI positions [m], same N as the task.
            normals: (N, 3) current unit normals (point targeting) or None.

        Raises:
            ValueError: for a different number of points.
        """
        pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
        if pts.shape != self.points.shape:
            raise ValueError(f"expected {len(self.points)} points, got {len(pts)}")
        self.points = pts
        p32 = pts.astype(np.float32)
        if self.cloud is not None:
            self.cloud.points = p32
        if self.path is not None and self.path.visible:
            self.path.points = p32
        if normals is not None and self.normal is not None and self.normal.visible:
            n = np.asarray(normals, dtype=np.float64).reshape(-1, 3)
            self.normal.points = np.stack([pts, pts + self.normal_length * n],
                                          axis=1).astype(np.float32)
        if 0 <= self._goal_index < len(pts):
            self.goal.position = pts[self._goal_index]

    def node_names(self, *, visible_only: bool = True) -> list[str]:
        """Names of the nodes (by default only those currently shown)."""
        return [h.name for h in (self.cloud, self.path, self.normal, self.goal)
                if h is not None and (h.visible or not visible_only)]


# ---------------------------------------------------------------------------------------
# Arrows


def arrow_mesh(sections: int = 12) -> tuple[FloatArray, NDArray[np.uint32]]:
    """A unit-topology arrow along +z: (V, 3) template vertices and (F, 3) faces.

    Vertex rows: shaft bottom ring, shaft top ring, head base ring, apex, bottom centre,
    head-base centre. :func:`arrow_vertices` moves them; the topology never changes.
    """
    s = sections
    ang = np.linspace(0.0, 2.0 * np.pi, s, endpoint=False)
    ring = np.column_stack([np.cos(ang), np.sin(ang), np.zeros(s)])
    v = np.vstack([ring, ring, ring, [[0, 0, 1]], [[0, 0, 0]], [[0, 0, 0]]])
    apex, bottom, head_c = 3 * s, 3 * s + 1, 3 * s + 2
    j = np.arange(s)
    k = (j + 1) % s
    faces = np.vstack([
        np.column_stack([j, k, s + k]), np.column_stack([j, s + k, s + j]),  # shaft
        np.column_stack([2 * s + j, 2 * s + k, np.full(s, apex)]),  # head cone
        np.column_stack([np.full(s, bottom), k, j]),  # shaft cap
        np.column_stack([np.full(s, head_c), 2 * s + k, 2 * s + j]),  # head base
        np.column_stack([s + j, s + k, 2 * s + k]), np.column_stack([s + j, 2 * s + k, 2 * s + j]),
    ])
    return v, faces.astype(np.uint32)


def arrow_vertices(template: FloatArray, start: FloatArray, end: FloatArray,
                   shaft_radius: float) -> NDArray[np.float32]:
    """World-frame vertices of the arrow from ``start`` to ``end`` (both (3,) [m]).

    The shaft is at most a tenth of the length thick, so a short arrow (VG near the path:
    a few mm) still reads as an arrow instead of a blob; ``shaft_radius`` [m] is the cap.
    """
    s = (len(template) - 3) // 3
    d = np.asarray(end, dtype=np.float64) - np.asarray(start, dtype=np.float64)
    length = float(np.linalg.norm(d))
    shaft_radius = min(float(shaft_radius), 0.1 * length)
    head_r = 2.4 * shaft_radius
    head_l = min(0.45 * length, 7.0 * shaft_radius)
    shaft_l = length - head_l
    local = template.copy()
    local[:s, :2] *= shaft_radius
    local[s:2 * s, :2] *= shaft_radius
    local[s:2 * s, 2] = shaft_l
    local[2 * s:3 * s, :2] *= head_r
    local[2 * s:3 * s, 2] = shaft_l
    local[3 * s, 2] = length
    local[3 * s + 2, 2] = shaft_l
    return (local @ matrix_z_to(d).T + np.asarray(start)).astype(np.float32)


class ArrowView:
    """The overlay arrows of a frame: VG guidance vectors and the FF force arrow.

    A fixed pool of ``slots`` arrow meshes (``/overlays/arrow_<i>``) with constant vertex
    count; an arrow's opacity and width map to the mesh's opacity and shaft radius (viser's
    own ``add_arrows`` has no opacity, and VG fades by opacity). Unused slots and arrows
    that are (almost) transparent or shorter than 0.1 mm are hidden.

    Args:
        server: the viser server.
        slots: maximum number of arrows drawn at once.
        radius_per_px: shaft radius per unit of ``Arrow.width`` [m/px].
        prefix: parent node of the slots.
    """

    MIN_OPACITY = 0.02
    MIN_LENGTH = 1e-4

    def __init__(self, server: viser.ViserServer, *, slots: int = 4,
                 radius_per_px: float = 0.0002, prefix: str = "/overlays"):
        self.radius_per_px = float(radius_per_px)
        self._template, faces = arrow_mesh()
        self.handles = [
            server.scene.add_mesh_simple(
                f"{prefix}/arrow_{i}", self._template.astype(np.float32), faces,
                color=(255, 255, 255), opacity=1.0, cast_shadow=False, receive_shadow=False,
                visible=False,
            )
            for i in range(slots)
        ]
        self._state: list[tuple[Rgb, float] | None] = [None] * slots
        self.kinds: tuple[str, ...] = ()
        """Kinds of the arrows currently visible, slot order."""

    def update(self, arrows: Sequence[Arrow]) -> None:
        """Draws ``arrows`` (extra arrows beyond the pool size are dropped)."""
        kinds = []
        for i, h in enumerate(self.handles):
            a = arrows[i] if i < len(arrows) else None
            show = (
                a is not None
                and a.opacity >= self.MIN_OPACITY
                and float(np.linalg.norm(a.end - a.start)) >= self.MIN_LENGTH
            )
            if not show or a is None:
                if h.visible:
                    h.visible = False
                self._state[i] = None
                continue
            kinds.append(a.kind)
            h.vertices = arrow_vertices(self._template, a.start, a.end,
                                        max(a.width, 0.5) * self.radius_per_px)
            color, opacity = rgb255(a.color), round(min(1.0, float(a.opacity)), 2)
            last = self._state[i]
            if last is None or last[0] != color:
                h.color = color
            if last is None or abs(last[1] - opacity) >= 0.02:
                h.opacity = opacity
            else:
                opacity = last[1]
            self._state[i] = (color, opacity)
            if not h.visible:
                h.visible = True
        self.kinds = tuple(kinds)

    def node_names(self) -> list[str]:
        return [h.name for h in self.handles]


# ---------------------------------------------------------------------------------------
# MS ghost


class GhostView:
    """The MS ghost: a translucent cone whose apex is where the tool tip would be without
    motion scaling, its axis along the tool toward the trocar (``/overlays/ghost``).

    Args:
        server: the viser server.
        trocar: (3,) trocar point of the tool [m].
        radius, height: cone size [m].
    """

    def __init__(self, server: viser.ViserServer, trocar: FloatArray, *,
                 radius: float = 0.004, height: float = 0.014):
        self.trocar = np.asarray(trocar, dtype=np.float64).reshape(3)
        cone = trimesh.creation.cone(radius=radius, height=height, sections=20)
        v = cone.vertices.copy()
        v[:, 2] = height - v[:, 2]  # apex at the origin, base toward +z
        self._template = v
        faces = cone.faces[:, ::-1]  # the mirror flipped the winding
        self.handle = server.scene.add_mesh_simple(
            "/overlays/ghost", v.astype(np.float32), faces.astype(np.uint32),
            color=(120, 220, 255), opacity=0.45, cast_shadow=False, receive_shadow=False,
            visible=False,
        )
        self.position: FloatArray | None = None
        """(3,) where the ghost is drawn [m], None when hidden."""

    def update(self, ghost: FloatArray | None) -> None:
        """Shows the ghost at ``ghost`` (3,) [m]; hides it for None (no MS in the schema)."""
        if ghost is None:
            if self.handle.visible:
                self.handle.visible = False
            self.position = None
            return
        p = np.asarray(ghost, dtype=np.float64)
        if self.position is None or not np.array_equal(p, self.position):
            rot = matrix_z_to(self.trocar - p)
            self.handle.vertices = (self._template @ rot.T + p).astype(np.float32)
            self.position = p.copy()
        if not self.handle.visible:
            self.handle.visible = True

    def node_names(self) -> list[str]:
        return [self.handle.name]


# ---------------------------------------------------------------------------------------
# Camera


class CameraController:
    """Drives every connected browser's camera: the Mag ``CameraView`` when the schema has
    Mag, otherwise a fixed endoscope-like ``default`` pose (applied on connect and once when
    Mag goes away; the user may orbit freely then).

    Writes are rate-limited to ``max_rate_hz`` and skipped when the pose barely moved (the
    browser eases toward each new pose within ~0.3 s anyway).

    Args:
        server: the viser server (only ``get_clients()`` and ``on_client_connect`` are used).
        default: the pose without Mag.
        max_rate_hz: maximum camera writes per second.
        near, far: clipping planes [m] (viser's 1 cm default near plane is too far for
            an abdomen).
        mapper: turns Mag's ``CameraView`` into the pose shown (the trainee's endoscope:
            ``endoscope.scope_from_mag``, Mag within the port's constraint); None: as is.
    """

    def __init__(self, server: viser.ViserServer, default: CameraPose, *,
                 max_rate_hz: float = 10.0, near: float = 0.002, far: float = 3.0,
                 mapper: Callable[[CameraView], CameraPose] | None = None):
        self.server = server
        self.mapper = mapper
        self.default = default
        self.min_interval = 1.0 / max_rate_hz
        self.near, self.far = near, far
        self._target: CameraPose = default
        self._mag = False
        self._sent: dict[int, CameraPose] = {}
        # on_connect runs on viser's callback threads, update on the view thread.
        self._lock = threading.Lock()
        self._last_push = -math.inf
        self.follow = True
        """False: Mag output is ignored and the user orbits freely."""
        self.writes = 0
        """Number of per-client camera writes so far (for tests and stats)."""
        self.failures = 0
        """Per-client camera writes that failed (that client skipped, the others served)."""
        self._failed: set[int] = set()

    def apply_initial(self) -> None:
        """Sets the server's initial camera (what a new page shows before connecting)."""
        ic = self.server.initial_camera
        ic.position = self.default.position
        ic.look_at = self.default.look_at
        ic.up = self.default.up
        ic.fov = self.default.fov
        ic.near = self.near
        ic.far = self.far

    def on_connect(self, client: viser.ClientHandle) -> None:
        """Gives a newly connected client the current target pose."""
        with self._lock:
            self._sent.pop(client.client_id, None)
            client.camera.near = self.near
            client.camera.far = self.far
            self._write(client, self._target)

    def update(self, view: CameraView | None, now: float | None = None) -> None:
        """Follows ``view`` (Mag output) or, for None, falls back to the default pose once."""
        now = time.perf_counter() if now is None else now
        if view is None or not self.follow:
            if self._mag:
                self._mag = False
                self._target = self.default
                self._push_all(force=True)
            return
        self._mag = True
        self._target = (self.mapper(view) if self.mapper is not None
                        else CameraPose.from_view(view))
        if now - self._last_push < self.min_interval:
            return
        self._last_push = now
        self._push_all()

    @property
    def target(self) -> CameraPose:
        """The pose the pages are being given."""
        return self._target

    def retarget(self, default: CameraPose) -> None:
        """A new pose without Mag (e.g. the scope re-aimed at a new trial's task); applied
        at once unless Mag drives the camera."""
        self.default = default
        if not self._mag:
            self._target = default
            self._push_all(force=True)

    def _push_all(self, *, force: bool = False) -> None:
        """Gives every client the target pose. Per-client isolation (issue #30.2): a client
        whose camera cannot be written (its state is bad) is skipped and logged once per
        connection; the others still get theirs."""
        with self._lock:
            clients = self.server.get_clients()
            for cid in list(self._sent):
                if cid not in clients:
                    del self._sent[cid]
            self._failed &= set(clients)
            for client in clients.values():
                last = self._sent.get(client.client_id)
                if force or last is None or not self._target.close_to(last):
                    try:
                        self._write(client, self._target)
                    except Exception as exc:
                        self.failures += 1
                        if client.client_id not in self._failed:
                            self._failed.add(client.client_id)
                            log.warning("camera of client %s not written (skipped): %s: %s",
                                        client.client_id, type(exc).__name__, exc)

    def _write(self, client: viser.ClientHandle, pose: CameraPose) -> None:
        with client.atomic():
            cam = client.camera
            cam.up_direction = pose.up
            cam.position = pose.position
            cam.look_at = pose.look_at  # after position: position moves look_at along
            cam.fov = pose.fov
        self._sent[client.client_id] = pose
        self.writes += 1


__all__ = [
    "ArrowView",
    "CameraController",
    "CameraPose",
    "GhostView",
    "OrganView",
    "SceneView",
    "ToolView",
    "TrajectoryView",
    "arrow_mesh",
    "arrow_vertices",
    "organ_style",
    "rgb255",
    "set_gui_value",
]
