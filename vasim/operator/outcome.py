"""The outcome engine: a trial-level model of the simulated operator's path deviation.

The scripted engine (``vasim.operator.scripted``) runs every trial at 1 kHz through the
simulated abdomen (about a minute of CPU per trial); parameter recovery, power planning and
the validation of the analysis need thousands of cohorts. This engine draws a trial's mean
path deviation directly from the same per-trial quantities the scripted engine receives
(the adjusted profile and the effective practice of ``Session.trial_config``), with the
scenario's ``[outcome]`` assumptions (``vasim.operator.scenario.OutcomeModel``)::

    E = E0 x kappa_N(skill) x lambda_P x (sigma / sigma_0) x exp(u_i + e_ij)

E0 = ``path_deviation_mm``, kappa_N = 1 + SKILL_NOISE (1 - skill) and
lambda_P = f + (1 - f)(1 + P)^-alpha as in the scripted engine, sigma / sigma_0 the trial's
learnable-noise factor (the fixture's accuracy while assisted, carry-over and dependence
when unassisted: ``vasim.operator.learning.trial_adjustment``), u_i ~ N(0, subject_sd_log)
per subject, e_ij ~ N(0, trial_sd_log) per trial. Path deviation is taken proportional to
the learnable noise: in this engine the assumed accuracy factor IS the assisted
path-deviation ratio (``vasim.study.recovery``'s effect). Fixture mechanisms (forces, zoom)
are not simulated here.

Example:
    >>> from vasim.operator.scenario import OutcomeModel
    >>> m = OutcomeModel(path_deviation_mm=3.0, subject_sd_log=0.0, trial_sd_log=0.0)
    >>> p = OperatorProfile(skill=1.0, learning_rate=0.5, asymptote=0.5)
    >>> expected_path_deviation(m, p, p.replace(noise=p.noise * 0.8), practice=3)
    1.8
"""

from __future__ import annotations

import math

import numpy as np

from vasim.operator.profile import OperatorProfile
from vasim.operator.scenario import OutcomeModel
from vasim.operator.scripted import SKILL_NOISE, power_law


def expected_path_deviation(model: OutcomeModel, base: OperatorProfile,
                            adjusted: OperatorProfile, practice: int) -> float:
    """E without the random terms [mm] (module docstring): ``base`` the subject's own
    profile, ``adjusted`` the trial's (its noise ratio is the trial's noise factor)."""
    kn = 1.0 + SKILL_NOISE * (1.0 - base.skill)
    lam = power_law(practice, base.learning_rate, base.asymptote)
    factor = adjusted.noise / base.noise if base.noise > 0 else 1.0
    return model.path_deviation_mm * kn * lam * factor


def draw_path_deviation(model: OutcomeModel, base: OperatorProfile,
                        adjusted: OperatorProfile, practice: int, subject_effect: float,
                        rng: np.random.Generator) -> float:
    """One trial's mean path deviation [mm] (module docstring); ``subject_effect`` u_i."""
    e = float(rng.normal(0.0, model.trial_sd_log)) if model.trial_sd_log > 0 else 0.0
    return expected_path_deviation(model, base, adjusted, practice) * math.exp(
        subject_effect + e)


__all__ = ["draw_path_deviation", "expected_path_deviation"]
