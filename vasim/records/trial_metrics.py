"""Per-trial metrics beyond e_i / l_i, as commercial laparoscopic trainers record them.

Pure functions of one trial's sample columns (``SampleBuffer.view()`` names: ``t (n,)`` [s],
``x (n, 3)`` [m], ``contact``, ``f_contact (n, 3)`` [N], ``tau_contact (n, 3)`` [N m],
``delicate``, ``clutch``, ``in_view``). Nothing here touches the store or the clock.

Conventions (**decisions**, documented here once and used by every function):

* **Sample durations.** Sample j stands for the interval (t_(j-1), t_j] with t_(-1) =
  ``t_start`` (the trial start, 0): w_j = t_j - t_(j-1). Times and integrals are sums of
  w_j (the rectangle rule of the logged steps; exact for a flag or force held over a step).
  With the trial runner's log (t_j = (j + 1) dt) every w_j is dt.
* **Episodes.** A *count* (contacts, excessive-force events, clutch presses, out-of-view
  episodes) is the number of rising edges of the condition: samples where it holds and did
  not hold on the previous sample (the first sample counts if it holds).
* **Low-pass before differentiating.** Speed, jerk and movement counts use the TCP track
  filtered by a Butterworth low-pass of order ``filter_order`` (4) at ``filter_cutoff_hz``
  (5 Hz), applied forward and backward (``scipy.signal.sosfiltfilt``: zero phase, the
  squared magnitude response, i.e. -6 dB at the cutoff and an effective order 8) with odd
  padding over ``3 fs / f_c`` samples. Physiological tremor (8-12 Hz, ~0.1 mm) would
  otherwise dominate: its jerk, (2 pi 10 Hz)^3 x 0.1 mm ~ 25 m/s^3, is ~30x that of a 1 cm,
  0.7 s reaching movement (~0.7 m/s^3); the filter divides its power by ~250 at 10 Hz while
  reaching movements (< 3 Hz) pass. Derivatives are second-order central differences
  (``numpy.gradient``) on the sample times.
* **Number of movements.** A movement (sub-movement) is an episode of the filtered speed
  |v| above ``movement_on_speed`` (10 mm/s) that ends when |v| falls below
  ``movement_off_speed`` (5 mm/s): two speed peaks above 10 mm/s count as two movements
  only if the speed drops below 5 mm/s between them (hysteresis, so that noise around one
  threshold does not split one movement). Slow drifts that never exceed 10 mm/s are not
  movements.
* **Smoothness.** ``mean_jerk`` is the time average of |d^3x/dt^3| (3-D magnitude) over the
  trial [m/s^3]. ``log_dimensionless_jerk`` is the velocity-based LDLJ of Balasubramanian,
  Melendez-Calderon, Roby-Brami & Burdet 2015 ("On the analysis of movement smoothness",
  J NeuroEng Rehabil 12:112; after Hogan & Sternad 2009):
  ``-ln( (t2 - t1)^3 / v_peak^2 * integral |d^2v/dt^2|^2 dt )`` over the whole trial
  [t1, t2] = [t_start, t_n], v_peak the largest filtered speed. Higher (less negative) is
  smoother; a single minimum-jerk movement filling [t1, t2] gives -ln(720 / 1.875^2) =
  -ln(204.8) = -5.32.
* **Excessive force.** |F| above ``excessive_force_n`` (2 N, **decision**: a calibration
  value for the tissue contact force, not a published damage threshold; protocols set their
  own). The force is the tissue contact force ``f_contact`` (``force_source = "contact"``)
  or the force rendered to the operator (``"rendered"``).
* **Camera view.** ``out_of_view_time`` counts samples with ``in_view == 0``; it is NaN when
  any sample's visibility was not determined (``in_view == -1``, e.g. a producer that does not
  know the camera).

Example:
    >>> import numpy as np
    >>> t = np.arange(1, 5) * 0.5
    >>> contact = np.array([0, 1, 1, 0])
    >>> contact_time(t, contact), episode_count(contact)
    (1.0, 1)
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray
from scipy import signal

from vasim.core.config import check_choice, check_int, check_number
from vasim.records.path_deviation import PATH_TRIAL_KEYS
from vasim.records.samples import IN_VIEW_UNKNOWN

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class MetricParams:
    """Constants of the trial metrics (see the module docstring).

    Attributes:
        filter_cutoff_hz: low-pass cutoff before differentiating [Hz], > 0; None disables
            the filter (for exact tests on noise-free signals).
        filter_order: Butterworth order per pass (forward + backward), 1..8.
        movement_on_speed: speed above which a movement starts [m/s], > 0.
        movement_off_speed: speed below which it ends [m/s], in (0, movement_on_speed].
        excessive_force_n: force threshold of the excessive-force metrics [N], > 0.
        force_source: ``"contact"`` (tissue contact force, ``f_contact``) or
            ``"rendered"`` (the force rendered to the operator, ``force``).
        path_tolerance_m: radius of the tolerance tube of ``path_dev_out_frac`` [m], > 0
            (protocol ``path_tolerance_m``; **Decision**: 2 mm, the order of the path
            deviations the seed's subjects' tracks show (3-4 mm mean), so the fraction
            separates fixtures instead of saturating at 0 or 1).

    Raises:
        ConfigError: naming the field and the bad value.
    """

    filter_cutoff_hz: float | None = 5.0
    filter_order: int = 4
    movement_on_speed: float = 0.010
    movement_off_speed: float = 0.005
    excessive_force_n: float = 2.0
    force_source: Literal["contact", "rendered"] = "contact"
    path_tolerance_m: float = 0.002

    def __post_init__(self) -> None:
        if self.filter_cutoff_hz is not None:
            check_number(self.filter_cutoff_hz, "filter_cutoff_hz", gt=0)
        check_int(self.filter_order, "filter_order", lo=1, hi=8)
        for name in ("movement_on_speed", "movement_off_speed", "excessive_force_n",
                     "path_tolerance_m"):
            check_number(getattr(self, name), name, gt=0)
        check_number(self.movement_off_speed, "movement_off_speed", le=self.movement_on_speed)
        check_choice(self.force_source, "force_source", ("contact", "rendered"))


TRIAL_METRICS: dict[str, tuple[str, str]] = {
    "n_points": ("1", "number of POIs of the task"),
    "points_reached": ("1", "POIs reached"),
    "completed": ("0/1", "1 when every POI was reached"),
    "completion_time": ("s", "reach time of the last POI (NaN unless completed)"),
    "duration": ("s", "logged duration: last sample time minus trial start"),
    "total_error_l1": ("m·sample", "sum of eq. 6.5's e_i (Manhattan distance to the next "
                                   "POI summed over logged samples): grows with time and "
                                   "rate, not a length"),
    "error_l1_sum_mm_s": ("mm s", "eq. 6.5's e integrated over time (e_i times the sample "
                                  "period, summed): distance to the next POI x time"),
    "path_dev_mean_mm": ("mm", "time-mean distance of the tool tip to the planned path "
                               "(polyline start -> POIs; independent of speed)"),
    "path_dev_rms_mm": ("mm", "RMS distance of the tool tip to the planned path"),
    "path_dev_max_mm": ("mm", "largest distance of the tool tip to the planned path"),
    "path_dev_out_frac": ("1", "fraction of time outside the tolerance tube around the path "
                               "(MetricParams.path_tolerance_m, default 2 mm)"),
    "path_covered_frac": ("1", "fraction of the planned path covered: largest progress "
                               "along it (projection onto the goal's segment) over its length"),
    "path_dev_attempted_mm": ("mm", "mean distance to the planned path along the part "
                                    "attempted (arc-length bins; NaN when nothing was "
                                    "attempted: not moving never scores as accurate)"),
    "final_error_mm": ("mm", "point targeting: distance of the last sample to the POI"),
    "overshoot_mm": ("mm", "point targeting: largest travel past the POI along the approach"),
    "mean_latency": ("s", "mean latency l_i over the reached points"),
    "path_l1": ("m", "Manhattan length of the whole TCP track"),
    "path_l2": ("m", "Euclidean length of the whole TCP track"),
    "n_movements": ("1", "sub-movements: filtered-speed episodes above 10 mm/s, split "
                         "when the speed drops below 5 mm/s"),
    "mean_speed": ("m/s", "path_l2 / duration"),
    "peak_speed": ("m/s", "largest filtered speed"),
    "mean_jerk": ("m/s^3", "time average of |d^3x/dt^3| of the filtered track"),
    "log_dimensionless_jerk": ("1", "velocity-based LDLJ over the trial (higher = smoother)"),
    "contact_time": ("s", "time in tissue contact (contact flag)"),
    "contact_count": ("1", "tissue contacts (rising edges of the contact flag)"),
    "delicate_contact_time": ("s", "time in contact with a delicate structure"),
    "delicate_contact_count": ("1", "contacts with a delicate structure"),
    "excessive_force_time": ("s", "time with |F| above the excessive-force threshold"),
    "excessive_force_count": ("1", "episodes with |F| above the threshold"),
    "max_force": ("N", "largest |F| (tissue contact force by default)"),
    "accumulated_force": ("N s", "integral of |F| dt (tissue contact force by default)"),
    "accumulated_torque": ("N m s", "integral of |tau| dt of the tissue contact torque"),
    "out_of_view_time": ("s", "time the tool tip is outside the camera's field of view "
                              "(NaN if visibility was not determined)"),
    "out_of_view_count": ("1", "episodes out of the camera view (NaN if undetermined)"),
    "clutch_count": ("1", "clutch presses (rising edges of the clutch flag)"),
    "clutch_time": ("s", "time with the clutch engaged"),
    "target_displacement_max": ("m", "largest displacement of a target by the tool (from the "
                                     "abdomen physics; NaN without a scene)"),
    "target_displacement_mean": ("m", "time mean of the largest target displacement (NaN "
                                      "without a scene)"),
}
"""Every metric ``trial_metrics`` returns: name -> (unit, meaning), in output order."""


# ------------------------------------------------------------------------------ helpers
def _times(t: ArrayLike) -> FloatArray:
    tt = np.asarray(t, dtype=np.float64)
    if tt.ndim != 1:
        raise ValueError(f"t must have shape (n,), got {tt.shape}")
    return tt


def _flag(name: str, a: ArrayLike | None, n: int, default: int = 0) -> NDArray[np.int64]:
    if a is None:
        return np.full(n, default, dtype=np.int64)
    arr = np.asarray(a)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    return arr.astype(np.int64)


def _vectors(name: str, a: ArrayLike | None, n: int) -> FloatArray:
    if a is None:
        return np.zeros((n, 3))
    arr = np.asarray(a, dtype=np.float64)
    if arr.shape != (n, 3):
        raise ValueError(f"{name} must have shape ({n}, 3), got {arr.shape}")
    return arr


def sample_durations(t: ArrayLike, t_start: float = 0.0) -> FloatArray:
    """Durations w_j = t_j - t_(j-1) [s] of the samples, t_(-1) = ``t_start``.

    Example:
        >>> sample_durations([0.001, 0.002, 0.004]).tolist()
        [0.001, 0.001, 0.002]
    """
    tt = _times(t)
    if tt.size == 0:
        return np.zeros(0)
    w = np.diff(tt, prepend=float(t_start))
    if np.any(w < 0) or not np.all(np.isfinite(w)):
        raise ValueError("sample times must be finite and non-decreasing from t_start")
    return w


def episode_count(flag: ArrayLike) -> int:
    """Number of rising edges of a 0/1 (or boolean) flag: episodes where it holds.

    Example:
        >>> episode_count([1, 1, 0, 1, 0, 0, 1])
        3
    """
    f = np.asarray(flag).astype(bool)
    if f.ndim != 1:
        raise ValueError(f"flag must have shape (n,), got {f.shape}")
    if f.size == 0:
        return 0
    return int(f[0]) + int(np.count_nonzero(f[1:] & ~f[:-1]))


def flag_time(t: ArrayLike, flag: ArrayLike, t_start: float = 0.0) -> float:
    """Time [s] during which a 0/1 flag holds (sum of its samples' durations).

    Example:
        >>> flag_time([0.5, 1.0, 1.5], [0, 1, 1])
        1.0
    """
    w = sample_durations(t, t_start)
    f = np.asarray(flag).astype(bool)
    if f.shape != w.shape:
        raise ValueError(f"flag must have shape {w.shape}, got {f.shape}")
    return float(w[f].sum())


def contact_time(t: ArrayLike, contact: ArrayLike, t_start: float = 0.0) -> float:
    """Time in tissue contact [s] (the ``contact`` flag)."""
    return flag_time(t, contact, t_start)


def accumulated_norm(t: ArrayLike, v: ArrayLike, t_start: float = 0.0) -> float:
    """Integral of |v| dt over the trial (e.g. accumulated force [N s]).

    Args:
        t: (n,) sample times [s]. v: (n, 3) vectors (force [N], torque [N m]).

    Example:
        >>> accumulated_norm([1.0, 2.0], [[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
        6.0
    """
    w = sample_durations(t, t_start)
    vv = _vectors("v", v, w.shape[0])
    return float((np.sqrt((vv * vv).sum(axis=1)) * w).sum())


def threshold_episodes(t: ArrayLike, v: ArrayLike, threshold: float,
                       t_start: float = 0.0) -> tuple[float, int]:
    """(time [s], count) of the episodes with |v| > ``threshold``.

    Example:
        >>> threshold_episodes([1.0, 2.0, 3.0], [[3, 0, 0], [1, 0, 0], [0, 0, 5]], 2.0)
        (2.0, 2)
    """
    w = sample_durations(t, t_start)
    vv = _vectors("v", v, w.shape[0])
    over = np.sqrt((vv * vv).sum(axis=1)) > threshold
    return float(w[over].sum()), episode_count(over)


def lowpass(t: ArrayLike, x: ArrayLike, params: MetricParams = MetricParams()) -> FloatArray:
    """The zero-phase Butterworth low-pass of a (n, 3) track (module docstring).

    The sampling rate is taken from the median sample spacing; tracks of fewer than 4
    samples, or ``filter_cutoff_hz=None``, are returned unfiltered (as a copy). A cutoff at
    or above the Nyquist rate leaves the track unfiltered too.

    Args:
        t: (n,) sample times [s]. x: (n, 3) positions [m].

    Returns:
        (n, 3) filtered positions [m].
    """
    tt = _times(t)
    xx = _vectors("x", x, tt.shape[0])
    n = tt.shape[0]
    fc = params.filter_cutoff_hz
    if fc is None or n < 4:
        return xx.copy()
    dt = float(np.median(np.diff(tt)))
    if not dt > 0:
        raise ValueError("sample times must increase")
    fs = 1.0 / dt
    if fc >= 0.5 * fs:
        return xx.copy()
    sos = signal.butter(params.filter_order, fc, btype="low", fs=fs, output="sos")
    padlen = min(n - 1, round(3.0 * fs / fc))
    return signal.sosfiltfilt(sos, xx, axis=0, padtype="odd", padlen=padlen)


def derivatives(t: ArrayLike, x: ArrayLike) -> tuple[FloatArray, FloatArray, FloatArray]:
    """(velocity, acceleration, jerk), each (n, 3), by repeated second-order central
    differences (``numpy.gradient`` on the sample times); needs n >= 2.

    Example:
        >>> t = np.linspace(0.0, 1.0, 11)
        >>> v, a, j = derivatives(t, np.column_stack([t**3, 0 * t, 0 * t]))
        >>> round(float(j[5, 0]), 9)
        6.0
    """
    tt = _times(t)
    xx = _vectors("x", x, tt.shape[0])
    if tt.shape[0] < 2:
        raise ValueError("derivatives need at least 2 samples")
    v = np.gradient(xx, tt, axis=0)
    a = np.gradient(v, tt, axis=0)
    j = np.gradient(a, tt, axis=0)
    return v, a, j


def movement_count(speed: ArrayLike, on: float = 0.010, off: float = 0.005) -> int:
    """Number of movements in a speed profile (hysteresis rule of the module docstring).

    Args:
        speed: (n,) speed [m/s] (already low-passed). on, off: thresholds [m/s], off <= on.

    Example:
        >>> movement_count([0, 0.02, 0.007, 0.02, 0.001, 0.03, 0.0])
        2
    """
    s = np.asarray(speed, dtype=np.float64)
    if s.ndim != 1:
        raise ValueError(f"speed must have shape (n,), got {s.shape}")
    if not (0 < off <= on):
        raise ValueError(f"need 0 < off <= on, got on={on!r}, off={off!r}")
    # +1 above `on`, -1 below `off`, 0 in between (keeps the previous state); a movement
    # starts at each +1 whose previous non-zero state is -1 (or the start of the trial).
    state = np.where(s > on, 1, np.where(s < off, -1, 0))
    st = state[state != 0]
    if st.size == 0:
        return 0
    return int(st[0] == 1) + int(np.count_nonzero((st[1:] == 1) & (st[:-1] == -1)))


def mean_jerk(jerk: ArrayLike) -> float:
    """Mean of |jerk| [m/s^3] over the samples (the time average for uniform sampling).

    Args:
        jerk: (n, 3) third derivative of position [m/s^3].

    Example:
        >>> mean_jerk([[3.0, 4.0, 0.0], [0.0, 0.0, 1.0]])
        3.0
    """
    jj = np.asarray(jerk, dtype=np.float64)
    if jj.ndim != 2 or jj.shape[1] != 3:
        raise ValueError(f"jerk must have shape (n, 3), got {jj.shape}")
    if jj.shape[0] == 0:
        return math.nan
    return float(np.sqrt((jj * jj).sum(axis=1)).mean())


def log_dimensionless_jerk(t: ArrayLike, velocity: ArrayLike, acceleration_rate: ArrayLike,
                           ) -> float:
    """Velocity-based log dimensionless jerk over [t_0, t_n] (module docstring).

    Args:
        t: (n,) sample times [s]. velocity: (n, 3) [m/s]. acceleration_rate: (n, 3) the
            second derivative of velocity, i.e. the jerk [m/s^3].

    Returns:
        LDLJ (dimensionless), NaN if the tool never moved or n < 2.
    """
    tt = _times(t)
    v = _vectors("velocity", velocity, tt.shape[0])
    j = _vectors("acceleration_rate", acceleration_rate, tt.shape[0])
    if tt.shape[0] < 2:
        return math.nan
    vpk = float(np.sqrt((v * v).sum(axis=1)).max())
    span = float(tt[-1] - tt[0])
    if not (vpk > 0 and span > 0):
        return math.nan
    integral = float(np.trapezoid((j * j).sum(axis=1), tt))
    if not integral > 0:
        return math.nan
    return -math.log(span**3 / (vpk * vpk) * integral)


def kinematic_metrics(t: ArrayLike, x: ArrayLike, params: MetricParams = MetricParams(),
                      ) -> dict[str, float]:
    """Path, speed, movement and smoothness metrics of a TCP track.

    Args:
        t: (n,) sample times [s]. x: (n, 3) TCP positions [m].
        params: filter and movement constants.

    Returns:
        dict with ``path_l1``, ``path_l2`` [m] (raw track), ``peak_speed`` [m/s],
        ``n_movements``, ``mean_jerk`` [m/s^3], ``log_dimensionless_jerk`` (filtered track).
        Fewer than 4 samples give path lengths and NaN for the rest.
    """
    tt = _times(t)
    xx = _vectors("x", x, tt.shape[0])
    n = tt.shape[0]
    if n >= 2:
        d = np.diff(xx, axis=0)
        l1 = float(np.abs(d).sum())
        l2 = float(np.sqrt((d * d).sum(axis=1)).sum())
    else:
        l1 = l2 = 0.0
    out = {"path_l1": l1, "path_l2": l2, "peak_speed": math.nan, "n_movements": math.nan,
           "mean_jerk": math.nan, "log_dimensionless_jerk": math.nan}
    if n < 4 or not np.all(np.isfinite(xx)):
        return out
    xf = lowpass(tt, xx, params)
    v, _, j = derivatives(tt, xf)
    speed = np.sqrt((v * v).sum(axis=1))
    out["peak_speed"] = float(speed.max())
    out["n_movements"] = float(movement_count(speed, params.movement_on_speed,
                                              params.movement_off_speed))
    out["mean_jerk"] = mean_jerk(j)
    out["log_dimensionless_jerk"] = log_dimensionless_jerk(tt, v, j)
    return out


def trial_metrics(
    columns: Mapping[str, ArrayLike],
    *,
    summary: Mapping[str, Any] | None = None,
    t_start: float = 0.0,
    params: MetricParams = MetricParams(),
) -> dict[str, float]:
    """Every per-trial metric of ``TRIAL_METRICS`` for one trial.

    Args:
        columns: the trial's sample columns by ``SampleBuffer.view()`` name: ``t`` and
            ``x`` required; ``force``, ``contact``, ``f_contact``, ``tau_contact``,
            ``delicate``, ``clutch``, ``in_view`` optional (their buffer defaults).
        summary: ``metrics.trial_summary`` of the trial (e_i / l_i aggregates); its keys
            ``n_points``, ``points_reached``, ``completed``, ``completion_time``,
            ``total_error_l1``, ``mean_latency`` and the path-deviation keys
            (``path_deviation.PATH_TRIAL_KEYS``) are copied (NaN when absent).
        t_start: trial start [s] (reference of the first sample's duration).
        params: metric constants.

    Returns:
        dict name -> float, keys in ``TRIAL_METRICS`` order (counts as floats; NaN where
        undefined).

    Example:
        >>> import numpy as np
        >>> t = np.arange(1, 1001) * 1e-3
        >>> x = np.column_stack([0.1 * t, 0 * t, 0 * t])   # 10 cm/s along x for 1 s
        >>> m = trial_metrics({"t": t, "x": x})
        >>> round(m["path_l2"], 6), m["n_movements"], m["contact_time"], m["out_of_view_time"]
        (0.0999, 1.0, 0.0, nan)
    """
    if "t" not in columns or "x" not in columns:
        raise ValueError("columns need at least 't' and 'x'")
    tt = _times(columns["t"])
    n = tt.shape[0]
    xx = _vectors("x", columns["x"], n)
    w = sample_durations(tt, t_start)
    contact = _flag("contact", columns.get("contact"), n)
    delicate = _flag("delicate", columns.get("delicate"), n)
    clutch = _flag("clutch", columns.get("clutch"), n)
    in_view = _flag("in_view", columns.get("in_view"), n, IN_VIEW_UNKNOWN)
    source = "f_contact" if params.force_source == "contact" else "force"
    force = _vectors(source, columns.get(source), n)
    torque = _vectors("tau_contact", columns.get("tau_contact"), n)

    s = dict(summary or {})

    def from_summary(key: str) -> float:
        v = s.get(key)
        return math.nan if v is None else float(v)

    out: dict[str, float] = {k: math.nan for k in TRIAL_METRICS}
    for key in ("n_points", "points_reached", "completed", "completion_time",
                "total_error_l1", "mean_latency", *PATH_TRIAL_KEYS):
        out[key] = from_summary(key)
    # Target displacement is measured by the abdomen physics (vasim.abdomen.quality), not
    # from the samples: copied from the runner's summary.
    out["target_displacement_max"] = from_summary("tissue_target_displacement_max")
    out["target_displacement_mean"] = from_summary("tissue_target_displacement_mean")
    duration = float(tt[-1] - t_start) if n else 0.0
    out["duration"] = duration
    out.update(kinematic_metrics(tt, xx, params))
    out["mean_speed"] = out["path_l2"] / duration if duration > 0 else math.nan
    out["contact_time"] = float(w[contact != 0].sum())
    out["contact_count"] = float(episode_count(contact != 0))
    out["delicate_contact_time"] = float(w[delicate != 0].sum())
    out["delicate_contact_count"] = float(episode_count(delicate != 0))
    fmag = np.sqrt((force * force).sum(axis=1))
    over = fmag > params.excessive_force_n
    out["excessive_force_time"] = float(w[over].sum())
    out["excessive_force_count"] = float(episode_count(over))
    out["max_force"] = float(fmag.max()) if n else math.nan
    out["accumulated_force"] = float((fmag * w).sum())
    out["accumulated_torque"] = float((np.sqrt((torque * torque).sum(axis=1)) * w).sum())
    if n and not np.any(in_view == IN_VIEW_UNKNOWN):
        out["out_of_view_time"] = float(w[in_view == 0].sum())
        out["out_of_view_count"] = float(episode_count(in_view == 0))
    out["clutch_count"] = float(episode_count(clutch != 0))
    out["clutch_time"] = float(w[clutch != 0].sum())
    return {k: out[k] for k in TRIAL_METRICS}


__all__ = [
    "TRIAL_METRICS",
    "MetricParams",
    "accumulated_norm",
    "contact_time",
    "derivatives",
    "episode_count",
    "flag_time",
    "kinematic_metrics",
    "log_dimensionless_jerk",
    "lowpass",
    "mean_jerk",
    "movement_count",
    "sample_durations",
    "threshold_episodes",
    "trial_metrics",
]
