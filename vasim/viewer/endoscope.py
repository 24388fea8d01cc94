"""The trainee's view is the endoscope's (issue #19 §1): a scope entering through the camera
trocar on the abdominal wall, 0 deg or 30 deg optics, a light at its tip, dark surroundings
and tissue with per-organ colour variation.

Geometry (world frame, metres, ``z`` up). The scope's shaft passes through its port
(the fulcrum); its tip (the camera) is ``insertion`` along the shaft. With 0 deg optics the
camera looks along the shaft; with ``optics_deg`` > 0 its view axis is tilted that angle
from the shaft, away from the shaft's "up" side (a 30 deg scope is held with its light post
up, looking down-forward). :func:`scope_pose` aims the view axis exactly at a target point by
tilting the shaft (a 1-D root in the plane of the port, the target and the world's up).

Mag acts on this endoscope, not on a free camera (:func:`scope_from_mag`): the Mag fixture's
``CameraView`` names what to look at (``look_at``), how far from it (its distance) and its
field of view (optical zoom); the scope aims at ``look_at`` from its port and moves in or
out along its shaft to Mag's distance, clipped to the port's travel
(``min_insertion_m`` .. the target less ``min_clearance_m``).

Look: viser 1.1 has one colour per ``add_mesh_simple`` mesh and no roughness control, so
tissue variation is procedural patches (:func:`tissue_patches`: the faces split by a smooth
noise field over the surface into three tones of the organ's colour, each tone its own mesh
on the same deforming vertices) and the moist sheen is the standard material's specular
response to the spot light at the scope tip. Nothing is downloaded.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import viser
from numpy.typing import NDArray
from scipy import optimize

from vasim.core.config import check_choice
from vasim.fixtures.types import CameraView
from vasim.viewer.camera_pose import CameraPose
from vasim.viewer.lighting import no_environment_map

FloatArray = NDArray[np.float64]

OPTICS_DEG: tuple[float, ...] = (0.0, 30.0)
"""The scope optics a scene may choose (deg from the shaft axis)."""

SCOPE_FOV_DEG = 75.0
"""Vertical field of view of the scope at zoom 1 [deg] (**decision**: a wide-angle
laparoscope; with the page's ~1.6 aspect ~100 deg horizontally, so that every trajectory
variant and the tool's start are in view from the umbilical port)."""


@dataclass(frozen=True)
class Scope:
    """The endoscope: its port and optics.

    Attributes:
        port: (3,) the camera trocar [m]. optics_deg: 0 or 30 [deg].
        fov_deg: vertical field of view at zoom 1 [deg].
        min_insertion_m: the least insertion past the port (the tip inside the wall) [m].
        min_clearance_m: the least distance kept from the target [m].
    """

    port: FloatArray
    optics_deg: float = 0.0
    fov_deg: float = SCOPE_FOV_DEG
    min_insertion_m: float = 0.01
    min_clearance_m: float = 0.02

    def __post_init__(self) -> None:
        check_choice(self.optics_deg, "optics", OPTICS_DEG)


def _unit(v: FloatArray) -> FloatArray:
    return v / float(np.linalg.norm(v))


def scope_pose(scope: Scope, target: FloatArray, insertion: float,
               fov: float | None = None) -> tuple[CameraPose, FloatArray]:
    """The camera at the tip of the scope aimed at ``target``.

    Args:
        scope: the endoscope. target: (3,) point to look at [m].
        insertion: tip distance past the port along the shaft [m] (clipped to the port's
            travel, see the module docstring).
        fov: vertical field of view [rad] (default the scope's).

    Returns:
        (pose, shaft): the camera pose (its ``position`` is the tip, ``look_at`` the target)
        and the shaft's unit direction from the port into the body.
    """
    port = np.asarray(scope.port, dtype=np.float64)
    target = np.asarray(target, dtype=np.float64)
    to_target = target - port
    dist = float(np.linalg.norm(to_target))
    u = to_target / dist
    up_world = np.array([0.0, 0.0, 1.0])
    w = up_world - float(up_world @ u) * u
    w = _unit(w) if np.linalg.norm(w) > 1e-9 else _unit(np.cross(u, [1.0, 0.0, 0.0]))
    hi = max(dist - scope.min_clearance_m, scope.min_insertion_m)
    ins = float(np.clip(insertion, scope.min_insertion_m, hi))
    alpha = math.radians(scope.optics_deg)

    def shaft_of(beta: float) -> FloatArray:
        return math.cos(beta) * u + math.sin(beta) * w

    if alpha > 0.0:
        def gap(beta: float) -> float:   # angle(shaft, target - tip) - alpha
            s = shaft_of(beta)
            d = _unit(target - (port + ins * s))
            return math.acos(float(np.clip(s @ d, -1.0, 1.0))) - alpha

        beta = float(optimize.brentq(gap, 0.0, alpha, xtol=1e-12))
    else:
        beta = 0.0
    shaft = shaft_of(beta)
    tip = port + ins * shaft
    view = _unit(target - tip)
    # Image up: the world's up, made perpendicular to the view axis.
    cam_up = _unit(up_world - float(up_world @ view) * view)
    f = math.radians(scope.fov_deg) if fov is None else float(fov)
    return CameraPose(position=tip, look_at=target, up=cam_up, fov=f), shaft


def scope_from_mag(scope: Scope, view: CameraView) -> CameraPose:
    """Mag's camera view as the scope can give it (module docstring): aimed at Mag's
    ``look_at`` from the port, at Mag's distance where the port's travel allows, with Mag's
    field of view scaled to the scope's (Mag's zoom is optical zoom then)."""
    look_at = np.asarray(view.look_at, dtype=np.float64)
    mag_dist = float(np.linalg.norm(np.asarray(view.position, dtype=np.float64) - look_at))
    reach = float(np.linalg.norm(look_at - np.asarray(scope.port, dtype=np.float64)))
    from vasim.fixtures.mag import MagParams

    zoom_fov = float(view.fov) * scope.fov_deg / MagParams().fov_deg
    pose, _ = scope_pose(scope, look_at, reach - mag_dist, fov=zoom_fov)
    return pose


def task_target(points: FloatArray, start: FloatArray) -> FloatArray:
    """Where the scope aims during a trial: the centre of the bounding box of the task's
    points and the tool's start."""
    p = np.vstack([np.asarray(points, dtype=np.float64), np.asarray(start, dtype=np.float64)])
    return (p.min(axis=0) + p.max(axis=0)) / 2.0


def in_frustum(pose: CameraPose, points: FloatArray, aspect: float) -> NDArray[np.bool_]:
    """Which points lie inside the camera's view frustum (vertical ``fov``, ``aspect`` =
    width / height)."""
    fwd = _unit(np.asarray(pose.look_at) - np.asarray(pose.position))
    right = _unit(np.cross(fwd, pose.up))
    up = np.cross(right, fwd)
    d = np.asarray(points, dtype=np.float64) - pose.position
    z = d @ fwd
    th = math.tan(pose.fov / 2.0)
    return (z > 0) & (np.abs(d @ up) <= th * z) & (np.abs(d @ right) <= th * aspect * z)


# ---------------------------------------------------------------------------------------
# Tissue look


def tissue_patches(vertices: FloatArray, faces: NDArray[np.integer], color: tuple[float, ...],
                   *, seed: int = 0, scale_m: float = 0.012,
                   ) -> list[tuple[NDArray[np.uint32], tuple[int, int, int]]]:
    """Splits an organ's faces into three tones of its colour by a smooth noise field.

    Args:
        vertices: (n, 3) [m]. faces: (m, 3). color: RGB in [0, 1].
        seed: the noise's seed (per organ: its name's hash). scale_m: patch size [m].

    Returns:
        [(faces of the tone, RGB 0-255)] for the tones that have faces: the base colour, a
        darker and redder one (vessels, congestion) and a lighter one (serosa sheen).
    """
    rng = np.random.default_rng(seed)
    c = np.asarray(vertices, dtype=np.float64)[np.asarray(faces)].mean(axis=1)
    k = rng.normal(size=(4, 3)) / scale_m
    phase = rng.uniform(0, 2 * np.pi, size=4)
    noise = np.sin(c @ k.T + phase).sum(axis=1) / 4.0    # smooth, in [-1, 1]
    base = np.asarray(color, dtype=np.float64)
    tones = (base, np.clip(base * np.array([0.86, 0.72, 0.72]), 0, 1),
             np.clip(base * 1.15 + 0.04, 0, 1))
    which = np.where(noise < -0.25, 1, np.where(noise > 0.3, 2, 0))
    out = []
    for i, tone in enumerate(tones):
        sel = np.asarray(faces, dtype=np.uint32)[which == i]
        if len(sel):
            out.append((sel, tuple(round(float(x) * 255) for x in tone)))
    return out  # type: ignore[return-value]  # RGB triples of 3 ints


class ScopeLight:
    """The trainee page's lighting: the default lights and viser's environment map off, a
    dim ambient light, a spot light at the scope tip along its view axis, and a near-black
    background.

    **decision** (issue #26.2, measured): no environment map (:mod:`vasim.viewer.lighting`:
    it cost Chromium's GPU process 3,940 ms of CPU per full-resolution frame against 556 ms
    without it); the ambient light is raised from 0.12 to 0.3 so the tissue outside the
    spot's cone stays readable without the map's fill.
    """

    def __init__(self, server: viser.ViserServer, *, intensity: float = 2.5,
                 ambient: float = 0.3):
        server.scene.configure_default_lights(False)
        no_environment_map(server)
        server.scene.set_background_image(np.full((4, 4, 3), 6, dtype=np.uint8))
        self.ambient = server.scene.add_light_ambient("/endoscope/ambient",
                                                      color=(255, 236, 224),
                                                      intensity=ambient)
        self.spot = server.scene.add_light_spot(
            "/endoscope/light", color=(255, 248, 236), intensity=intensity,
            angle=math.radians(50.0), penumbra=0.6, decay=0.0, distance=0.0,
            direction=(0.0, 0.0, 1.0))
        self.pose: CameraPose | None = None

    def follow(self, pose: CameraPose) -> None:
        """Puts the light at the scope tip, shining along its view axis (+z of the node)."""
        from vasim.core.geometry import quat_z_to

        self.pose = pose
        self.spot.position = np.asarray(pose.position, dtype=np.float64)
        self.spot.wxyz = quat_z_to(np.asarray(pose.look_at) - np.asarray(pose.position))


__all__ = ["OPTICS_DEG", "SCOPE_FOV_DEG", "Scope", "ScopeLight", "in_frustum",
           "scope_from_mag", "scope_pose", "task_target", "tissue_patches"]
