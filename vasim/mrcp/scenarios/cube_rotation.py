"""Cube rotation (seed sec. 4.5.2, Fig. 4.27): two RX60B facing each other turn a cube with
six grasp points (one per face) in front of a camera.

R1 (right) holds the +x face, R0 (left) waits. The operator turns the cube about the
vertical axis at a constant rate; R1's wrist pitch θ5 runs toward its upper limit
(2.01 rad, reached after about 100°), RJ falls, ``texec_RJ -> 0`` and NTT -> 1: the task is
handed to R0 before R1 reaches the limit, and R1 then moves toward its best grasp point.
The camera looks at the cube from -y; its view cone is a sensing body (distance only), so
a robot near the face the camera sees scores low on visibility.

Geometry: bases 1.0 m apart on the x axis (shoulders at z = 0), cube (60 mm) centred
between them 50 mm above the shoulders; grippers' TCP 40 mm off the faces, waiting 50 mm
further out.
"""

from __future__ import annotations

import numpy as np

from vasim.core.geometry import rot_z
from vasim.mrcp.interfaces import ArmKinematics, FloatArray
from vasim.mrcp.kernel import IndexSpec, KernelConfig
from vasim.mrcp.planner import PlannerParams
from vasim.mrcp.scenarios.base import (
    ScenarioOptions,
    Setup,
    base_pose,
    cube_points,
    grasp_configuration,
)
from vasim.mrcp.scenarios.world import Station, view_cone_vertices

CENTRE = np.array([0.0, 0.0, 0.05])
HALF = 0.03
PALM = 0.04
STANDOFF = 0.05
CAMERA = np.array([0.0, -0.75, 0.05])
RATE = np.radians(15.0)          # [rad/s] the operator's turning rate


def kernel_config(coarse: bool, seed: int, indices: tuple[IndexSpec, ...]) -> KernelConfig:
    """The kernel parameters the scenarios share.

    **Decision**: the default run has the seed's 18 ms period with every window the
    kernel keeps (predicted points' spacing, the predictor's and texec's sample windows,
    the hand-over's grasp cycles) twice the kernel's defaults in cycles, so that ``coarse``
    — 36 ms period, the kernel's defaults in cycles — spans the same times: the coarse run
    (the tests) is a subsampling of the default one, not a different controller. The
    per-period displacement bound scales with the period (same robot speeds). ``coarse``
    also uses first-order IK steps along the prediction; distances stay at every predicted
    point (with ``distance_points="ends"`` the CR index sees no closing speed, as its impact
    time pairs consecutive points only).
    """
    dt, k = (0.036, 1) if coarse else (0.018, 2)
    return KernelConfig(dt=dt, indices=indices, seed=seed, stride=3 * k, window=12 * k,
                        texec_window=15 * k, texec_min_samples=5 * k, grasp_cycles=2 * k,
                        trajectory_ik="linear" if coarse else "exact",
                        planner=PlannerParams(dr_max=0.3 * dt, rot_max=2.0 * dt))


class CubeRotation:
    name = "cube_rotation"
    summary = ("two RX60B turn a cube (6 grasp points) in front of a camera; the task is "
               "handed over before R1's joint 5 reaches its limit (seed Fig. 4.27)")
    duration = 10.0

    def build(self, options: ScenarioOptions) -> Setup:
        st = Station()
        tps = cube_points(HALF, PALM, STANDOFF)
        b0, b1 = base_pose(np.array([-0.5, 0.0, 0.0]), 0.0), base_pose(
            np.array([0.5, 0.0, 0.0]), np.pi)
        from vasim.mrcp.backend import PybulletArm

        arms: dict[str, ArmKinematics] = {"R0": PybulletArm(st.model, b0, name="R0"),
                                          "R1": PybulletArm(st.model, b1, name="R1")}
        q1 = grasp_configuration(arms["R1"], CENTRE + tps[0].position, tps[0].rotation,
                                 arms["R1"].home, "the +x face")          # type: ignore[attr-defined]  # a PybulletArm
        pre = CENTRE + tps[1].position + tps[1].approach
        q0 = grasp_configuration(arms["R0"], pre, tps[1].rotation,
                                 arms["R0"].home, "the -x pre-grasp")     # type: ignore[attr-defined]  # a PybulletArm
        st.add_robot("R0", b0, q0)
        st.add_robot("R1", b1, q1)
        st.add_sensing_convex("view_cone", view_cone_vertices(CAMERA, CENTRE, HALF * np.sqrt(3)))

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return CENTRE.copy(), rot_z(RATE * t)

        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("theta"),
                   IndexSpec("cr", {"ignore": ("view_cone",)}), IndexSpec("visibility"))
        return Setup(arms=arms, world=st, task_points=tps, rsel="R1", cutp=0,
                     operator=operator, config=kernel_config(options.coarse, options.seed,
                                                             indices),
                     duration=self.duration, close=st.close,
                     notes={"rate_deg_s": float(np.degrees(RATE))})
