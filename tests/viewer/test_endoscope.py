"""The endoscope's view (issue #19 §1): a scope through the camera trocar, 0 and 30 deg
optics, Mag acting on it within the port's travel, every task in view, procedural tissue."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from vasim.abdomen.anatomy import TROCAR_NAMES, trocar_points
from vasim.core.errors import ConfigError
from vasim.fixtures.types import CameraView
from vasim.tasks import TRAJECTORY_VARIANTS
from vasim.trials.vf import TrialConfig, make_task
from vasim.viewer.endoscope import (
    Scope,
    in_frustum,
    scope_from_mag,
    scope_pose,
    task_target,
    tissue_patches,
)

PORT = trocar_points()[TROCAR_NAMES.index("camera")]


def angle(a: np.ndarray, b: np.ndarray) -> float:
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    return math.degrees(math.acos(float(np.clip(a @ b, -1, 1))))


def test_zero_degree_optics_look_along_the_shaft_from_inside_the_port() -> None:
    target = np.array([0.0, 0.02, 0.085])
    pose, shaft = scope_pose(Scope(PORT), target, 0.03)
    np.testing.assert_allclose(pose.position, PORT + 0.03 * shaft, atol=1e-15)
    assert angle(shaft, target - PORT) < 1e-6 and angle(pose.look_at - pose.position,
                                                          shaft) < 1e-6
    assert math.degrees(pose.fov) == pytest.approx(75.0)
    assert abs(float(pose.up @ (pose.look_at - pose.position))) < 1e-12


@settings(max_examples=60, deadline=None)
@given(x=st.floats(-0.06, 0.06), y=st.floats(-0.02, 0.1), z=st.floats(0.03, 0.11),
       ins=st.floats(0.0, 0.2))
def test_thirty_degree_optics_see_the_target_thirty_degrees_off_the_shaft(
        x: float, y: float, z: float, ins: float) -> None:
    target = np.array([x, y, z])
    scope = Scope(PORT, optics_deg=30.0)
    pose, shaft = scope_pose(scope, target, ins)
    reach = float(np.linalg.norm(target - PORT))
    depth = float(np.linalg.norm(pose.position - PORT))
    # The tip is on the shaft, within the port's travel; the view axis is 30 deg off it.
    np.testing.assert_allclose(pose.position, PORT + depth * shaft, atol=1e-12)
    assert scope.min_insertion_m - 1e-12 <= depth <= max(reach - scope.min_clearance_m,
                                                          scope.min_insertion_m) + 1e-12
    assert angle(shaft, pose.look_at - pose.position) == pytest.approx(30.0, abs=1e-6)
    np.testing.assert_array_equal(pose.look_at, target)


def test_unknown_optics_are_refused_naming_the_field() -> None:
    with pytest.raises(ConfigError, match="45") as exc:
        Scope(PORT, optics_deg=45.0)
    assert exc.value.field == "optics"


def test_mag_moves_the_scope_along_its_shaft_and_zooms_optically() -> None:
    scope = Scope(PORT)
    look = np.array([0.0, 0.03, 0.09])
    u = (look - PORT) / np.linalg.norm(look - PORT)
    for dist, fov_deg in ((0.04, 35.0), (0.06, 70.0)):
        view = CameraView(position=look + dist * np.array([0.0, -0.6, 0.8]), look_at=look,
                          up=np.array([0.0, 1.0, 0.0]), fov=math.radians(fov_deg), zoom=1.0)
        pose = scope_from_mag(scope, view)
        # Same distance to what Mag looks at, but from the port's line, not Mag's free pose.
        assert np.linalg.norm(look - pose.position) == pytest.approx(dist, abs=1e-12)
        assert angle(pose.position - PORT, u) < 1e-5   # acos near 0: ~1e-6 deg of rounding
        assert math.degrees(pose.fov) == pytest.approx(fov_deg * 75.0 / 70.0)
    # Mag asks for a view from farther away than the port allows: the tip stays inside.
    far = CameraView(position=look + 0.5 * u * -1, look_at=look, up=np.array([0, 1.0, 0]),
                     fov=math.radians(70.0), zoom=1.0)
    pose = scope_from_mag(scope, far)
    assert np.linalg.norm(pose.position - PORT) == pytest.approx(scope.min_insertion_m)


@pytest.mark.parametrize("optics", [0.0, 30.0])
def test_every_task_and_the_tool_start_are_in_the_scopes_view(optics: float) -> None:
    configs = [TrialConfig(task="trajectory", variant=v, schema="vg")
               for v in range(TRAJECTORY_VARIANTS)]
    configs.append(TrialConfig(task="point", schema="point_targeting"))
    for cfg in configs:
        task = make_task(cfg)
        pts = np.vstack([task.points, task.start])
        pose, _ = scope_pose(Scope(PORT, optics_deg=optics), task_target(task.points,
                                                                         task.start), 0.01)
        inside = in_frustum(pose, pts, aspect=820 / 520)
        assert inside.all(), (cfg.task, cfg.variant, np.flatnonzero(~inside))


def test_tissue_patches_cover_every_face_once_in_three_tones() -> None:
    import trimesh

    mesh = trimesh.creation.icosphere(subdivisions=3, radius=0.05)
    patches = tissue_patches(mesh.vertices, mesh.faces, (0.55, 0.2, 0.18), seed=3)
    faces = np.vstack([f for f, _ in patches])
    assert len(faces) == len(mesh.faces)
    assert len({tuple(r) for r in faces.tolist()}) == len(mesh.faces)
    colors = [c for _, c in patches]
    assert len(colors) == 3 and len(set(colors)) == 3 and colors[0] == (140, 51, 46)
    assert all(len(f) > len(mesh.faces) // 10 for f, _ in patches)   # real patches
