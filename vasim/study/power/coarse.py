"""Validation of the coarse planning step (``--coarse``, :data:`~vasim.study.power.design.
COARSE_DT`): the same trials (same configurations and seeds) at the full and the coarse
control step, and the relative change of each per-trial measure's mean.

The measures are the report's per-trial outcomes: cumulative error Σe_i (eq. 6.5),
*rate-normalised* (× dt / 1 ms: e_i sums over samples, so a 2 ms step halves it; the
RM-ANOVA is invariant to that common factor), latency Σl_i over reached points [s] and the
mean path deviation [mm].
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import numpy as np
import pandas as pd

from vasim.records.trial_metrics import MetricParams
from vasim.study.cohort import simulate_trial
from vasim.study.power.design import COARSE_DT, FULL_DT
from vasim.trials.vf import TrialConfig

MEASURES: tuple[str, ...] = ("cum_error_norm", "latency", "path_deviation")
"""Columns of :func:`trial_measures` compared between the steps."""
VALIDATION_SCHEMAS: tuple[str, ...] = ("none", "vg_seed", "ag_seed", "ms", "mag", "ff")
"""The VF study's six conditions as they run (VG and AG as in the seed's study)."""


def trial_measures(configs: Sequence[TrialConfig], dt: float,
                   params: MetricParams | None = None) -> pd.DataFrame:
    """Runs each configuration at control step ``dt`` and returns its measures.

    Returns:
        One row per configuration: ``schema, seed, dt, cum_error_norm`` (Σe_i × dt / 1 ms)
        [m], ``latency`` (Σl_i over reached points) [s], ``path_deviation`` [mm].
    """
    rows = []
    for cfg in configs:
        out = simulate_trial(replace(cfg, dt=dt), params or MetricParams())
        m = out["metrics"]
        reached = m["reached"].astype(bool).to_numpy()
        rows.append({"schema": cfg.schema, "seed": cfg.seed, "dt": dt,
                     "cum_error_norm": float(m["error_l1"].sum()) * dt / FULL_DT,
                     "latency": float(m.loc[reached, "latency"].sum()),
                     "path_deviation": float(out["trial_metrics"]["path_dev_mean_mm"])})
    return pd.DataFrame(rows)


def validation_configs(seeds: Sequence[int], schemas: Sequence[str] = VALIDATION_SCHEMAS,
                       *, practice: int = 5) -> list[TrialConfig]:
    """The validation's trials: every schema x seed, variant = seed mod 7, a subject with
    ``practice`` earlier trials (the VF study's first block)."""
    return [TrialConfig(schema=s, seed=int(seed), variant=int(seed) % 7, practice=practice,
                        subject="VAL1") for s in schemas for seed in seeds]


def relative_mean_change(full: pd.DataFrame, coarse: pd.DataFrame) -> dict[str, float]:
    """``mean(coarse) / mean(full) - 1`` of each measure (:data:`MEASURES`).

    Example:
        >>> f = pd.DataFrame({m: [1.0, 3.0] for m in MEASURES})
        >>> c = pd.DataFrame({m: [1.0, 2.6] for m in MEASURES})
        >>> {k: round(v, 3) for k, v in relative_mean_change(f, c).items()}["latency"]
        -0.1
    """
    return {m: float(np.mean(coarse[m]) / np.mean(full[m]) - 1.0) for m in MEASURES}


def validate_coarse(seeds: Sequence[int], schemas: Sequence[str] = VALIDATION_SCHEMAS,
                    coarse_dt: float = COARSE_DT) -> tuple[dict[str, float], pd.DataFrame]:
    """Runs the validation trials at both steps.

    Returns:
        (:func:`relative_mean_change`, both steps' per-trial measures stacked).
    """
    cfgs = validation_configs(seeds, schemas)
    full = trial_measures(cfgs, FULL_DT)
    coarse = trial_measures(cfgs, coarse_dt)
    return relative_mean_change(full, coarse), pd.concat([full, coarse], ignore_index=True)


__all__ = ["MEASURES", "VALIDATION_SCHEMAS", "relative_mean_change", "trial_measures",
           "validate_coarse", "validation_configs"]
