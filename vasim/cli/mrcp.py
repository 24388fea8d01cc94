"""``vasim mrcp``: run the seed's MRCP scenarios and show why the task changed hands.

``vasim mrcp run SCENARIO [--plot out.png] [--seed N] [--json]`` runs a scripted scenario
through the MRCP kernel and prints its event log (each task transfer with the robot giving
and receiving the task, the grasp point, NTT and the cause: the index whose ``texec`` was
the smallest), then the invariant checks; ``--plot`` saves the Figs. 4.23-4.26-style plot.
``vasim mrcp list`` names the scenarios. Exit code 1 when an invariant was violated or a
safety stop ended the run (its cause is printed).
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, TextIO

from vasim.cli.args import bounded_float, bounded_int
from vasim.core.bounds import DURATION_S, SEED
from vasim.core.config import check_dir, check_int, check_number, expect
from vasim.core.errors import InputError
from vasim.core.jsonio import dumps
from vasim.trials.kinds import MAX_TRIAL_TIME_S

_EPILOG = """\
examples:
  vasim mrcp list
  vasim mrcp run cube_rotation
  vasim mrcp run cube_translation --plot translation.png
  vasim mrcp run faucet --seed 3 --json
  vasim mrcp run suture_combined --coarse --json
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``vasim mrcp`` to the ``vasim`` command line."""
    p = subparsers.add_parser(
        "mrcp",
        help="run the multi-robot cooperative platform (MRCP) scenarios of the seed",
        description="MRCP: one operator moves the task; the kernel evaluates every robot, "
                    "picks the best one to continue and hands the task over in time.",
        epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = p.add_subparsers(dest="mrcp_command", metavar="ACTION", required=True)
    ls = sub.add_parser("list", help="list the scenarios")
    ls.set_defaults(func=cmd_list)
    r = sub.add_parser("run", help="run a scenario and print its transfer log",
                       description="Run a scripted scenario through the MRCP kernel.")
    r.add_argument("scenario", help="scenario name (see `vasim mrcp list`)")
    r.add_argument("--plot", metavar="PATH", help="save the indices/texec/ttransf*/NTT/RSel "
                   "plot (PNG, PDF or SVG by suffix)")
    r.add_argument("--seed", type=bounded_int(SEED), default=0,
                   help="seed of the planner's random force")
    r.add_argument("--duration", type=bounded_float(DURATION_S, gt=0.0), default=None,
                   help="run length [s] (default: the scenario's)")
    r.add_argument("--coarse", action="store_true", help="cheaper run: 36 ms period (same "
                   "prediction and texec windows in seconds), first-order trajectory IK")
    r.add_argument("--json", action="store_true", help="print the run summary as JSON")
    r.set_defaults(func=cmd_run)


def cmd_list(args: argparse.Namespace) -> int:
    from vasim.mrcp.scenarios import SCENARIOS

    out: TextIO = getattr(args, "out", None) or sys.stdout
    width = max(len(n) for n in SCENARIOS)
    for name, sc in SCENARIOS.items():
        print(f"{name:<{width}}  {sc.summary}", file=out)
    return 0


def format_events(events: list[tuple[float, str]]) -> list[str]:
    """Event lines; a run of identical consecutive events collapses into one line.

    Example:
        >>> format_events([(0.1, "a"), (0.2, "rsel_hold R1: x"), (0.3, "rsel_hold R1: x")])
        ['t=  0.100  a', 't=  0.200  rsel_hold R1: x  (x2, until t=0.300)']
    """
    lines: list[str] = []
    i = 0
    while i < len(events):
        t, e = events[i]
        j = i
        while j + 1 < len(events) and events[j + 1][1] == e:
            j += 1
        extra = f"  (x{j - i + 1}, until t={events[j][0]:.3f})" if j > i else ""
        lines.append(f"t={t:7.3f}  {e}{extra}")
        i = j + 1
    return lines


PLOT_SUFFIXES = (".png", ".pdf", ".svg")


def check_plot_path(path: Path) -> None:
    """Refuses a plot path whose format is unknown or whose folder does not exist.

    Example:
        >>> check_plot_path(Path("run.txt"))  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        vasim.core.errors.InputError: field '--plot': got 'run.txt', expected a .png, .pdf \
or .svg file
    """
    expect(path.suffix.lower() in PLOT_SUFFIXES, str(path), "a .png, .pdf or .svg file",
           field="--plot", error=InputError)
    check_dir(path.parent, "--plot", what="an existing folder for the plot")


def cmd_run(args: argparse.Namespace) -> int:
    from vasim.mrcp.scenarios import get_scenario
    from vasim.mrcp.scenarios.base import ScenarioOptions
    from vasim.mrcp.scenarios.runner import run

    out: TextIO = getattr(args, "out", None) or sys.stdout
    if args.duration is not None:
        check_number(args.duration, "--duration", gt=0.0, le=MAX_TRIAL_TIME_S,
                     error=InputError)
    check_int(args.seed, "--seed", lo=0, error=InputError)
    if args.plot:
        check_plot_path(Path(args.plot))      # before the run, not after it
    scenario = get_scenario(args.scenario)
    opts = ScenarioOptions(seed=args.seed, duration=args.duration, coarse=args.coarse)
    res = run(scenario, opts)
    summary: dict[str, Any] = res.to_dict()
    if args.plot:
        from vasim.mrcp.plots import plot_run

        summary["plot"] = str(plot_run(res, args.plot))
    failed = bool(res.violations) or res.stop is not None
    if args.json:
        print(dumps(summary, indent=2), file=out)       # strict JSON: inf/NaN -> null
        return 1 if failed else 0
    print(f"scenario {res.scenario}: {scenario.summary}", file=out)
    print(f"{len(res.samples)} cycles, {summary['duration']:.2f} s, robots "
          f"{', '.join(res.robots)}", file=out)
    print("events:", file=out)
    for line in format_events(res.events()):
        print(f"  {line}", file=out)
    print("transfers:", file=out)
    for k, tr in enumerate(res.transfers(), 1):
        done = f"done t={tr['t_done']:.3f}" if tr["t_done"] is not None else "not completed"
        print(f"  #{k} t={tr['t_start']:.3f} {tr['from']} -> {tr['to']}@{tr['point']} "
              f"cause={tr['cause']} ntt={tr['ntt']:.2f} ({done})", file=out)
    if not res.transfers():
        print("  none", file=out)
    if summary.get("subtasks"):        # a scenario with a state graph (suture_combined)
        print("subtasks:", file=out)
        for st in summary["subtasks"]:
            where = f" (stitch {st['stitch']})" if st.get("stitch") else ""
            print(f"  {st['t_start']:7.3f} - {st['t_end']:7.3f}  {st['mode']:<5} "
                  f"{st['name']}{where}", file=out)
    if res.stop is not None:
        print(f"SAFETY STOP {res.stop}: the run ended there (no operator to acknowledge it)",
              file=out)
    print(res.invariant_summary() + (":" if res.violations else ""), file=out)
    for v in res.violations[:20]:
        print(f"  {v}", file=out)
    if args.plot:
        print(f"plot: {summary['plot']}", file=out)
    return 1 if failed else 0
