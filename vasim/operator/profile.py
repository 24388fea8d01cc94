"""The parameters of one simulated person (the scripted operator's profile).

The equations the fields enter are in ``vasim.operator.scripted`` (motion model); the
fixture-specific and learning adjustments per trial in ``vasim.operator.learning``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields, replace
from typing import ClassVar, Literal

import numpy as np


@dataclass(frozen=True)
class OperatorProfile:
    """Parameters of one simulated person (see the module docstring for the equations).

    Attributes:
        skill: s in [0, 1]: 0 novice, 1 expert (scales movement time, noise, feedback gain).
        learning_rate: alpha >= 0, power-law exponent of practice (0.1-0.5).
        asymptote: f in [0, 1), the share of the learnable noise and movement time that
            practice never removes: lambda_P = f + (1 - f) (1 + P)^-alpha (0: the plain
            power law; a scenario's group sets it, ``vasim.operator.scenario``).
        reaction_delay: tau_d [s], visual feedback delay, in [0, 1] (typically 0.15-0.25).
        tremor_amplitude: RMS tremor displacement per axis [m] (about 1e-4), >= 0.
        tremor_hz: tremor frequency [Hz], in [4, 20] (physiological: 8-12).
        noise: sigma_m, additive motor noise [m/sqrt(s)] (hand random-walk intensity), >= 0.
        gain_noise: sigma_g, signal-dependent relative velocity noise (dimensionless), >= 0.
        perception_noise: sigma_p, std of the misjudged TCP position at zoom 1 [m], >= 0.
        perception_time: correlation time of the misjudgement [s], > 0.
        perception_length: correlation length of the misjudgement along the planned path
            of the tip [m], > 0 (the misjudgement changes as the scene changes).
        feedback_gain: K0 [1/s], visual-feedback correction gain, > 0.
        fitts_a: Fitts intercept a [s], > 0.
        fitts_b: Fitts slope b [s/bit], >= 0.
        anticipation: phi in (0, 1]: fraction of a submovement after which the next POI is
            targeted (smaller = smoother, more overlapping movements).
        arm_stiffness: k_arm [N/m], endpoint stiffness of the hand holding the stylus, > 0.
        force_time: time constant of the hand's response to force [s], > 0.
        ms_compensation: c_MS in [0, 1], how much of the motion scaling the person undoes.
        force_acceptance: a_F in [0, 1], fraction of the force-induced hand displacement
            the person goes along with (0: corrects it all visually, 1: follows the pull).
        guidance_gain: beta_VG >= 0, precision of the VG arrow relative to unaided vision;
            also the feedback-gain boost while the arrow is shown.
        audio_gain: beta_AG >= 0, precision of the AG cue at full volume relative to vision;
            also the feedback-gain boost per unit of AG volume.

    Raises:
        ValueError: for any value outside its range; the message names field and value.
    """

    skill: float = 0.5
    learning_rate: float = 0.25
    asymptote: float = 0.0
    reaction_delay: float = 0.2
    tremor_amplitude: float = 1e-4
    tremor_hz: float = 10.0
    noise: float = 1.5e-3
    gain_noise: float = 0.15
    perception_noise: float = 1.5e-3
    perception_time: float = 3.0
    perception_length: float = 0.01
    feedback_gain: float = 6.0
    fitts_a: float = 0.4
    fitts_b: float = 0.5
    anticipation: float = 0.6
    arm_stiffness: float = 300.0
    force_time: float = 0.03
    ms_compensation: float = 0.5
    force_acceptance: float = 0.7
    guidance_gain: float = 1.0
    audio_gain: float = 1.0

    _RANGES: ClassVar[dict[str, tuple[float, float, bool, bool]]] = {
        # field: (low, high, low_inclusive, high_inclusive)
        "skill": (0.0, 1.0, True, True),
        "learning_rate": (0.0, 2.0, True, True),
        "asymptote": (0.0, 1.0, True, False),
        "reaction_delay": (0.0, 1.0, True, True),
        "tremor_amplitude": (0.0, 0.01, True, True),
        "tremor_hz": (4.0, 20.0, True, True),
        "noise": (0.0, 0.1, True, True),
        "gain_noise": (0.0, 2.0, True, True),
        "perception_noise": (0.0, 0.05, True, True),
        "perception_time": (0.0, 1000.0, False, True),
        "perception_length": (0.0, 10.0, False, True),
        "feedback_gain": (0.0, 100.0, False, True),
        "fitts_a": (0.0, 10.0, False, True),
        "fitts_b": (0.0, 10.0, True, True),
        "anticipation": (0.0, 1.0, False, True),
        "arm_stiffness": (0.0, 1e5, False, True),
        "force_time": (0.0, 10.0, False, True),
        "ms_compensation": (0.0, 1.0, True, True),
        "force_acceptance": (0.0, 1.0, True, True),
        "guidance_gain": (0.0, 100.0, True, True),
        "audio_gain": (0.0, 100.0, True, True),
    }

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise ValueError(f"OperatorProfile.{f.name} must be a number, got {v!r}")
            if not math.isfinite(v):
                raise ValueError(f"OperatorProfile.{f.name} must be finite, got {v!r}")
            lo, hi, lo_in, hi_in = self._RANGES[f.name]
            ok = (v >= lo if lo_in else v > lo) and (v <= hi if hi_in else v < hi)
            if not ok:
                lb = "[" if lo_in else "("
                rb = "]" if hi_in else ")"
                raise ValueError(
                    f"OperatorProfile.{f.name} must be in {lb}{lo}, {hi}{rb}, got {v!r}")

    @classmethod
    def novice(cls) -> OperatorProfile:
        """A novice (medical student level): slow, noisy, learns fast."""
        return cls(skill=0.1, learning_rate=0.35, reaction_delay=0.22,
                   tremor_amplitude=1.2e-4, anticipation=0.7)

    @classmethod
    def intermediate(cls) -> OperatorProfile:
        """A resident with some laparoscopic experience (the field defaults)."""
        return cls()

    @classmethod
    def expert(cls) -> OperatorProfile:
        """An experienced laparoscopic surgeon: fast, accurate, little left to learn."""
        return cls(skill=0.9, learning_rate=0.15, reaction_delay=0.18,
                   tremor_amplitude=0.8e-4, anticipation=0.5)

    @classmethod
    def sample(cls, rng: np.random.Generator,
               group: Literal["surgeon", "resident"]) -> OperatorProfile:
        """Draws one person of a simulated cohort (the VF study had surgeons and residents).

        Distributions (**decision**, plausible spreads, not fitted to data): skill ~
        Beta(7, 3) for surgeons (mean 0.7) and Beta(3, 5) for residents (mean 0.375);
        learning rate ~ N(0.15, 0.05) / N(0.3, 0.07) clipped to [0.02, 0.6]; reaction delay
        ~ N(0.2, 0.02) s clipped to [0.14, 0.3]; tremor amplitude lognormal around 1e-4 m
        (sigma 0.3); tremor frequency U(8, 12) Hz; motor, gain and perceptual noise
        lognormal (sigma 0.25) around the defaults; anticipation 0.75 - 0.25 skill.

        Raises:
            ValueError: for an unknown group.
        """
        if group == "surgeon":
            skill = rng.beta(7.0, 3.0)
            alpha = rng.normal(0.15, 0.05)
        elif group == "resident":
            skill = rng.beta(3.0, 5.0)
            alpha = rng.normal(0.3, 0.07)
        else:
            raise ValueError(f"group must be 'surgeon' or 'resident', got {group!r}")
        base = cls()
        return cls(
            skill=float(skill),
            learning_rate=float(np.clip(alpha, 0.02, 0.6)),
            reaction_delay=float(np.clip(rng.normal(0.2, 0.02), 0.14, 0.3)),
            tremor_amplitude=float(1e-4 * rng.lognormal(0.0, 0.3)),
            tremor_hz=float(rng.uniform(8.0, 12.0)),
            noise=float(base.noise * rng.lognormal(0.0, 0.25)),
            gain_noise=float(base.gain_noise * rng.lognormal(0.0, 0.25)),
            perception_noise=float(base.perception_noise * rng.lognormal(0.0, 0.25)),
            anticipation=float(0.75 - 0.25 * skill),
        )

    def replace(self, **changes: float) -> OperatorProfile:
        """A copy with some fields changed (validated)."""
        return replace(self, **changes)


__all__ = ["OperatorProfile"]
