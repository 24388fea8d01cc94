"""Plausibility bounds of every physical and protocol number vasim reads (one table).

Each bound is ``Bound(low, high, unit, reason)``: a value outside ``[low, high]`` is not a
setting of a real experiment but a typo or a units error (mm for m, N/mm for N/m), and the
loaders refuse it with the file, the field, the value and this range
(:func:`vasim.core.config.check_number`). The bounds are deliberately loose: they stop
values that cannot describe the Phantom Omni, the abdomen or a study, not unusual settings.

**Decision**: bounds are closed intervals of finite floats; an open end (``> 0``) is asked
by the check (``gt=0``) on top of the bound, because the table states plausibility and the
checks state mathematics (a mass must be > 0 whatever the device). Keeping every bound
finite and small also means no arithmetic on validated input can overflow: the largest
products the simulator forms (gain x distance x scale, stiffness x extent, subjects x trials)
stay below 1e12.

Sources: Geomagic Phantom Omni / Touch specification (peak force 3.3 N, continuous 0.88 N,
stiffness 1.02-2.31 N/mm, workspace 160 x 120 x 70 mm); human anatomy (liver ~ 1.5 kg and
~ 0.2 m, the abdominal cavity ~ 0.4 m across); the seed thesis' studies (up to ~ 40 subjects,
~ 40 trials of at most a few minutes each).
"""

from __future__ import annotations

import os
from dataclasses import dataclass


@dataclass(frozen=True)
class Bound:
    """A plausibility range.

    Attributes:
        low, high: the closed range [low, high] in ``unit``.
        unit: the unit shown in messages (``""`` for counts and ratios).
        reason: why these limits (shown in messages).
    """

    low: float
    high: float
    unit: str
    reason: str

    def __post_init__(self) -> None:
        if not self.low <= self.high:
            raise ValueError(f"bound low {self.low!r} > high {self.high!r}")

    def __contains__(self, value: object) -> bool:
        return isinstance(value, int | float) and self.low <= value <= self.high


# -- the haptic device -------------------------------------------------------------------
FORCE_N = Bound(0.0, 3.3, "N", "the Phantom Omni's peak force, 3.3 N (Geomagic spec)")
"""Any force a fixture or a schema saturates to, and force thresholds of the metrics."""
FIXTURE_GAIN_N = Bound(0.0, 100.0, "N per unit d_norm",
                       "a gain 30x the Omni's 3.3 N peak saturates at 3% of D already")
"""Spring gains of fixtures per unit normalised distance (FF k, cone k_attract)."""
FIXTURE_DAMPING_NS = Bound(0.0, 10.0, "N s per unit d_norm",
                           "at the Omni's ~1 m/s hand speed 10 N s saturates 3x over")
"""Viscous gains of fixtures per unit normalised velocity (FF c, cone viscosity)."""
WALL_STIFFNESS_N_PER_M = Bound(0.0, 10_000.0, "N/m",
                               "4x the Omni's 2.31 N/mm maximum renderable stiffness")
"""Stiffness of virtual walls in N/m."""
# fixture gain (fading and assist-as-needed, vasim.fixtures.gain)
GAIN = Bound(0.0, 1.0, "", "a fixture gain: 0 no assistance, 1 the schema as written")
GAIN_STAGES = Bound(1, 100, "", "stages of a fading schedule (4 in the fading literature)")
GAIN_TIME_CONSTANT_S = Bound(0.0, 600.0, "s",
                             "the assist-as-needed lag: seconds, at most a few trials")
GAIN_DEVIATION_M = Bound(0.0, 0.1, "m",
                         "path deviation of full assistance: millimetres (the task is ~0.1 m)")
F5PL_VALUE = Bound(-1000.0, 1000.0, "",
                   "f5PL end values a, d are factors/gains of order 0.01-10")
F5PL_SLOPE = Bound(0.0, 50.0, "", "Hill slope b: 50 is already a step function")
F5PL_MIDPOINT = Bound(0.0, 1000.0, "", "midpoint c in units of D (distances are 0-10 D)")
F5PL_ASYMMETRY = Bound(0.0, 100.0, "", "asymmetry g: 1 is the symmetric 4PL")
TASK_SCALE_M = Bound(1e-3, 0.5, "m",
                     "task size D: from 1 mm to past the Omni's 160 mm workspace x 3")
"""The length D that normalises distances (schema ``scale_m``)."""
PATH_TOLERANCE_M = Bound(1e-4, 0.05, "m",
                         "tolerance tube around the planned path: 0.1 mm (sensor noise) to "
                         "5 cm (wider than any abdominal task's corridor)")
POI_SPACING_M = Bound(1e-3, 0.1, "m",
                      "arc length between trajectory POIs: 1 mm to 10 cm (the workspace is "
                      "about 10 cm across)")
REACH_RADIUS_M = Bound(1e-4, 0.02, "m",
                       "r_reach is a few mm; 2 cm already covers several trajectory points "
                       "in the Omni's 160 x 120 x 70 mm workspace")
"""Radius at which a trajectory/point goal counts as reached."""

CUE_PERIOD_S = Bound(0.0, 60.0, "s", "an audio cue repeating less than once a minute is silence")
NORMALISED_DISTANCE = Bound(0.0, 100.0, "D",
                            "distances in units of the task size D (the workspace is ~5 D)")
ZOOM = Bound(0.01, 100.0, "x", "a laparoscope zooms ~1-10x")
CAMERA_DISTANCE_M = Bound(0.0, 2.0, "m", "a laparoscope sits centimetres from the tissue")
LINE_WIDTH_PX = Bound(0.0, 100.0, "px", "an overlay arrow on a screen")
DIRECTION = Bound(-1000.0, 1000.0, "", "a direction vector, normalised on use")
COLOR_RGB = Bound(0.0, 1.0, "", "an RGB colour component")

# -- the abdomen -------------------------------------------------------------------------
ORGAN_MASS_KG = Bound(1e-3, 10.0, "kg",
                      "from a 1 g vessel segment to past the liver's ~1.5 kg (x 6)")
ORGAN_STIFFNESS_N_PER_M = Bound(0.0, 1e5, "N/m",
                                "soft tissue springs of 1-1000 N/m; 1e5 needs a step far "
                                "below the 4 ms physics rate")
ORGAN_DAMPING_NS_PER_M = Bound(0.0, 100.0, "N s/m", "per-node damping of soft tissue")
COORDINATE_M = Bound(-0.5, 0.5, "m",
                     "a point inside the abdomen (the cavity is ~0.4 m across; the scene "
                     "origin is its centre)")
"""Any position in a scene or in an organ mesh (after units)."""
ANCHOR_DISTANCE_M = Bound(0.0, 1.0, "m", "a distance within the abdomen (~0.4 m across)")
ORGAN_EXTENT_M = Bound(0.005, 0.4, "m",
                       "an organ is 5 mm (a duct) to ~0.25 m (the liver); 0.4 m is the "
                       "abdominal cavity itself")
"""Largest bounding-box side of an organ mesh."""
MESH_FILE_COORDINATE = Bound(-1e6, 1e6, "file units",
                             "1 km in mm; beyond, a vertex is corrupt, not a scale issue")
"""Raw vertex coordinates of a mesh file before unit scaling."""
DT_S = Bound(1e-5, 0.02, "s", "physics steps are tested from 10 us to 16 ms")
GRAVITY_M_S2 = Bound(0.0, 50.0, "m/s²", "~5 g; beyond, the value is not a gravity")
BREATHING_RATE_HZ = Bound(0.0, 1.0, "Hz", "60 breaths/min, above any tachypnoea (rest 0.2-0.3 Hz)")
HEARTBEAT_RATE_HZ = Bound(0.0, 3.0, "Hz", "180 beats/min, above any heart rate under anaesthesia")
BREATHING_AMPLITUDE_M = Bound(-0.05, 0.05, "m",
                              "the diaphragm moves organs 1-3 cm, ~5 cm in forced breathing")
HEARTBEAT_AMPLITUDE_M = Bound(-0.01, 0.01, "m", "pulsation moves tissue by millimetres")
SOLVER_ITERATIONS = Bound(1, 10_000, "", "iterations per organ and 4 ms physics step")

# -- robots (DH tables) ------------------------------------------------------------------
LINK_LENGTH_M = Bound(-5.0, 5.0, "m", "industrial arms reach at most a few metres")
JOINT_LIMIT_RAD = Bound(-4 * 3.141592653589793, 4 * 3.141592653589793, "rad",
                        "two turns either way (continuous joints are given as ±2π)")

JOINT_VELOCITY_RAD_S = Bound(0.0, 100.0, "rad/s",
                             "industrial joints turn at most ~12 rad/s (700 deg/s)")
JOINT_ACCELERATION_RAD_S2 = Bound(0.0, 10_000.0, "rad/s²", "~100x an RX60's 20-50 rad/s²")
LINK_RADIUS_M = Bound(0.0, 1.0, "m", "a robot link's collision capsule is centimetres thick")
DH_ANGLE_DEG = Bound(-720.0, 720.0, "deg", "a DH twist/offset angle (two turns either way)")

# -- studies -----------------------------------------------------------------------------
TRIAL_TIME_S = Bound(0.0, 86_400.0, "s",
                     "a day, the trial runner's limit (vasim.trials.kinds.MAX_TRIAL_TIME_S); "
                     "stored sessions up to it must reload")
REPETITIONS = Bound(1, 1000, "", "rounds over a block's variants")
PROBES_AFTER = Bound(0, 1000, "", "probe trials after one block")
TRIALS_PER_SESSION = Bound(1, 10_000, "",
                           "a session of 10,000 trials takes days (the thesis' ~40)")
SUBJECTS = Bound(1, 10_000, "", "a simulated cohort; the thesis' studies had ~10-40 subjects")
SURGEONS = Bound(0, 10_000, "", "surgeons among a simulated cohort")
RETENTION_DELAY_DAYS = Bound(0.0, 3650.0, "d",
                             "a retention interval; skill-decay studies span days to years "
                             "(Arthur et al. 1998: up to ~ 5 years)")
GATE_K = Bound(0.0, 10.0, "", "k of a benchmark mean ± k·SD (proficiency studies use 1-2)")
GATE_CONSECUTIVE = Bound(1, 100, "", "passes in a row a gate asks (the FLS proficiency "
                         "curriculum, Ritter & Scott 2007: 2 consecutive)")
GATE_MAX_TRIALS = Bound(1, 1000, "", "a gated block's cap of trials (proficiency curricula "
                        "reach their benchmarks within tens of repetitions)")
PRACTICE_TRIALS = Bound(0, 100_000, "", "earlier trials of one subject")
VARIANT = Bound(0, 6, "", "the trajectory's original and six mirrored/rotated variants")
PORT = Bound(0, 65_535, "", "a TCP port (0: any free port)")
DURATION_S = Bound(0.0, 86_400.0, "s", "a run of at most a day")
ID = Bound(1, 2**63 - 1, "", "a database row id (SQLite INTEGER)")
SEED = Bound(0, 2**63 - 1, "", "numpy SeedSequence entropy as stored (int64)")
QUESTION_RANGE = Bound(-1_000_000, 1_000_000, "", "integer answers of a questionnaire item")
TEXT_LENGTH = Bound(1, 100_000, "characters", "a free-text answer")
# -- power planning (vasim.study.power) ---------------------------------------------------
COHORTS = Bound(1, 100_000, "", "Monte Carlo cohorts per design point; 10,000 give a power "
                "to +-0.005, 100,000 x 46 subjects is years of CPU")
EFFECT_SCALE = Bound(0.0, 5.0, "", "x a scenario's fixture effects; a scale that makes an "
                     "effect invalid (an error reduction above 100 %) is refused by the "
                     "effect itself")
ALPHA = Bound(1e-6, 0.5, "", "a significance level; above 0.5 a test rejects more often "
              "than not under H0")
MAX_MESSAGE_CHARS = 80
"""Longest echo of a user value in an error message (longer ones are truncated)."""


def max_workers() -> int:
    """Upper bound of ``--workers``: 4 processes per CPU (beyond, only memory grows)."""
    return 4 * (os.cpu_count() or 1)


def workers_bound() -> Bound:
    """``--workers`` in [0 (in this process), 4 x CPU count]."""
    return Bound(0, max_workers(), "", f"4 x the {os.cpu_count() or 1} CPUs of this machine")


__all__ = [name for name in dir() if name.isupper()] + [
    "Bound", "max_workers", "workers_bound"]
