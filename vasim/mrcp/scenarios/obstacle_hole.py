"""Object carried through the hole of a moving obstacle (seed sec. 4.5.1, Fig. 4.22).

Two RX60B on either side of a wall-like obstacle with a square hole; the wall bobs up and
down and the operator carries a bar (two grasp points, one at each end) through the hole
and back, following the hole. A robot's arm cannot follow the bar through the hole: as the
held end nears the wall, the collision risk (CR) of the holder falls and the task goes to
the robot on the other side, which has moved — avoiding the wall and the other robot with
the guidance forces of the action planner — to the end that has come through.

The seed's sequence (sec. 4.5.1, Figs. 4.22-4.26): three transfers at t ≈ 5.5, 11.5 and
15.5 s, the first two decided by CR against the moving obstacle (R0 -> R1, then R1 -> R0:
RSel's ``texec`` is CR's in both phases), the third forced by R0's wrist θ5 reaching its
limit, when R1 takes the bar back and carries it to the end (the run stops at 20.5 s, the
seed's end of R1's availability). Here: the bar goes through the hole, back, and through
again; on the third pass the operator also rolls it about its long axis, which bends R0's
wrist (θ5 toward its 2.01 rad limit, measured by IK: +20° of roll from 1.52 to 1.91 rad)
so RJ, not CR, ends R0's turn while the bar's far end is already through the hole.

**Decision** (the seed gives the times, not the path): the pass speed is 0.5 m per 6 s
(the seed's 6 s between the first two transfers, which both come with the bar in the
same place, straddling the wall), and the operator starts after a 1.3 s hold (while R1
leaves its initial configuration for its grasp point, the seed's high initial
``ttransf``), which puts the first transfer at the seed's 5.5 s; the roll (12°/s from the
third pass's start, up to 30°, which R0 cannot reach) is the seed's unnamed cause of R0's
θ5 limit, chosen because a top grasp's wrist pitch follows the bar's roll one to one.

Geometry: the wall is the plane y = 0 (20 mm thick, 0.7 m wide), the hole 0.26 m wide and
0.24 m high centred 0.12 m above the shoulders; R0 on the -y side, R1 on the +y side, bases
0.9 m apart in x; the bar is 0.40 m long, gripped from above at its ends.
"""

from __future__ import annotations

import numpy as np

from vasim.core.geometry import rot_y
from vasim.mrcp.interfaces import ArmKinematics, FloatArray, ProximityWorld
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

HOLE_Z = 0.12
HOLE_W, HOLE_H = 0.26, 0.24
WALL_W, WALL_H, WALL_T = 0.70, 0.70, 0.02
BOB = 0.02                        # [m] amplitude of the wall's vertical motion
BOB_PERIOD = 8.0                  # [s]
HALF_BAR = 0.20
PALM = 0.04
STANDOFF = 0.06
Y_END = 0.25                      # the bar's centre goes from -Y_END to +Y_END and back
SPEED = 2 * Y_END / 6.0           # [m/s] one pass in 6 s: the seed's 5.5 -> 11.5 s
PASSES = 3
HOLD = 1.3                        # [s] the operator's initial hold
ROLL_RATE = np.radians(12.0)      # [rad/s] roll about the bar's axis on the third pass
ROLL_MAX = np.radians(30.0)       # [rad]
END = 20.5                        # [s] the seed's run length (Fig. 4.26)


def bar_points() -> list[TaskPoint]:
    """The bar's two ends (task frame: the bar along y), gripped from above."""
    rot = gripper_frame(np.array([0.0, 0.0, -1.0]), np.array([0.0, 1.0, 0.0]))
    return [TaskPoint(np.array([0.0, s * HALF_BAR, PALM]), rot,
                      approach=np.array([0.0, 0.0, STANDOFF])) for s in (-1.0, 1.0)]


def wall_height(t: float) -> float:
    """Height of the hole's centre at ``t`` (the moving obstacle)."""
    return HOLE_Z + BOB * np.sin(2 * np.pi * t / BOB_PERIOD)


def bar_y(t: float) -> float:
    """The bar centre's y at ``t``: held at ``-Y_END`` for ``HOLD`` seconds, then back and
    forth between ``-Y_END`` and ``+Y_END``, ``PASSES`` times."""
    span = 2 * Y_END
    s = min(SPEED * max(0.0, t - HOLD), PASSES * span)
    k, r = divmod(s, span)
    return float(-Y_END + r if int(k) % 2 == 0 else Y_END - r) if s < PASSES * span else (
        Y_END if PASSES % 2 else -Y_END)


def bar_roll(t: float) -> float:
    """The bar's roll about its long axis (task y) at ``t`` [rad]: 0 until the last pass
    starts, then ``ROLL_RATE`` up to ``ROLL_MAX``."""
    t3 = HOLD + (PASSES - 1) * 2 * Y_END / SPEED
    return float(min(ROLL_MAX, ROLL_RATE * max(0.0, t - t3)))


def wall_pieces() -> dict[str, tuple[FloatArray, FloatArray]]:
    """The wall as four boxes around the hole: name -> (half extents, centre offset from
    the hole's centre)."""
    side_w = (WALL_W - HOLE_W) / 4
    top_h = (WALL_H - HOLE_H) / 4
    return {
        "wall_left": (np.array([side_w, WALL_T / 2, WALL_H / 2]),
                      np.array([-(HOLE_W / 2 + side_w), 0.0, 0.0])),
        "wall_right": (np.array([side_w, WALL_T / 2, WALL_H / 2]),
                       np.array([HOLE_W / 2 + side_w, 0.0, 0.0])),
        "wall_top": (np.array([HOLE_W / 2, WALL_T / 2, top_h]),
                     np.array([0.0, 0.0, HOLE_H / 2 + top_h])),
        "wall_bottom": (np.array([HOLE_W / 2, WALL_T / 2, top_h]),
                        np.array([0.0, 0.0, -(HOLE_H / 2 + top_h)])),
    }


class ObstacleHole:
    name = "obstacle_hole"
    summary = ("a bar carried three times through the hole of a moving wall by two RX60B, "
               "one on each side: two CR transfers, then R0's wrist θ5 limit (RJ), seed Fig. 4.22")
    duration = END

    def build(self, options: ScenarioOptions) -> Setup:
        from vasim.mrcp.backend import PybulletArm

        st = Station()
        tps = bar_points()
        b0 = base_pose(np.array([-0.45, -0.15, 0.0]), 0.0)
        b1 = base_pose(np.array([0.45, 0.15, 0.0]), np.pi)
        arms: dict[str, ArmKinematics] = {"R0": PybulletArm(st.model, b0, name="R0"),
                                          "R1": PybulletArm(st.model, b1, name="R1")}
        centre0 = np.array([0.0, bar_y(0.0), wall_height(0.0)])
        q0 = grasp_configuration(arms["R0"], centre0 + tps[0].position, tps[0].rotation,
                                 arms["R0"].home, "the bar's -y end")  # type: ignore[attr-defined]  # a PybulletArm
        q1 = arms["R1"].home.copy()                                     # type: ignore[attr-defined]  # a PybulletArm
        st.add_robot("R0", b0, q0)
        st.add_robot("R1", b1, q1)
        pieces = wall_pieces()
        for name, (half, offset) in pieces.items():
            st.add_box(name, half, np.array([0.0, 0.0, wall_height(0.0)]) + offset)

        def on_cycle(t: float, world: ProximityWorld) -> None:
            hole = np.array([0.0, 0.0, wall_height(t)])
            for name, (_, offset) in pieces.items():
                st.set_obstacle_pose(name, hole + offset)

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return np.array([0.0, bar_y(t), wall_height(t)]), rot_y(bar_roll(t))

        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("theta"), IndexSpec("cr"))
        cfg = kernel_config(options.coarse, options.seed, indices)
        return Setup(arms=arms, world=st, task_points=tps, rsel="R0", cutp=0,
                     operator=operator, on_cycle=on_cycle, config=cfg,
                     duration=self.duration, close=st.close)
