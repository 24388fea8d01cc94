"""What each page of the training viewer draws and the trainee's drag input: the scene views
of one page (:class:`SceneViews`), the tool-tip gizmo (:class:`DragInput`) and the fixed
camera poses (split from :mod:`vasim.viewer.app`, which re-exports them)."""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser
from numpy.typing import NDArray

from vasim.abdomen.anatomy import TROCAR_NAMES, Organ
from vasim.fixtures.mag import MagParams
from vasim.haptics.device import BUTTON_2
from vasim.trials.vf import TrialFrame, tool_trocar
from vasim.viewer.state import TrialInfo
from vasim.viewer.views import (
    ArrowView,
    CameraPose,
    GhostView,
    OrganView,
    ToolView,
    TrajectoryView,
)

FloatArray = NDArray[np.float64]


def endoscope_pose(look_at: tuple[float, float, float] = (0.0, 0.02, 0.085),
                   distance: float = 0.16) -> CameraPose:
    """The fixed camera without Mag: Mag's own zoom-1 navigation view (a laparoscope through
    the umbilical port, from above and caudal: ``MagParams.view_dir`` and ``fov_deg``)
    aimed between the trajectory workspace and the organs below it, so that switching Mag on
    or off does not swing the view around. From 16 cm (Mag's zoom-1 distance is 15 cm) the
    whole workspace box stays within 30 deg of the view axis (the half fov is 35 deg).

    Args:
        look_at: (3,) point aimed at [m], world frame.
        distance: camera distance from ``look_at`` [m].
    """
    mag = MagParams()
    w = np.asarray(mag.view_dir, dtype=np.float64)
    w /= np.linalg.norm(w)
    target = np.asarray(look_at, dtype=np.float64)
    return CameraPose(position=target + float(distance) * w, look_at=target,
                      up=np.array([0.0, 0.0, 1.0]), fov=float(np.radians(mag.fov_deg)))


class DragInput:
    """The tool-tip gizmo (``/input/tip``): browser input for browser-driven trials.

    Dragging pushes ``(t, position)`` samples into the running trial's ``BrowserDevice``
    (the device interpolates them for the 1 kHz loop and the trial moves the tool by the
    master's increments). On release the gizmo snaps back onto the tool tip: two clutched
    samples (``BUTTON_2``, the servo loop's clutch) — one where the hand let go, one at the
    tip — re-index the master, so the snap never moves the tool (**decision**).

    Args:
        server: the viser server.
        device: returns the current trial's ``BrowserDevice`` (or None).
        guard: wraps the callback.
        name: the gizmo's scene node.
    """

    def __init__(self, server: viser.ViserServer, device: Callable[[], Any],
                 guard: Callable[[Callable[..., Any]], Callable[..., Any]], *,
                 name: str = "/input/tip"):
        self.handle = server.scene.add_transform_controls(
            name, scale=0.03, disable_rotations=True, depth_test=False,
            visible=False)
        self._device = device
        self._dragging = False
        self.samples = 0
        self._last_tip: FloatArray | None = None
        self.handle.on_update(guard(self._on_update))

    def _on_update(self, event: Any) -> None:
        dev = self._device()
        if dev is None:
            return
        phase = getattr(event, "phase", "update")
        p = np.asarray(self.handle.position, dtype=np.float64)
        t = time.perf_counter()
        if phase == "end":
            dev.push(t, p)
            self.samples += 1
            self._dragging = False
            tip = self._last_tip
            if tip is not None:
                dev.push(t + 1e-4, p, BUTTON_2)
                dev.push(t + 2e-4, tip, BUTTON_2)
                self.handle.position = np.array(tip, dtype=np.float64)
            return
        self._dragging = True
        dev.push(t, p)
        self.samples += 1

    def update(self, tip: FloatArray, active: bool) -> None:
        """Shows the gizmo for a browser-driven trial; parks it on the tip when not held."""
        self._last_tip = np.asarray(tip, dtype=np.float64)
        if self.handle.visible != active:
            self.handle.visible = active
            if active:
                self.handle.position = np.array(tip, dtype=np.float64)
                dev = self._device()
                if dev is not None:  # the first sample: where the gizmo starts
                    dev.push(time.perf_counter(), self._last_tip)


class SceneViews:
    """What one page draws of the training scene: the organs, the ports, the instrument,
    the task, the fixtures' arrows and the MS ghost. Each page (trainee, experimenter) has
    its own, on its own server; both are fed the same frames by the view thread.

    Args:
        server: the page's viser server.
        organs: the organs to draw. trocars: (4, 3) port positions [m].
        trocar: the instrument's port of the first trial.
    """

    def __init__(self, server: viser.ViserServer, organs: list[Organ], trocars: FloatArray,
                 trocar: FloatArray, *, tones: bool = False):
        server.scene.set_up_direction("+z")
        self.server = server
        self.organs = [OrganView(server, o, tones=tones) for o in organs]
        ports = trocars[[i for i, n in enumerate(TROCAR_NAMES) if n != "camera"]]
        server.scene.add_point_cloud("/trocars", ports.astype(np.float32), (40, 40, 40),
                                     point_size=0.004, point_shape="circle",
                                     precision="float32")
        self.tool = ToolView(server, trocar)
        self.trajectory = TrajectoryView(server)
        self.arrows = ArrowView(server)
        self.ghost = GhostView(server, trocar)
        self._shown_physics = -1

    def show_trial(self, info: TrialInfo) -> None:
        """A new trial: its task, and the instrument through its port."""
        self.trajectory.set_task(info.points, info.reach_radius, info.normals)
        trocar = tool_trocar(info.config.task, info.start)
        self.tool.set_trocar(trocar)
        self.ghost.trocar = trocar

    def show_physics(self, info: TrialInfo, frame: TrialFrame) -> None:
        """Deforming, breathing organs and the POIs riding on them (one physics step)."""
        snap = frame.abdomen
        if snap is None or snap.seq == self._shown_physics:
            return
        self._shown_physics = snap.seq
        for view in self.organs:
            try:
                view.update(snap.organ(view.organ.name).surface)
            except (KeyError, ValueError):  # an organ this scene does not simulate
                continue
        if len(snap.targets) == len(info.points):
            self.trajectory.move(snap.targets, snap.target_normals
                                 if frame.n_points == 1 else None)

    def update(self, info: TrialInfo, frame: TrialFrame, *, new_trial: bool,
               scene: bool = True) -> None:
        """Every view from one frame (call inside the server's ``atomic()``).

        Args:
            scene: False: this frame leaves out what the trainee does not steer (the organs
                and the points riding on them; ``flow.ScenePacer`` decides, issue #26.2);
                a new trial always carries it.
        """
        if new_trial:
            self.show_trial(info)
        if scene or new_trial:
            self.show_physics(info, frame)
        out = frame.outputs
        self.tool.update(frame.tcp)
        self.trajectory.update(frame.goal_index)
        self.arrows.update(out.arrows)
        self.ghost.update(out.ghost)

    def node_names(self) -> list[str]:
        names: list[str] = []
        views: list[Any] = [*self.organs, self.tool, self.trajectory, self.arrows, self.ghost]
        for v in views:
            names.extend(v.node_names())
        return sorted(names)


def third_person_pose() -> CameraPose:
    """The experimenter's camera: the whole abdomen from above, cranial-left, wide angle."""
    look_at = np.array([0.0, 0.02, 0.05])
    return CameraPose(position=look_at + np.array([0.28, -0.30, 0.32]), look_at=look_at,
                      up=np.array([0.0, 0.0, 1.0]), fov=float(np.radians(55.0)))


__all__ = ["DragInput", "SceneViews", "endoscope_pose", "third_person_pose"]
