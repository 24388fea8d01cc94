"""The coarse planning step (2 ms) against the full 1 ms step on the same trials and seeds
(vasim/study/power/coarse.py; the 48-trial figures are bench/power.py --validate 8)."""

from __future__ import annotations

import pandas as pd

from vasim.study.power.coarse import (
    MEASURES,
    relative_mean_change,
    trial_measures,
    validation_configs,
)
from vasim.study.power.design import COARSE_DT, COARSE_TOLERANCE, FULL_DT

SAMPLE_TOLERANCE = 0.20
"""Tolerance of this test's 12-trial sample: :data:`COARSE_TOLERANCE` (10 %, met by the
48-trial validation: -2.0 / -3.0 / -7.1 %) plus the sampling noise of a 12-trial mean
(trial-to-trial sd of path deviation ~35 %: ~10 % on a mean of 12, the two steps drawing
different noise from the same seed)."""


def test_coarse_step_keeps_the_per_trial_means() -> None:
    cfgs = validation_configs([0, 1])               # six conditions x 2 seeds, full trials
    full = trial_measures(cfgs, FULL_DT)
    coarse = trial_measures(cfgs, COARSE_DT)
    assert len(full) == len(coarse) == 12
    change = relative_mean_change(full, coarse)
    assert set(change) == set(MEASURES)
    for m, v in change.items():
        assert abs(v) <= SAMPLE_TOLERANCE, (m, v)
    assert COARSE_TOLERANCE < SAMPLE_TOLERANCE
    # the documented bias: the VF-free trials move most (less error at 2 ms), so the
    # coarse step shrinks the fixture effects relative to VF-free
    by = pd.concat([full.assign(step="full"), coarse.assign(step="coarse")])
    rel = by.groupby(["step", by["schema"] == "none"])["path_deviation"].mean()
    vf_free = rel[("coarse", True)] / rel[("full", True)] - 1
    assisted = rel[("coarse", False)] / rel[("full", False)] - 1
    assert vf_free < assisted and vf_free < 0, (vf_free, assisted)
