"""``vasim trial`` (one logged trial headless) and ``vasim study`` (sessions, cohorts, export).

``vasim study`` subcommands:

* ``run``: a subject's whole session of a protocol, headless, with the scripted operator;
* ``resume``: continue a session at its first unfinished scheduled trial;
* ``list``: sessions with their progress;
* ``export``: tidy tables (CSV / Parquet) for analysis;
* ``simulate``: a synthetic cohort (parallel workers, one writer, resumable);
* ``power``: power of the primary tests against the subject count (simulated cohorts on Ray);
* ``schedule``: print the schedule a protocol and seed give (nothing is stored);
* ``answer``: record a session's questionnaire answers from a TOML file;
* ``abort``: close a session for good.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from vasim.cli.args import bounded_float, bounded_int, output_folder, subject_code, workers
from vasim.cli.power import register_power
from vasim.cli.trial_text import format_summary, format_timing
from vasim.core.bounds import (
    EFFECT_SCALE,
    GAIN,
    ID,
    PRACTICE_TRIALS,
    SEED,
    SUBJECTS,
    SURGEONS,
    TRIAL_TIME_S,
    VARIANT,
)
from vasim.core.config import check_file, check_not_dir, expect
from vasim.core.errors import ConfigError, InputError


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
    p.add_argument("--variant", type=bounded_int(VARIANT), default=0,
                   help="trajectory variant: 0 original, 1-6 mirrored/rotated (default 0)")
    p.add_argument("--schema", default="none",
                   help="fixture schema name (see `vasim schemas list`) or TOML path")
    p.add_argument("--operator", choices=["scripted"], default="scripted")
    p.add_argument("--skill", choices=["novice", "intermediate", "expert"],
                   default="intermediate", help="scripted operator preset")
    p.add_argument("--practice", type=bounded_int(PRACTICE_TRIALS), default=0,
                   help="earlier trials of this subject (learning), default 0")
    p.add_argument("--seed", type=bounded_int(SEED), default=0)
    p.add_argument("--subject", type=subject_code, default=None,
                   help="subject code (not a name); default: none (the trial is stored "
                        "without a subject and left out of subject analyses)")
    p.add_argument("--label", default=None,
                   help="free-practice label of a trial (stored beside, never as, the "
                        "subject; it must contain a space or ':', e.g. 'free: warm-up', so "
                        "that it cannot be mistaken for a subject code)")
    p.add_argument("--max-time", type=bounded_float(TRIAL_TIME_S, gt=0.0), default=180.0,
                   help="time limit [s]")
    p.add_argument("--gain", type=bounded_float(GAIN), default=1.0, metavar="G",
                   help="constant fixture gain in [0, 1] scaling every fixture's f5PL output "
                        "(1: the schema as written, default; 0: no assistance); logged per "
                        "sample and stored with the trial like a schedule's gain")
    p.add_argument("--scene", default="default",
                   help="abdomen scene (protocols/scenes/NAME.toml or a TOML path), or 'none' "
                        "for a static task without tissue (default: default)")
    p.add_argument("--db", type=Path, default=None,
                   help="SQLite study database to store the trial in")
    p.add_argument("--points", action="store_true", help="print the per-point table")
    rt = p.add_argument_group(
        "real time", "run the trial in real time through the 1 kHz haptic servo loop "
        "(vasim.trials.realtime), or replay a recorded real-time trial exactly")
    rt.add_argument("--realtime", action="store_true",
                    help="run in real time (1 kHz servo loop in its own process, physics "
                         "thread beside it); prints the loop's "
                         "timing; with --db the timing and the device recording are stored")
    rt.add_argument("--device", choices=["scripted", "emulator", "openhaptics"],
                    default="scripted",
                    help="input device of a --realtime trial (default: the scripted "
                         "operator; emulator: an emulated Omni held still)")
    rt.add_argument("--physics", choices=["thread", "off"], default="thread",
                    help="abdomen physics of a --realtime trial (default: its own thread)")
    rt.add_argument("--in-process", action="store_true",
                    help="run the servo loop as a thread of this process instead of its "
                         "own process (the viewer's way; less steady on a loaded host)")
    rt.add_argument("--replay", type=bounded_int(ID), default=None, metavar="TRIAL_ID",
                    help="re-run a stored real-time trial from its recording (needs --db) "
                         "and compare it with the stored samples and metrics")
    p.set_defaults(func=_cmd_trial)
    _register_study(sub)


def _cmd_trial(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore
    from vasim.trials.registry import run_trial
    from vasim.trials.vf import TrialConfig

    realtime_only = [flag for flag, given in (
        ("--device", getattr(args, "device", "scripted") != "scripted"),
        ("--physics", getattr(args, "physics", "thread") != "thread"),
        ("--in-process", getattr(args, "in_process", False))) if given]
    if getattr(args, "replay", None) is not None:
        if getattr(args, "realtime", False) or realtime_only:
            raise InputError("--replay re-runs the stored trial as recorded: it takes no "
                             f"{', '.join(['--realtime', *realtime_only][:3])}",
                             field="replay")
        return _cmd_replay(args)
    if getattr(args, "realtime", False):
        return _cmd_realtime(args)
    if realtime_only:
        verb = "applies" if len(realtime_only) == 1 else "apply"
        raise InputError(f"{', '.join(realtime_only)} {verb} only with --realtime",
                         field=realtime_only[0])

    config = TrialConfig(
        task=args.task, variant=args.variant, schema=args.schema, operator=args.operator,
        skill=args.skill, practice=args.practice, seed=args.seed, subject=args.subject,
        max_time=args.max_time, scene=args.scene, label=_label(args), gain=_gain(args),
    )
    store = None
    if args.db is not None:
        store = TrialStore(_new_db(args.db))
    try:
        result, trial_id = run_trial(config, store, progress=sys.stderr.isatty())
    finally:
        if store is not None:
            store.close()
    print(format_summary(result, trial_id, args.db))
    if args.points:
        print(result.metrics.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    return 0


def _gain(args: argparse.Namespace) -> float:
    """``--gain`` (already in [0, 1], ``bounded_float(GAIN)``), refused below 1 on a schema
    without fixtures.

    **Decision**: as a protocol refuses a gain on a fixture-free schema ("a schema with
    fixtures (a gain scales them)"), ``vasim trial`` does: a gain < 1 there would be stored
    as a faded trial that nothing faded.

    Raises:
        ConfigError: (field ``--gain``) naming the value and the schema.
    """
    gain = float(getattr(args, "gain", 1.0))
    if gain != 1.0:
        from vasim.fixtures.schema import load_schema

        schema = load_schema(args.schema)
        expect(schema.fixtures, gain, f"1 for schema {schema.name!r}, which has no "
               "fixtures (a gain scales a schema's fixtures)", field="--gain", error=InputError)
    return gain


def _label(args: argparse.Namespace) -> str | None:
    """``--label``, checked (``vasim.study.store.validate_label``), or None."""
    label = getattr(args, "label", None)
    if label is None:
        return None
    from vasim.study.store import validate_label

    return validate_label(label)


def _realtime_device_factory(kind: str) -> object | None:
    """A picklable factory of the input device ``--device`` names (None: the scripted
    operator); the servo process calls it."""
    if kind == "scripted":
        return None
    if kind == "emulator":
        from functools import partial

        from vasim.haptics.devices.emulator import EmulatorDevice

        return partial(EmulatorDevice, hand=(0.0, 0.0, 0.0))
    from vasim.haptics.devices.openhaptics import OpenHapticsDevice

    return OpenHapticsDevice


def _cmd_realtime(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore
    from vasim.trials.realtime import run_realtime_trial
    from vasim.trials.vf import TrialConfig

    config = TrialConfig(
        task=args.task, variant=args.variant, schema=args.schema, operator=args.operator,
        skill=args.skill, practice=args.practice, seed=args.seed, subject=args.subject,
        max_time=args.max_time, scene=args.scene, label=_label(args), gain=_gain(args),
    )
    factory = _realtime_device_factory(args.device)
    in_process = bool(getattr(args, "in_process", False))
    store = None
    if args.db is not None:
        store = TrialStore(_new_db(args.db))
    try:
        if in_process:
            device = factory() if callable(factory) else None
            result, trial_id, timing = run_realtime_trial(
                config, store, device, physics=args.physics)
        else:
            result, trial_id, timing = run_realtime_trial(
                config, store, physics=args.physics, process=True,
                device_factory=factory, device_name=args.device)
    finally:
        if store is not None:
            store.close()
    print(format_summary(result, trial_id, args.db))
    print(format_timing(timing))
    if args.points:
        print(result.metrics.to_string(index=False, float_format=lambda v: f"{v:.4f}"))
    return 0


def _cmd_replay(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore
    from vasim.trials.realtime import replay_trial

    if args.db is None:
        raise InputError("--replay needs --db (the database the trial is stored in)",
                         field="db")
    store = TrialStore(_existing_db(args.db), readonly=True)
    try:
        report = replay_trial(store, args.replay)
    finally:
        store.close()
    print(format_summary(report.result, args.replay, args.db))
    same = report.samples_equal and report.metrics_equal
    print(f"replay: {report.ticks} servo ticks from the recording; "
          + ("samples and metrics identical to the stored trial" if same else
             "DIFFERS from the stored trial: " + ", ".join(report.differences)))
    return 0 if same else 1


def _register_study(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    p = sub.add_parser(
        "study", help="run, resume, list, export and simulate study sessions",
        description=(
            "Study sessions: a protocol (protocols/studies/*.toml) gives each subject a "
            "schedule of trials, randomised from a seed that is stored with the session; "
            "every completed trial is durable before the next starts, and an interrupted "
            "session resumes at its first unfinished scheduled trial."))
    ss = p.add_subparsers(dest="study_command", metavar="SUBCOMMAND", required=True)

    _add_run(ss)

    r = ss.add_parser("resume", help="continue a session at its first unfinished trial")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--subject", type=subject_code, default=None,
                   help="subject code of a running session")
    r.add_argument("--session", type=bounded_int(ID), default=None, help="session id")
    r.add_argument("--protocol", default=None,
                   help="protocol name, when the subject has several running sessions")
    r.add_argument("--answers", type=Path, default=None,
                   help="TOML file with [post] (and [pre]) answers to record")
    r.add_argument("--simulate-delay", action="store_true",
                   help="begin a later sitting (a retention block's delay) now, recording a "
                        "simulated delay instead of waiting for it")
    _no_progress_flag(r)
    r.set_defaults(func=_cmd_resume)

    r = ss.add_parser("list", help="sessions with their progress")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--subject", type=subject_code, default=None)
    r.set_defaults(func=_cmd_list)

    r = ss.add_parser("export", help="write tidy tables (CSV / Parquet)")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--out", type=output_folder, required=True, help="output folder")
    r.add_argument("--format", default="csv", help="csv, parquet or csv,parquet")
    r.add_argument("--tables", default=None,
                   help="comma-separated subset of: samples, trials, trial_metrics, "
                        "point_metrics, questionnaires, subjects, sessions, schedule")
    _no_progress_flag(r)
    r.set_defaults(func=_cmd_export)

    _add_simulate(ss)

    register_power(ss)   # vasim/cli/power.py

    r = ss.add_parser("schedule", help="print the schedule of a protocol and seed")
    r.add_argument("--protocol", required=True)
    r.add_argument("--seed", type=bounded_int(SEED), required=True)
    r.add_argument("--sequence", type=bounded_int(SEED), default=None,
                   help="the subject's sequence number i (Williams row i mod R, probe-variant "
                        "rotation offset; default: the seed)")
    r.set_defaults(func=_cmd_schedule)

    r = ss.add_parser("answer", help="record questionnaire answers from a TOML file")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--session", type=bounded_int(ID), required=True)
    r.add_argument("--file", type=Path, required=True,
                   help="TOML with a [pre] and/or [post] table of item = answer")
    r.set_defaults(func=_cmd_answer)

    r = ss.add_parser("abort", help="close a session for good (its trials are kept)")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--session", type=bounded_int(ID), required=True)
    r.add_argument("--reason", required=True)
    r.set_defaults(func=_cmd_abort)


def _add_run(ss: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """``vasim study run``: a subject's whole session, headless."""
    r = ss.add_parser("run", help="run a subject's whole session headless")
    r.add_argument("--protocol", required=True,
                   help="protocol name (protocols/studies) or TOML path")
    r.add_argument("--subject", type=subject_code, required=True,
                   help="subject code (never a name)")
    r.add_argument("--db", type=Path, required=True, help="SQLite study database")
    r.add_argument("--operator", default="scripted",
                   help="input device: scripted (browser sessions run from `vasim serve`)")
    r.add_argument("--seed", type=bounded_int(SEED), default=None,
                   help="randomisation seed (default: a fresh random one, printed and stored)")
    r.add_argument("--skill", choices=["novice", "intermediate", "expert"],
                   default="intermediate", help="scripted operator preset")
    r.add_argument("--max-time", type=bounded_float(TRIAL_TIME_S, gt=0.0), default=None,
                   help="trial time limit [s] (default: the protocol's)")
    r.add_argument("--answers", type=Path, default=None,
                   help="TOML file with [pre] and [post] questionnaire answers")
    r.add_argument("--again", default=None, metavar="REASON",
                   help="run the protocol again for a subject who completed it, for this "
                        "reason (stored with the new session); without it such a run is "
                        "refused")
    _no_progress_flag(r)
    r.set_defaults(func=_cmd_run)


def _add_simulate(ss: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """``vasim study simulate``: a cohort of scripted subjects."""
    r = ss.add_parser("simulate", help="simulate a cohort of scripted subjects")
    r.add_argument("--protocol", required=True)
    r.add_argument("--subjects", type=bounded_int(SUBJECTS), default=46,
                   help=f"cohort size (default 46; at most {SUBJECTS.high:,})")
    r.add_argument("--surgeons", type=bounded_int(SURGEONS), default=None,
                   help="surgeons among them (default 31 of 46, scaled for other sizes)")
    r.add_argument("--seed", type=bounded_int(SEED), default=7, help="cohort seed (default 7)")
    r.add_argument("--db", type=Path, required=True)
    r.add_argument("--workers", type=workers, default=None,
                   help="worker processes (default: number of cores; 0: in this process; at "
                        "most 4 x the cores)")
    r.add_argument("--max-time", type=bounded_float(TRIAL_TIME_S, gt=0.0), default=None,
                   help="trial time limit [s] (default: the protocol's)")
    r.add_argument("--scenario", default=None, metavar="NAME|FILE.toml",
                   help="the declared scenario of the simulated operator: a name in "
                        "protocols/scenarios or a TOML file (docs/simulation.md); a VF "
                        "protocol takes a VF scenario (default seed_plausible; null), a "
                        "teleoperation protocol a teleoperation one (default "
                        "teleop_mechanism_only; teleop_assumed, docs/seed-chapter5.md); "
                        "stored with each session with its sha256")
    r.add_argument("--effect-scale", type=bounded_float(EFFECT_SCALE), default=1.0,
                   metavar="X",
                   help="x the scenario's fixture effects and mechanism gain, or its mode "
                        "penalties (default 1; 0: no fixture effect at all, or the "
                        "teleoperation mechanism alone)")
    _no_progress_flag(r)
    r.set_defaults(func=_cmd_simulate)


def _existing_db(path: Path) -> Path:
    return check_file(path, "--db", what="an existing study database file")


def _new_db(path: Path) -> Path:
    return check_not_dir(path, "--db", what="a database file (new or existing)")


def _no_progress_flag(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--no-progress", action="store_true",
                        help="no progress output (default: a bar on a terminal, a line every "
                             "15 s in a log file)")


def _progress(args: argparse.Namespace) -> bool:
    return not args.no_progress


def _record_file_answers(store: object, session_id: int, path: Path | None,
                         which: tuple[str, ...], *, skip_answered: bool = False) -> list[str]:
    """Records the [pre]/[post] tables of an answers file; returns what was recorded.
    ``skip_answered`` (``resume``: the file given to ``run`` again) passes over a table the
    session already has; otherwise recording it again is an error (StoreError)."""
    if path is None:
        return []
    from vasim.study.session import load_answers_file, record_answers
    from vasim.study.store import TrialStore

    assert isinstance(store, TrialStore)
    data = load_answers_file(path)
    answered = set(store.answers(session_id)["questionnaire"]) if skip_answered else set()
    done = []
    for q in which:
        if q in data and q not in answered:
            n = record_answers(store, session_id, q, data[q], source=str(path))  # type: ignore[arg-type]  # a parsed answers table
            done.append(f"{q} ({n} answers)")
    return done


def _session_line(store: object, session_id: int) -> str:
    from vasim.study.store import TrialStore

    assert isinstance(store, TrialStore)
    df = store.sessions()
    row = df[df["id"] == session_id].iloc[0]
    return (f"session {session_id}: subject {row['subject']}, protocol {row['protocol']}, "
            f"seed {row['seed']}, {row['n_completed']}/{row['n_trials']} trials completed, "
            f"status {row['status']}")


def _print_next_sitting(store: object, session_id: int) -> None:
    """When a running session stopped at a later sitting: when it is due and how to go on."""
    from vasim.study.session import load_session, sitting_begins
    from vasim.study.store import TrialStore

    assert isinstance(store, TrialStore)
    s = load_session(store, session_id)
    if s.status != "running" or not s.pending:
        return
    st = s.pending[0]
    delay = sitting_begins(s, st)
    if delay is None:
        return
    print(f"the next sitting (block {st.block!r}) begins {delay:g} d after the last trial: "
          f"`vasim study resume --db {store.path} --session {session_id}` then (or now "
          "with --simulate-delay)")


def _cmd_run(args: argparse.Namespace) -> int:
    from vasim.records.trial_meta import validate_subject_code
    from vasim.study.protocol import load_protocol
    from vasim.study.session import SessionSettings, check_again, run_session, start_session
    from vasim.study.store import TrialStore

    settings = SessionSettings(operator=args.operator, skill=args.skill,
                               max_trial_time=args.max_time)
    validate_subject_code(args.subject)
    protocol = load_protocol(args.protocol)
    protocol.check_runnable()
    if args.answers is not None:      # a bad answers file must not leave an empty session
        from vasim.study.protocol import validate_answers
        from vasim.study.session import load_answers_file

        for q, table in load_answers_file(args.answers).items():
            validate_answers(protocol, q, table, source=str(args.answers))  # type: ignore[arg-type]  # a parsed answers table
    with TrialStore(_new_db(args.db)) as store:
        notes = check_again(store, protocol.name, args.subject, args.again)
        sid = start_session(store, protocol, args.subject, seed=args.seed, settings=settings,
                            notes=notes)
        if notes is not None:
            print(f"session {sid}: {notes}", file=sys.stderr)
        recorded = _record_file_answers(store, sid, args.answers, ("pre",))
        print(f"session {sid} started: {protocol.n_trials} trials, seed "
              f"{store.session(sid)['seed']}", file=sys.stderr)
        run_session(store, sid, progress=_progress(args))
        if store.session(sid)["status"] == "completed":
            recorded += _record_file_answers(store, sid, args.answers, ("post",))
        print(_session_line(store, sid))
        _print_next_sitting(store, sid)
        if recorded:
            print(f"questionnaires recorded: {', '.join(recorded)}")
    return 0


def _cmd_resume(args: argparse.Namespace) -> int:
    from vasim.study.session import find_session, run_session
    from vasim.study.store import TrialStore

    name, given = _protocol_ref(args.protocol)
    with TrialStore(_existing_db(args.db)) as store:
        sid = find_session(store, subject=args.subject, session_id=args.session,
                           protocol=name)
        note = stored_protocol_note(store, sid, given)
        if note:
            print(note, file=sys.stderr)
        if store.recovered:
            print(f"marked interrupted (writer gone): trials {store.recovered}",
                  file=sys.stderr)
        n = run_session(store, sid, progress=_progress(args),
                        simulate_delay=args.simulate_delay)
        recorded = []
        if store.session(sid)["status"] == "completed":
            recorded = _record_file_answers(store, sid, args.answers, ("pre", "post"),
                                            skip_answered=True)
        print(f"{n} trial(s) run")
        print(_session_line(store, sid))
        _print_next_sitting(store, sid)
        if recorded:
            print(f"questionnaires recorded: {', '.join(recorded)}")
    return 0


def _protocol_ref(ref: str | None) -> tuple[str | None, Path | None]:
    """``resume --protocol``: (the protocol name sessions are stored under, the file it
    names if it is a path). A path's name is read from the file (its stem if the file no
    longer parses)."""
    if ref is None:
        return None, None
    p = Path(ref)
    if p.suffix != ".toml" and not p.is_file():
        return ref, None
    from vasim.study.protocol import load_protocol

    try:
        return load_protocol(p).name, p
    except ConfigError:
        return p.stem, p


def stored_protocol_note(store: object, session_id: int, given: Path | None) -> str | None:
    """A note when the protocol file (``given``, else the shipped file of the stored name)
    differs from the text stored with the session, else None (issue #30 item 8).

    **Decision**: a resumed session always runs the protocol stored with it (the module
    docstring of :mod:`vasim.study.session`); an edited file is not an error, but the
    experimenter is told which protocol runs, and how to run the edited one.
    """
    import hashlib

    from vasim.study.protocol import protocol_path
    from vasim.study.store import TrialStore

    assert isinstance(store, TrialStore)
    row = store.session(session_id)
    try:
        path = given if given is not None else protocol_path(str(row["protocol"]))
        text = path.read_text(encoding="utf-8")
    except (ConfigError, OSError, UnicodeDecodeError):
        return None      # no file of that name here: nothing to compare
    if hashlib.sha256(text.encode("utf-8")).hexdigest() == row["protocol_sha256"]:
        return None
    return (f"note: {path} has changed since session {session_id} started "
            f"({str(row['created_at'])[:19]}); the session resumes with the protocol stored "
            "with it, as it was then (to run the edited file, abort this session and start "
            "a new one with `vasim study run`)")


def _cmd_list(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore

    with TrialStore(_existing_db(args.db), readonly=True) as store:
        df = store.sessions(subject=args.subject)
    if df.empty:
        print(f"no sessions in {args.db}")
        return 0
    df = df.assign(progress=[f"{c}/{n}" for c, n in zip(df["n_completed"], df["n_trials"],
                                                        strict=True)],
                   next=[("-" if i < 0 else str(i)) for i in df["next_index"]],
                   created=[str(c)[:19] for c in df["created_at"]])
    cols = ["id", "subject", "protocol", "status", "progress", "n_interrupted", "next",
            "seed", "operator", "created"]
    if "notes" in df and df["notes"].notna().any():   # e.g. why a session was run --again
        df = df.assign(notes=df["notes"].fillna("-"))
        cols.append("notes")
    print(df[cols].rename(columns={"n_interrupted": "interrupted"}).to_string(index=False))
    return 0


def _cmd_export(args: argparse.Namespace) -> int:
    from vasim.study.export import EXPORT_TABLES, export_study

    formats = [f.strip() for f in args.format.split(",") if f.strip()]
    tables = EXPORT_TABLES if args.tables is None else tuple(
        t.strip() for t in args.tables.split(",") if t.strip())
    out = export_study(_existing_db(args.db), args.out, formats=formats, tables=tables,
                       progress=_progress(args))
    import json

    manifest = json.loads((out / "manifest.json").read_text(encoding="utf-8"))
    for name, info in manifest["tables"].items():
        print(f"{name:<16} {info['rows']:>10} rows  {', '.join(info['files'].values())}")
    n_free = manifest.get("trials_without_subject", 0)
    if n_free:
        print(f"{n_free} completed trial(s) without a subject: in trials/samples only, left "
              "out of the subject analyses (trial_metrics, point_metrics)")
    print(f"written to {out}")
    return 0


def _cmd_simulate(args: argparse.Namespace) -> int:
    from vasim.operator.scenario import load_scenario, scenario_path
    from vasim.study.cohort import (
        CohortPlan,
        CohortRun,
        check_scenario_kind,
        default_scenario_for,
        simulate_cohort,
    )
    from vasim.study.protocol import load_protocol

    protocol = load_protocol(args.protocol)
    protocol.check_runnable()
    if args.scenario is None:
        scenario = default_scenario_for(protocol)
    else:
        scenario = load_scenario(args.scenario)
        check_scenario_kind(protocol, scenario, scenario_path(args.scenario))
    surgeons = args.surgeons
    if surgeons is None:
        surgeons = round(args.subjects * 31 / 46)  # the VF study: 31 surgeons of 46
    rep = simulate_cohort(
        _new_db(args.db), protocol,
        CohortPlan(n_subjects=args.subjects, n_surgeons=surgeons, seed=args.seed,
                   scenario=scenario, effect_scale=args.effect_scale,
                   max_trial_time=args.max_time),
        CohortRun(workers=args.workers, progress=_progress(args)))
    print(f"cohort of {_count(rep.subjects, 'subject')} ({_count(surgeons, 'surgeon')}), "
          f"seed {args.seed}, scenario {scenario.name} ({scenario.sha256[:12]}) x "
          f"{args.effect_scale:g}: "
          f"{rep.sessions_completed} sessions completed, {rep.trials_run} trials run now")
    print(f"simulated {rep.sim_seconds:.1f} s in {rep.wall_seconds:.1f} s wall with "
          f"{rep.workers} worker(s): {rep.realtime_ratio:.1f}x real time")
    return 0


def _count(n: int, noun: str) -> str:
    """``3 subjects``, ``1 subject``."""
    return f"{n} {noun}{'' if n == 1 else 's'}"


def _cmd_schedule(args: argparse.Namespace) -> int:
    from vasim.study.protocol import block_of, day_offsets, generate_schedule, load_protocol

    protocol = load_protocol(args.protocol)
    rows = generate_schedule(protocol, args.seed, sequence=args.sequence)
    print(f"{protocol.name}: {len(rows)} trials, seed {args.seed}")
    print(f"{'index':>5}  {'block':<16} {'condition':<16} {'variant':>7}  probe")
    from vasim.study.gain_plan import gain_text

    days = day_offsets(protocol, rows)
    for t in rows:
        probe = f"VF-free #{t.probe_index}" if t.probe else gain_text(protocol, t)
        b = block_of(protocol, t.block)
        extra = [b.phase] if b.phase != "acquisition" else []
        extra += [f"day {days[t.index]:g}"] if days[t.index] else []
        if b.gate is not None and not t.probe:
            extra.append(f"gated: repeats up to {b.gate.max_trials}")
        note = f"  ({', '.join(extra)})" if extra else ""
        print(f"{t.index:>5}  {t.block:<16} {t.condition:<16} {t.variant:>7}  {probe}{note}")
    print()
    for line in _design_lines(protocol, rows, args.seed if args.sequence is None
                              else args.sequence):
        print(line)
    return 0


def _design_lines(protocol: Any, rows: list[Any], sequence: int) -> list[str]:
    """The design of the printed schedule: block-order sequence and probe-variant rotation
    (issue #25; ``vasim.study.protocol`` schedule rules)."""
    from vasim.study.protocol import williams_square

    blocks = [t.block for i, t in enumerate(rows) if i == 0 or rows[i - 1].block != t.block]
    n_cb = sum(b.counterbalance for b in protocol.blocks)
    order = ", ".join(dict.fromkeys(blocks))
    if protocol.block_order == "latin_square" and n_cb >= 2:
        r = len(williams_square(n_cb))
        head = (f"block order: Williams sequence {sequence % r + 1} of {r} (sequence number "
                f"{sequence} mod {r}): {order}")
    else:
        head = f"block order ({protocol.block_order}): {order}"
    out = [head]
    vs = protocol.probe_variants
    if vs is not None:
        probes = " ".join(str(t.variant) for t in rows if t.probe)
        out.append(f"VF-free trials: variants {probes} (rotation over "
                   f"{', '.join(map(str, vs))} from offset {sequence % len(vs)}; "
                   "balanced across subjects)")
    else:
        out.append(f"VF-free trials: variant {protocol.probe_variant} (no rotation)")
    return out


def _cmd_answer(args: argparse.Namespace) -> int:
    from vasim.study.store import TrialStore

    with TrialStore(_existing_db(args.db)) as store:
        store.session(args.session)
        done = _record_file_answers(store, args.session, args.file, ("pre", "post"))
    print(f"recorded: {', '.join(done) if done else 'nothing (no [pre] or [post] table)'}")
    return 0


def _cmd_abort(args: argparse.Namespace) -> int:
    from vasim.study.session import abort_session
    from vasim.study.store import TrialStore

    with TrialStore(_existing_db(args.db)) as store:
        abort_session(store, args.session, args.reason)
        print(_session_line(store, args.session))
    return 0
