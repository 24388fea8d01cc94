"""Scripted MRCP scenarios of the seed (issue #7 §3 and §5), one module each, and their registry.

``SCENARIOS`` maps a name to a scenario object (``name``, ``summary``, ``duration``,
``build(options) -> Setup``); :func:`vasim.mrcp.scenarios.runner.run` runs one through the
MRCP kernel; ``vasim mrcp run NAME`` is the command line.
"""

from __future__ import annotations

from vasim.core.config import check_choice
from vasim.mrcp.scenarios.base import Scenario, ScenarioOptions, Setup
from vasim.mrcp.scenarios.cube_rotation import CubeRotation
from vasim.mrcp.scenarios.cube_translation import CubeTranslation
from vasim.mrcp.scenarios.eight_robots import EightRobots
from vasim.mrcp.scenarios.faucet import Faucet
from vasim.mrcp.scenarios.laparoscopic_rings import LaparoscopicRings
from vasim.mrcp.scenarios.obstacle_hole import ObstacleHole
from vasim.mrcp.scenarios.suture_combined import SutureCombined

SCENARIOS: dict[str, Scenario] = {s.name: s for s in (
    CubeRotation(), CubeTranslation(), ObstacleHole(), LaparoscopicRings(), Faucet(),
    EightRobots(), SutureCombined())}


def get_scenario(name: str) -> Scenario:
    """The registered scenario ``name``.

    Raises:
        ConfigError: for an unknown name (the known names are listed).
    """
    return SCENARIOS[check_choice(name, "scenario", sorted(SCENARIOS))]


__all__ = ["SCENARIOS", "Scenario", "ScenarioOptions", "Setup", "get_scenario"]
