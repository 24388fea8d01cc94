"""``vasim study power``: power of the VF study's tests against the subject count (the
PRIMARY post-block probe model and the seed's RM-ANOVAs),
from Monte Carlo cohorts of a declared scenario's operator on Ray (issue #18 item 5;
:mod:`vasim.study.power`). Registered by :mod:`vasim.cli.study` under ``vasim study``."""

from __future__ import annotations

import argparse
import contextlib
from collections.abc import Iterator
from pathlib import Path

from vasim.cli.args import bounded_float, bounded_int, output_folder, workers
from vasim.core.bounds import ALPHA, COHORTS, EFFECT_SCALE, SEED, TRIAL_TIME_S


def register_power(ss: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """``vasim study power`` (issue #18 item 5; :mod:`vasim.study.power`)."""
    r = ss.add_parser(
        "power", help="power of the primary tests against N, from simulated cohorts (Ray)",
        description=(
            "Simulate --cohorts cohorts of the scripted operator of --scenario at each subject "
            "count of --subjects, analyse each as the report does -- the PRIMARY analysis, "
            "the post-block probe model (nested F test of the fixture just practised, with "
            "block position and variant; docs/study-design.md), and the seed's RM-ANOVAs "
            "(fixture effect and practice effect), each on path deviation, latency and eq. "
            "6.5's e -- and print the power of each test (share of cohorts with p < alpha) "
            "with its "
            "Monte Carlo standard error sqrt(p(1-p)/cohorts); --out gets power.csv, "
            "power_cohorts.csv and power.png. Runs on a local Ray (127.0.0.1), the cluster "
            "--address names (both need the cluster extra) or a local process pool; no "
            "study database is written unless --keep-cohorts."))
    r.add_argument("--protocol", required=True,
                   help="protocol name (protocols/studies) or TOML path")
    r.add_argument("--subjects", required=True,
                   help="subject counts: START:STOP:STEP (e.g. 10:60:5), N1,N2,... or N")
    r.add_argument("--cohorts", type=bounded_int(COHORTS), default=200,
                   help="Monte Carlo cohorts per N (default 200: power to +-0.035 at 0.5)")
    r.add_argument("--effect-scale", type=bounded_float(EFFECT_SCALE), default=None,
                   help="x the scenario's fixture effects and mechanism gain (1: as "
                        "declared; 0: none, the fixture tests' type-I error; 0.5: half); "
                        "default: the protocol's [power] effect_scale, else 1")
    r.add_argument("--effects", type=Path, default=None, metavar="FILE.toml",
                   help="fixture effects by condition label ([ff] accuracy = 0.8, speed, "
                        "practice_weight, carryover, dependence), applied over the "
                        "protocol's [power.effects]; unset fields keep those (else the "
                        "scenario's); --effect-scale applies on top")
    r.add_argument("--scenario", default="seed_plausible", metavar="NAME|FILE.toml",
                   help="the declared scenario of the simulated operator (subjects, groups, "
                        "fixture effects and mechanisms): a name in protocols/scenarios "
                        "(seed_plausible, null) or a TOML file, as `vasim study simulate`")
    r.add_argument("--alpha", type=bounded_float(ALPHA), default=0.05,
                   help="significance level (default 0.05)")
    r.add_argument("--p", choices=["gg", "uncorrected"], default="gg",
                   help="p-value the seed's RM-ANOVAs reject on: Greenhouse-Geisser "
                        "(default) or uncorrected (the primary probe model's F test has "
                        "one p, used either way)")
    r.add_argument("--coarse", action="store_true",
                   help="2 ms control step instead of 1 ms, ~1.5x faster: dry runs and the "
                        "practice effect only (the per-trial means stay within 10 %%, but the "
                        "fixture effects shrink: docs/researcher.md, 'Power planning')")
    r.add_argument("--seed", type=bounded_int(SEED), default=7, help="base seed (default 7)")
    r.add_argument("--max-time", type=bounded_float(TRIAL_TIME_S, gt=0.0), default=None,
                   help="trial time limit [s] (default: the protocol's)")
    r.add_argument("--address", type=ray_address, default=None,
                   help="Ray cluster to join (HEAD:6379 on a node of it, ray://HEAD:10001 "
                        "from anywhere, or auto on a node); checked first (it must answer "
                        "within a few seconds); default: a local Ray on this machine")
    r.add_argument("--workers", type=workers, default=None,
                   help="CPUs of the local Ray or processes of the local pool (default: "
                        "number of cores)")
    # the values of vasim.study.power.backend.BACKENDS (not imported: keeps `--help` quick)
    r.add_argument("--backend", choices=("auto", "ray", "processes"), default="auto",
                   help="where cohorts run: ray (needs the cluster extra), processes (a "
                        "local pool) or auto (default: Ray when installed, else processes)")
    r.add_argument("--out", type=output_folder, default=None,
                   help="folder for power.csv, power_cohorts.csv and power.png")
    r.add_argument("--keep-cohorts", type=Path, default=None, metavar="DIR",
                   help="write each cohort's study database into DIR (default: none)")
    r.add_argument("--no-progress", action="store_true",
                   help="no progress output (default: a bar on a terminal, a line every 15 s "
                        "in a log file)")
    r.set_defaults(func=_cmd_power)


def ray_address(text: str) -> str:
    """``--address``: the syntax of a Ray address (``vasim.study.power.driver
    .parse_ray_address``), refused at parse time with exit code 2 (``''`` included)."""
    from vasim.core.errors import FieldError
    from vasim.study.power.driver import parse_ray_address

    try:
        parse_ray_address(text)
    except FieldError as exc:
        raise argparse.ArgumentTypeError(exc.reason) from None
    return text


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM ends a power run like Ctrl-C (``KeyboardInterrupt``: Ray is shut down in the
    driver's ``finally`` and the command exits 130), where it would otherwise kill the
    driver without that (issue #30 item 4); the previous handler is restored afterwards
    (the command may run inside another program, e.g. a test process)."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt(f"signal {signum}")

    previous = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _cmd_power(args: argparse.Namespace) -> int:
    from vasim.operator.scenario import load_scenario
    from vasim.study.power.design import (
        COARSE_DT,
        COARSE_WARNING,
        FULL_DT,
        PowerDesign,
        load_effects,
        parse_subjects,
    )
    from vasim.study.power.driver import run_power
    from vasim.study.power.output import format_table, write_outputs
    from vasim.study.protocol import load_protocol
    from vasim.study.protocol.power import resolve_effects

    scenario = load_scenario(args.scenario)
    protocol = load_protocol(args.protocol)
    protocol.check_runnable()
    # Decision (vasim.study.protocol.power): scenario < protocol [power] < command line
    scale, base = resolve_effects(protocol.power, cli_scale=args.effect_scale,
                                  base=scenario.fixtures)
    if args.effects is not None:
        base = load_effects(args.effects, base=base)
        check_effects_labels(args.effects, protocol.name, protocol.conditions)
    sources = effect_sources(protocol.power is not None and bool(protocol.power.effects),
                             args.effects)
    design = PowerDesign(subjects=parse_subjects(args.subjects), cohorts=args.cohorts,
                         seed=args.seed, effect_scale=scale, alpha=args.alpha,
                         dt=COARSE_DT if args.coarse else FULL_DT,
                         max_trial_time=args.max_time,
                         p_column="p_gg" if args.p == "gg" else "p_unc", base_effects=base,
                         scenario=scenario)
    if args.out is not None:   # before the run: a bad --out must not waste the cohorts
        args.out.mkdir(parents=True, exist_ok=True)
    with _sigterm_as_interrupt():
        res = run_power(protocol, design, address=args.address, workers=args.workers,
                        keep_dir=args.keep_cohorts, progress=not args.no_progress,
                        backend=args.backend)
    step = "coarse 2 ms" if args.coarse else "full 1 ms"
    print(f"power of {protocol.name}'s tests: the PRIMARY post-block probe model (fixture "
          "practised -> next VF-free probe) and the seed's RM-ANOVAs, secondary")
    print(f"(synthetic: scripted operator of "
          f"scenario {scenario.name} ({scenario.sha256[:12]}){sources}, effect scale "
          f"{scale:g}, {step} step, "
          f"alpha {args.alpha:g}, {'Greenhouse-Geisser' if args.p == 'gg' else 'uncorrected'}"
          f" p; {args.cohorts} cohorts per N; ± = Monte Carlo standard error)")
    print(format_table(res.power))
    if args.coarse:
        print(f"warning: {COARSE_WARNING}")
    print(f"{res.n_trials} trials ({res.sim_seconds:.0f} s simulated) in "
          f"{res.wall_seconds:.1f} s wall on {res.workers} CPU(s) "
          f"({'cluster ' + res.address if res.address else _LOCAL[res.backend]}): "
          f"{res.cohorts_per_second:.3g} cohorts/s")
    if args.out is not None:
        title = (f"{protocol.name}: power of the primary tests, {args.cohorts} cohorts per N, "
                 f"effect scale {scale:g}, alpha {args.alpha:g}"
                 + (" (coarse 2 ms step: fixture power underestimated)" if args.coarse
                    else ""))
        for path in write_outputs(args.out, res.power, res.cohorts, title=title):
            print(f"wrote {path}")
    return 0


_LOCAL = {"ray": "local Ray", "processes": "local processes"}
"""How the summary line names a local run's backend."""


def check_effects_labels(path: Path, protocol: str, conditions: tuple[str, ...]) -> None:
    """Refuses an ``--effects`` table whose label is not a condition of the protocol.

    **Decision** (issue #30 item 6): as a protocol's own ``[power.effects]`` labels are
    (``vasim.study.protocol.power``): a misspelt label (``[f]`` for ``[ff]``) was silently
    unused, and the run then reported power for the scenario's effects as if the file's.
    A file shared between protocols must therefore hold only labels of the protocol it is
    given with.

    Raises:
        ConfigError: naming the file, the label and the protocol's conditions.
    """
    from vasim.core.config import fail, parse_toml

    data = parse_toml(path.read_text(encoding="utf-8"), file=path, kind="effects")
    for label in data:
        if label not in conditions:
            raise fail(label, f"a condition of protocol {protocol!r} ({', '.join(conditions)}); "
                       "remove or rename that table", field=str(label), file=path)


def effect_sources(protocol_effects: bool, effects_file: Path | None) -> str:
    """What the header names besides the scenario: the protocol's ``[power.effects]``
    and the ``--effects`` file, when used.

    >>> effect_sources(True, Path("e.toml"))
    ", effects of the protocol's [power] and e.toml"
    >>> effect_sources(False, None)
    ''
    """
    parts = (["the protocol's [power]"] if protocol_effects else []) + (
        [str(effects_file)] if effects_file is not None else [])
    return f", effects of {' and '.join(parts)}" if parts else ""


__all__ = ["check_effects_labels", "effect_sources", "ray_address", "register_power"]
