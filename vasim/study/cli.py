"""``vasim trial``: run one logged trial headless and print its summary."""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

from vasim.errors import ConfigError


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "trial",
        help="run one trial headless (1 kHz control step) and store it",
        description=(
            "Run one trial headless, faster than real time, at a 1 kHz control step. With "
            "--db, every sample and the per-point metrics (cumulative Manhattan error e_i, "
            "latency l_i, path length) are stored in SQLite in one transaction when the trial "
            "ends; an interrupted trial is marked 'interrupted', never half-written."
        ),
    )
    p.add_argument("--task", choices=["trajectory", "point"], default="trajectory")
    p.add_argument("--variant", type=int, default=0,
                   help="trajectory variant: 0 original, 1-6 mirrored/rotated (default 0)")
    p.add_argument("--schema", default="none",
                   help="fixture schema name (see `vasim schemas list`) or TOML path")
    p.add_argument("--operator", choices=["scripted"], default="scripted")
    p.add_argument("--skill", choices=["novice", "intermediate", "expert"],
                   default="intermediate", help="scripted operator preset")
    p.add_argument("--practice", type=int, default=0,
                   help="earlier trials of this subject (learning), default 0")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--subject", default="S00", help="subject code (not a name)")
    p.add_argument("--max-time", type=float, default=180.0, help="time limit [s]")
    p.add_argument("--db", type=Path, default=None,
                   help="SQLite study database to store the trial in")
    p.add_argument("--points", action="store_true", help="print the per-point table")
    p.set_defaults(func=_cmd_trial)


def _cmd_trial(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore
    from vasim.study.trial import TrialConfig, run_trial

    config = TrialConfig(
        task=args.task, variant=args.variant, schema=args.schema, operator=args.operator,
        skill=args.skill, practice=args.practice, seed=args.seed, subject=args.subject,
        max_time=args.max_time,
    )
    store = None
    if args.db is not None:
        if args.db.exists() and args.db.is_dir():
            raise ConfigError(f"--db {args.db} is a directory, expected a database file")
        store = TrialStore(args.db)
    try:
        result, trial_id = run_trial(config, store, progress=sys.stderr.isatty())
    finally:
        if store is not None:
            store.close()
    print(format_summary(result, trial_id, args.db))
    if args.points:
        print(result.metrics.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    return 0


def format_summary(result: object, trial_id: int | None, db: Path | None) -> str:
    """A fixed-width summary table of one trial."""
    from vasim.study.trial import TrialResult

    assert isinstance(result, TrialResult)
    s = result.summary
    m = result.metrics
    reached = int(m["reached"].sum())
    lat = m["latency"].dropna()
    n = max(len(result.samples), 1)
    rows = [
        ("trial id", "-" if trial_id is None else str(trial_id)),
        ("database", "-" if db is None else str(db)),
        ("task", f"{result.task.name} ({result.task.kind}, {len(m)} points)"),
        ("schema", f"{result.schema.name} [{s['active_fixtures'] or 'no fixtures'}]"),
        ("operator", f"{result.config.operator}/{result.config.skill}, seed {result.config.seed}"),
        ("points reached", f"{reached}/{len(m)}"),
        ("completion time", f"{s['sim_time']:.2f} s"),
        ("cumulative error", f"sum e_i = {m['error_l1'].sum():.2f} m over {n} samples "
                             f"(mean |x - g|_1 = {1000 * m['error_l1'].sum() / n:.1f} mm)"),
        ("mean e_i", f"{m['error_l1'].mean():.3f} m per point"),
        ("mean latency l_i", f"{lat.mean():.3f} s" if len(lat) else "-"),
        ("path length", f"{m['path_l1'].sum():.3f} m (Manhattan), "
                        f"{m['path_l2'].sum():.3f} m (Euclidean)"),
        ("samples", f"{len(result.samples)} at {1 / result.config.dt:.0f} Hz"),
        ("speed", f"{s['sim_time'] / max(result.wall_time, 1e-9):.1f}x real time"),
    ]
    if result.events:
        rows.append(("events", f"{len(result.events)} (see the events table)"))
    w = max(len(k) for k, _ in rows)
    lines = [f"{k:<{w}}  {v}" for k, v in rows]
    if not math.isfinite(float(s["sim_time"])):
        lines.append("warning: non-finite time")
    return "\n".join(lines)
