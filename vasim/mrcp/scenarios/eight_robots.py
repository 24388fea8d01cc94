"""Eight RX60B around one cube (issue #17 §4-5): the cube-rotation task of seed Fig. 4.27
with the slave station scaled to eight robots, the load the real-time budget is measured
on (``bench/mrcp.py``) and an 8-robot scene for the browser's MRCP panel
(``vasim serve --scene mrcp:eight_robots``).

Not a seed experiment: **Decision** (set-up, no seed figure to follow): the bases stand on
a 0.5 m circle about the cube, each facing it; R0 (on +x) holds the +x face, the other
seven wait with their TCPs on a 0.28 m circle 0.1 m above the cube (position-only IK),
where no two arms touch. The operator turns the cube about the vertical at 15°/s, as in
``cube_rotation``: R0's wrist runs toward its limit and the task goes to another robot.
"""

from __future__ import annotations

import numpy as np

from vasim.mrcp.interfaces import ArmKinematics, FloatArray
from vasim.mrcp.kernel import IndexSpec
from vasim.mrcp.scenarios.base import (
    ScenarioOptions,
    Setup,
    base_pose,
    cube_points,
    grasp_configuration,
    rot_z,
)
from vasim.mrcp.scenarios.cube_rotation import HALF, PALM, RATE, STANDOFF, kernel_config
from vasim.mrcp.scenarios.world import Station

CENTRE = np.array([0.0, 0.0, 0.05])
ROBOTS = 8
BASE_RADIUS = 0.5          # [m] the bases' circle about the cube (cube_rotation's distance)
WAIT_RADIUS = 0.28         # [m] the waiting TCPs' circle
WAIT_HEIGHT = 0.1          # [m] above the cube's centre


class EightRobots:
    name = "eight_robots"
    summary = ("eight RX60B around a cube turned at 15°/s (the cube-rotation task on an "
               "8-robot station; the real-time load of issue #17, not a seed figure)")
    duration = 10.0

    def build(self, options: ScenarioOptions) -> Setup:
        st = Station()
        tps = cube_points(HALF, PALM, STANDOFF)
        from vasim.mrcp.backend import PybulletArm

        arms: dict[str, ArmKinematics] = {}
        for i in range(ROBOTS):
            a = 2 * np.pi * i / ROBOTS
            u = np.array([np.cos(a), np.sin(a), 0.0])
            base = base_pose(CENTRE * [1, 1, 0] + BASE_RADIUS * u, a + np.pi)
            name = f"R{i}"
            arm = PybulletArm(st.model, base, name=name)
            if i == 0:
                q = grasp_configuration(arm, CENTRE + tps[0].position, tps[0].rotation,
                                        arm.home, "the +x face")
            else:
                wait = CENTRE + WAIT_RADIUS * u + np.array([0.0, 0.0, WAIT_HEIGHT])
                q = grasp_configuration(arm, wait, None, arm.home, f"{name}'s waiting pose")
            st.add_robot(name, base, q)
            arms[name] = arm

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return CENTRE.copy(), rot_z(RATE * t)

        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("theta"), IndexSpec("cr"))
        return Setup(arms=arms, world=st, task_points=tps, rsel="R0", cutp=0,
                     operator=operator, config=kernel_config(options.coarse, options.seed,
                                                             indices),
                     duration=self.duration, close=st.close,
                     notes={"rate_deg_s": float(np.degrees(RATE)), "robots": ROBOTS})
