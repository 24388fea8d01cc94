"""Cube translation (seed sec. 4.5.2, Fig. 4.28): a cube lying on a table is lifted along a
vertical plane, carried and put back on the table by two RX60B facing each other.

R0 (left) holds the cube by its top face; R1 starts away from it and moves to its best
grasp point. The operator's path (XZ plane, piecewise linear at constant speed) lifts the
cube high, carries it toward R1's side, then back over the middle and down to the table.
Along it the task changes hands for the reasons of the seed's experiment: a joint limit
(R0's wrist θ5 first), dexterity (Θ, as an arm stretches toward the links 2-3 alignment of
the workspace boundary or its wrist nears alignment), collision risk, and — going down —
the table in the predicted path of the side grasp (CR), so the cube is put down by the top
grasp.

Geometry: bases 1.0 m apart on the x axis (shoulders at z = 0), table top 0.05 m below the
shoulders, cube 100 mm; grippers' TCP 40 mm off the faces, waiting 50 mm further out.
"""

from __future__ import annotations

import itertools

import numpy as np

from vasim.mrcp.interfaces import ArmKinematics, FloatArray
from vasim.mrcp.kernel import IndexSpec
from vasim.mrcp.scenarios.base import (
    ScenarioOptions,
    Setup,
    base_pose,
    cube_points,
    grasp_configuration,
)
from vasim.mrcp.scenarios.cube_rotation import kernel_config
from vasim.mrcp.scenarios.world import Station

HALF = 0.05
PALM = 0.04
STANDOFF = 0.05
TABLE_TOP = -0.05
START = np.array([0.0, 0.0, TABLE_TOP + HALF + 0.002])
#: The operator's waypoints [m] (XZ plane) and speed [m/s].
WAYPOINTS = (START, np.array([-0.05, 0.0, 0.40]), np.array([0.10, 0.0, 0.40]),
             np.array([0.0, 0.0, 0.20]), np.array([0.0, 0.0, START[2] + 0.004]))
SPEED = 0.06


def polyline(points: tuple[FloatArray, ...], speed: float, t: float) -> FloatArray:
    """Position at time ``t`` along a polyline walked at constant ``speed`` (then held).

    Example:
        >>> pts = (np.zeros(3), np.array([1.0, 0.0, 0.0]), np.array([1.0, 1.0, 0.0]))
        >>> polyline(pts, 0.5, 3.0).tolist()
        [1.0, 0.5, 0.0]
    """
    s = speed * t
    for a, b in itertools.pairwise(points):
        seg = float(np.linalg.norm(b - a))
        if s <= seg:
            return a + (b - a) * (s / seg if seg > 0 else 0.0)
        s -= seg
    return points[-1].copy()


def path_length(points: tuple[FloatArray, ...]) -> float:
    return float(sum(np.linalg.norm(b - a) for a, b in itertools.pairwise(points)))


class CubeTranslation:
    name = "cube_translation"
    summary = ("a cube lifted from a table and put back by two RX60B: transfers for a joint "
               "limit, the links 2-3 alignment singularity and the table (seed Fig. 4.28)")
    duration = path_length(WAYPOINTS) / SPEED + 1.0

    def build(self, options: ScenarioOptions) -> Setup:
        from vasim.mrcp.backend import PybulletArm

        st = Station()
        tps = cube_points(HALF, PALM, STANDOFF, side_hint=(0.0, 0.0, -1.0))
        b0 = base_pose(np.array([-0.5, 0.0, 0.0]), 0.0)
        b1 = base_pose(np.array([0.5, 0.0, 0.0]), np.pi)
        arms: dict[str, ArmKinematics] = {"R0": PybulletArm(st.model, b0, name="R0"),
                                          "R1": PybulletArm(st.model, b1, name="R1")}
        home0 = arms["R0"].home                                   # type: ignore[attr-defined]  # a PybulletArm
        q0 = grasp_configuration(arms["R0"], START + tps[4].position, tps[4].rotation, home0,
                                 "the cube's top face")
        q1 = arms["R1"].home.copy()                               # type: ignore[attr-defined]  # a PybulletArm
        q1[0] = 0.6                                               # "a random configuration"
        st.add_robot("R0", b0, q0)
        st.add_robot("R1", b1, q1)
        st.add_box("table", np.array([0.30, 0.40, 0.02]),
                   np.array([0.0, 0.0, TABLE_TOP - 0.02]))

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return polyline(WAYPOINTS, SPEED, t), np.eye(3)

        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("theta"), IndexSpec("cr"))
        return Setup(arms=arms, world=st, task_points=tps, rsel="R0", cutp=4,
                     operator=operator,
                     config=kernel_config(options.coarse, options.seed, indices),
                     duration=self.duration, close=st.close)
