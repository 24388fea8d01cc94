"""Multi-revolution faucet (seed sec. 1.2.2, Figs. 1.4-1.5): two RX60B facing each other
turn a three-spoke faucet wheel for several revolutions, alternating, never releasing it.

The faucet returns to its start when nobody holds it, so the task constraint is the
platform's first invariant: some robot always grasps a spoke (a transfer is a grasp by the
receiving robot *before* the giving robot releases). The operator only commands the turning
direction and speed: the task is the wheel's rotation about its (vertical) axis. Each robot
grips a spoke from above; turning winds its flange joint θ6 (±3.05 rad) and swings its
arm around the wheel until a joint limit or the reach ends its useful time, and the other
robot, waiting over another spoke, takes over.

Geometry: bases 0.9 m apart on the x axis (shoulders at z = 0), wheel of radius 0.11 m
centred between them 0.1 m below the shoulders, spokes at 120°; the gripper's TCP 40 mm
above the spoke, waiting 60 mm higher.
"""

from __future__ import annotations

import numpy as np

from vasim.core.geometry import rot_z
from vasim.mrcp.interfaces import ArmKinematics, FloatArray
from vasim.mrcp.kernel import IndexSpec, TaskPoint
from vasim.mrcp.scenarios.base import (
    ScenarioOptions,
    Setup,
    base_pose,
    grasp_configuration,
    gripper_frame,
)
from vasim.mrcp.scenarios.cube_rotation import kernel_config
from vasim.mrcp.scenarios.world import Station

CENTRE = np.array([0.0, 0.0, -0.10])
RADIUS = 0.11
PALM = 0.04
STANDOFF = 0.06
RATE = np.radians(60.0)            # [rad/s] turning speed commanded by the operator
REVOLUTIONS = 2.0


def spoke_points(radius: float = RADIUS, spokes: int = 3) -> list[TaskPoint]:
    """Grasp points over the spoke ends (task frame: the wheel's centre, z its axis); the
    gripper points down, its x axis along the wheel's tangent (the fingers close along the
    spoke's axis direction is immaterial; this roll leaves the RX60B's θ6 mid-range at
    the start: clockwise turning winds θ6 toward +3.05 rad)."""
    out = []
    for k in range(spokes):
        a = 2 * np.pi * k / spokes
        radial = np.array([np.cos(a), np.sin(a), 0.0])
        tangent = np.array([-np.sin(a), np.cos(a), 0.0])
        out.append(TaskPoint(radius * radial + np.array([0.0, 0.0, PALM]),
                             gripper_frame(np.array([0.0, 0.0, -1.0]), tangent),
                             approach=np.array([0.0, 0.0, STANDOFF])))
    return out


def wheel_angle(t: float) -> float:
    """The operator's command: the wheel's angle [rad] at ``t`` (clockwise from above)."""
    return -RATE * min(t, REVOLUTIONS * 2 * np.pi / RATE)


class Faucet:
    name = "faucet"
    summary = ("two RX60B alternate turning a three-spoke faucet for two revolutions; the "
               "faucet is never released (seed sec. 1.2.2)")
    duration = REVOLUTIONS * 2 * np.pi / RATE + 0.5

    def build(self, options: ScenarioOptions) -> Setup:
        from vasim.mrcp.backend import PybulletArm

        st = Station()
        tps = spoke_points()
        b0 = base_pose(np.array([-0.45, 0.0, 0.0]), 0.0)
        b1 = base_pose(np.array([0.45, 0.0, 0.0]), np.pi)
        arms: dict[str, ArmKinematics] = {"R0": PybulletArm(st.model, b0, name="R0"),
                                          "R1": PybulletArm(st.model, b1, name="R1")}
        # R1 holds spoke 0 (on its side, +x); R0 waits over spoke 1.
        q1 = grasp_configuration(arms["R1"], CENTRE + tps[0].position, tps[0].rotation,
                                 arms["R1"].home, "spoke 0")          # type: ignore[attr-defined]  # a PybulletArm
        pre = CENTRE + tps[1].position + tps[1].approach
        q0 = grasp_configuration(arms["R0"], pre, tps[1].rotation,
                                 arms["R0"].home, "over spoke 1")     # type: ignore[attr-defined]  # a PybulletArm
        st.add_robot("R0", b0, q0)
        st.add_robot("R1", b1, q1)
        st.add_box("faucet_body", np.array([0.03, 0.03, 0.15]),
                   CENTRE - np.array([0.0, 0.0, 0.17]))

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return CENTRE.copy(), rot_z(wheel_angle(t))

        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("theta"), IndexSpec("cr"))
        return Setup(arms=arms, world=st, task_points=tps, rsel="R1", cutp=0,
                     operator=operator,
                     config=kernel_config(options.coarse, options.seed, indices),
                     duration=self.duration, close=st.close,
                     notes={"rate_deg_s": float(np.degrees(RATE)),
                            "revolutions": REVOLUTIONS})
