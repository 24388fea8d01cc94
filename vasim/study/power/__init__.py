"""Power planning: how many subjects a protocol needs (``vasim study power``).

Many Monte Carlo cohorts of a declared scenario's scripted operator are simulated on Ray, each
analysed with the report's own primary tests, and the share of cohorts in which a test
rejects estimates its power at each subject count N, with its Monte Carlo error.

One job per module: :mod:`~vasim.study.power.design` (the run's design: ``--subjects``
grid, cohort seeds, effect sizes, the coarse step; pure), :mod:`~vasim.study.power.estimate`
(power, Monte Carlo error, intervals; pure), :mod:`~vasim.study.power.cohort` (one cohort
simulated in memory, or into a kept study database, and analysed),
:mod:`~vasim.study.power.driver` (the Ray shell) and :mod:`~vasim.study.power.output`
(CSV, PNG, printed table).
"""

from __future__ import annotations

from vasim.study.power.design import (
    COARSE_DT,
    FULL_DT,
    PowerDesign,
    cohort_seed,
    parse_subjects,
    scaled_effects,
)
from vasim.study.power.estimate import mc_standard_error, power_table

__all__ = ["COARSE_DT", "FULL_DT", "PowerDesign", "cohort_seed", "mc_standard_error",
           "parse_subjects", "power_table", "scaled_effects"]
