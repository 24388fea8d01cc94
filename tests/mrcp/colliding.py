"""A scenario that ends in a safety stop: ``cube_rotation`` with a ball put in the way of
RSel's hand after 0.3 s (for the runner, the CLI and the browser panel, issue #26 §4)."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from vasim.mrcp.kernel import IndexSpec
from vasim.mrcp.scenarios import get_scenario
from vasim.mrcp.scenarios.base import ScenarioOptions, rot_z

DROP_T = 0.3


class CollidingScenario:
    name = "colliding_cube"
    summary = "cube_rotation with a ball in the way of the holder's hand"
    duration = 3.0

    def build(self, options: ScenarioOptions) -> Any:
        setup = get_scenario("cube_rotation").build(options)
        world = setup.world
        world.add_sphere("ball", 0.015, np.array([2.0, 2.0, 2.0]))
        rsel = setup.rsel
        tcp0, _ = setup.arms[rsel].tcp_pose(world.configuration(rsel))
        centre, _ = setup.operator(0.0)
        far = np.array([2.0, 2.0, 2.0])
        for deg in range(10, 120, 5):     # the first place ahead that is 8 mm clear of RSel
            ahead = centre + rot_z(np.radians(deg)) @ (tcp0 - centre)
            world.set_obstacle_pose("ball", ahead)
            if world.min_distance(rsel, "ball", 0.1).distance > 0.008:
                break
        world.set_obstacle_pose("ball", far)

        def on_cycle(t: float, w: Any) -> None:
            if t >= DROP_T:       # put where the turning cube takes RSel's hand next
                w.set_obstacle_pose("ball", ahead)

        # Without the collision index (CR) the kernel does not see the ball coming and hand
        # the task over: RSel's next step is refused and the kernel stops.
        config = replace(setup.config, indices=(IndexSpec("rj"),))
        return replace(setup, on_cycle=on_cycle, duration=self.duration, config=config)
