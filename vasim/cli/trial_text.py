"""How the command line words a trial: its summary, its gain schedule, its outcome and the
real-time loop's timing (pure text from results; ``vasim trial`` and ``vasim study`` print it)."""

from __future__ import annotations

import math
from pathlib import Path


def format_timing(timing: object) -> str:
    """The servo loop's (and the physics thread's) timing of a real-time trial."""
    from vasim.trials.realtime import RealtimeTiming

    assert isinstance(timing, RealtimeTiming)
    s = timing.servo
    rows = [
        ("servo rate", f"{s.achieved_hz:.1f} Hz achieved (nominal {s.nominal_hz:g} Hz), "
                       f"{s.n_ticks} ticks"),
        ("servo period", f"p50 {s.period_p50_ms:.3f} / p99 {s.period_p99_ms:.3f} / max "
                         f"{s.period_max_ms:.2f} ms, jitter {s.jitter_rms_ms:.3f} ms"),
        ("overruns", f"{s.overruns} (period > {1.5:g} x nominal), {s.missed_deadlines} "
                     "missed slots"),
        ("tick cost", f"p50 {s.tick_cost_p50_ms:.3f} / p99 {s.tick_cost_p99_ms:.3f} ms"),
        ("scheduling", {True: "real-time (SCHED_FIFO)", False: "normal (real-time priority "
                        "refused)", None: "normal"}[timing.priority_granted]),
    ]
    p = timing.physics
    if p is not None and p.get("steps"):
        rows.append(("physics", f"{p['steps']} steps, {p['rate_hz']:.1f} Hz, step cost p50 "
                                f"{1e3 * p['cost_p50']:.2f} ms"))
    else:
        rows.append(("physics", timing.physics_mode))
    w = max(len(k) for k, _ in rows)
    return "\n".join(f"{k:<{w}}  {v}" for k, v in rows)


def format_summary(result: object, trial_id: int | None, db: Path | None) -> str:
    """A fixed-width summary table of one trial."""
    from vasim.trials.vf import TrialResult
    from vasim.trials.vf_config import VfTrialConfig

    assert isinstance(result, TrialResult) and isinstance(result.config, VfTrialConfig)
    s = result.summary
    m = result.metrics
    reached = int(m["reached"].sum())
    lat = m["latency"].dropna()
    n = max(len(result.samples), 1)
    rows = [
        ("trial id", "-" if trial_id is None else str(trial_id)),
        ("database", "-" if db is None else str(db)),
        ("task", f"{result.task.name} ({result.task.kind}, {len(m)} points)"),
        ("schema", f"{result.schema.name} [{s['active_fixtures'] or 'no fixtures'}]"
                   + (f", gain {describe_gain(result.config.gain, s)}"
                      if result.config.gain != 1.0 else "")),
        ("operator", f"{result.config.operator}/{result.config.skill}, seed {result.config.seed}"),
        ("subject", result.config.subject or (
            f"none ({result.config.label})" if result.config.label else "none")),
        ("outcome", describe_outcome(s, reached, len(m))),
        ("points reached", f"{reached}/{len(m)}"),
        ("completion time" if s.get("outcome") == "reached_all" else "duration",
         f"{s['sim_time']:.2f} s"),
        ("path deviation", f"mean {s['path_dev_mean_mm']:.2f} mm, RMS "
                           f"{s['path_dev_rms_mm']:.2f} mm, max {s['path_dev_max_mm']:.2f} mm, "
                           f"{100 * s['path_dev_out_frac']:.1f} % of time outside the tube"),
        ("cumulative error", f"sum e_i x dt = {s['error_l1_sum_mm_s']:.1f} mm s (eq. 6.5: "
                             f"{m['error_l1'].sum():.2f} m·sample over {n} samples; mean "
                             f"|x - g|_1 = {1000 * m['error_l1'].sum() / n:.1f} mm)"),
        ("mean latency l_i", f"{lat.mean():.3f} s" if len(lat) else "-"),
        ("path length", f"{m['path_l1'].sum():.3f} m (Manhattan), "
                        f"{m['path_l2'].sum():.3f} m (Euclidean)"),
        ("samples", f"{len(result.samples)} at {1 / result.config.dt:.0f} Hz"),
        ("speed", f"{float(s['sim_time']) / max(result.wall_time, 1e-9):.1f}x real time"),
    ]
    if result.events:
        rows.append(("events", f"{len(result.events)} (see the events table)"))
    w = max(len(k) for k, _ in rows)
    lines = [f"{k:<{w}}  {v}" for k, v in rows]
    if not math.isfinite(float(s["sim_time"])):
        lines.append("warning: non-finite time")
    return "\n".join(lines)


def describe_gain(gain: object, summary: object) -> str:
    """A trial's fixture gain in words: ``"0.5 (constant)"`` or ``"adaptive 0.25-1, mean
    0.61"`` (``summary["gain_mean"]``).

    >>> describe_gain(0.5, {"gain_mean": 0.5})
    '0.5 (constant)'
    """
    from vasim.fixtures.gain import AdaptiveRule

    mean = summary.get("gain_mean") if isinstance(summary, dict) else None
    if isinstance(gain, AdaptiveRule):
        return (f"adaptive {gain.gain_min:g}-{gain.gain_max:g}"
                + (f", mean {float(mean):.2f}" if mean is not None else ""))
    return f"{float(gain):g} (constant)"  # type: ignore[arg-type]


_OUTCOME_WORDS = {"timed_out": "timed out", "stopped": "stopped", "failed": "failed",
                  "interrupted": "interrupted"}


def describe_outcome(summary: object, reached: int, n_points: int) -> str:
    """How a trial ended, in words: ``"reached all 30 points in 12.30 s"``, ``"timed out
    after 2.0 s with 3 of 30 points"`` (``summary["outcome"]``, ``summary["sim_time"]`` [s]).

    Example:
        >>> describe_outcome({"outcome": "timed_out", "sim_time": 2.0}, 3, 30)
        'timed out after 2.0 s with 3 of 30 points'
    """
    assert isinstance(summary, dict)
    outcome = summary.get("outcome")
    t = float(summary.get("sim_time", math.nan))
    if outcome == "reached_all":
        return f"reached all {n_points} points in {t:.2f} s"
    word = _OUTCOME_WORDS.get(str(outcome), str(outcome))
    return f"{word} after {t:.1f} s with {reached} of {n_points} points"


# ------------------------------------------------------------------------------ study


__all__ = ["describe_gain", "describe_outcome", "format_summary", "format_timing"]
