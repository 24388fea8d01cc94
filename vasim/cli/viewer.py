"""``vasim serve``: the browser training viewer.

It starts in demo mode (a scripted operator plays trials in real time); the page's
Experimenter tab switches to free training or a protocol session (stored in ``--db``), picks
the schema and edits its f5PL curves, and shows progress, live metrics and the learning
curve; the Trainee tab shows the abdomen, the tool, the task and the fixture overlays.
"""

from __future__ import annotations

import argparse
import signal
import sys
import threading
import time
from pathlib import Path
from typing import Any

from vasim.cli.args import bounded_float, bounded_int, host_address
from vasim.core.bounds import DURATION_S, PORT, SEED
from vasim.core.errors import InputError


def register(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``vasim serve`` to the ``vasim`` command line."""
    p = sub.add_parser(
        "serve", formatter_class=_ServeHelpFormatter,
        help="start the browser training viewer (trainee view and experimenter panel)",
        description=(
            "Serve the training viewer: the trainee's view (the deforming abdomen, the tool, "
            "the task and the fixture overlays, AG audible in the page) and the "
            "experimenter's panel (subject, protocol, progress, start/stop, schema with live "
            "f5PL editing, metrics, learning curve). Open the printed URL in a browser; "
            "Ctrl-C stops the server."
        ),
    )
    p.add_argument("--host", type=host_address, default="127.0.0.1",
                   help="interface to bind (default 127.0.0.1: this machine only; any other "
                        "address needs --expose)")
    p.add_argument("--expose", action="store_true",
                   help="allow a --host beyond this machine; every page then needs the "
                        "access token printed with its URL (the trainee's and the "
                        "experimenter's pages have different tokens)")
    p.add_argument("--port", type=bounded_int(PORT), default=8080,
                   help="TCP port (default 8080; if busy, the next free port is used and "
                        "printed; 0 picks any free port)")
    p.add_argument("--experimenter-port", type=bounded_int(PORT), default=None,
                   metavar="PORT",
                   help="TCP port of the experimenter's page (default: --port + 1; the "
                        "trainee's page is on --port)")
    p.add_argument("--optics", type=int, choices=[0, 30], default=0,
                   help="the trainee's endoscope optics in degrees (0: forward-viewing, "
                        "30: angled; default 0; stored with every trial)")
    p.add_argument("--scene", default="default",
                   help="abdomen scene of every trial, a name in protocols/scenes or a file "
                        "(default: default; none: a static task without physics); or an "
                        "MRCP slave-station scenario served live with its MRCP panel: "
                        "{mrcp_scenes}")
    p.add_argument("--db", default=None, metavar="FILE",
                   help="study database (SQLite) that trials run from the viewer are stored "
                        "in, like headless ones (default: none: demo mode only)")
    p.add_argument("--protocol", default=None, metavar="NAME",
                   help="open the experimenter's page in protocol mode with this study "
                        "protocol chosen (a name in protocols/studies, e.g. "
                        "mrcp_suture_dynamic; needs --db); the experimenter enters the "
                        "subject code and starts the session")
    p.add_argument("--schema", default=None,
                   help="fixture schema of the demo trials, a name in protocols/schemas "
                        "(default: trajectory_following, or point_targeting with --task point)")
    p.add_argument("--task", choices=["trajectory", "point"], default="trajectory",
                   help="task of the demo trials (default trajectory)")
    p.add_argument("--seed", type=bounded_int(SEED), default=0,
                   help="operator seed of the first trial")
    p.add_argument("--skill", choices=["novice", "intermediate", "expert"],
                   default="intermediate", help="scripted operator preset")
    p.add_argument("--duration", type=bounded_float(DURATION_S), default=None,
                   metavar="SECONDS",
                   help="stop after this many seconds (default: run until Ctrl-C)")
    p.add_argument("--mrcp-coarse", action="store_true",
                   help="MRCP scenes: the runner's cheaper 36 ms cycle (keeps real time on a "
                        "slow machine; default: the seed's 18 ms cycle)")
    p.set_defaults(func=serve)


class _ServeHelpFormatter(argparse.HelpFormatter):
    """Fills ``{mrcp_scenes}`` in a help string with the registered MRCP scenarios, only
    when help is printed (listing them imports the MRCP kernel: ~1 s)."""

    def _get_help_string(self, action: argparse.Action) -> str | None:
        text = super()._get_help_string(action)
        if text and "{mrcp_scenes}" in text:
            from vasim.viewer.mrcp_panel import scenario_help

            text = text.replace("{mrcp_scenes}", scenario_help())
        return text


def exposure_warning(host: str, port: int) -> str | None:
    """The warning printed for a non-loopback bind address, or None for loopback."""
    from vasim.viewer.access import is_loopback

    if is_loopback(host):
        return None
    where = "every network interface" if host in ("0.0.0.0", "::", "") else host
    return (f"warning: --host {host} exposes the viewer on {where} (port {port}): anyone who "
            "can reach this machine and has the URL with its token can watch the trial and "
            "use its controls; use --host 127.0.0.1 unless you mean to")


def serve(args: argparse.Namespace) -> int:
    """Runs ``vasim serve`` with parsed arguments; returns the exit code.

    Raises:
        VasimError: for a bad schema/task (the caller prints it as one line).
    """
    from vasim.viewer.access import is_loopback, new_token
    from vasim.viewer.app import (
        DEFAULT_SCHEMA_FOR_TASK,
        PageAccess,
        TrialOptions,
        ViewerApp,
        check_bind_address,
    )

    check_bind_address(args.host, args.port)  # a bad address is the error, not a warning
    token: str | None = None
    if not is_loopback(args.host):
        if not getattr(args, "expose", False):
            raise InputError(f"--host {args.host} exposes the viewer beyond this machine; add "
                             "--expose to confirm (every page then needs an access token)",
                             field="--host")
        token = new_token()
    warning = exposure_warning(args.host, args.port)
    if warning:
        print(warning, file=sys.stderr, flush=True)
    from vasim.viewer.mrcp_panel import MrcpViewerApp, scenario_from_scene

    scene = getattr(args, "scene", "default")
    app: ViewerApp | MrcpViewerApp
    if scenario_from_scene(scene) is not None:
        ignored = [f"--{k}" for k in ("db", "schema") if getattr(args, k, None)]
        if ignored:
            print(f"note: {', '.join(ignored)} do not apply to an MRCP scene (no trainee "
                  "trials): ignored", file=sys.stderr)
        app = MrcpViewerApp(args.host, args.port, scene, seed=args.seed,
                            coarse=bool(getattr(args, "mrcp_coarse", False)), token=token)
        what = (f"MRCP scenario {app.scenario.name}, seed {args.seed}, "
                f"{'36' if getattr(args, 'mrcp_coarse', False) else '18'} ms cycle, looping")
    else:
        schema = args.schema or DEFAULT_SCHEMA_FOR_TASK[args.task]
        protocol = check_protocol(getattr(args, "protocol", None), getattr(args, "db", None))
        if getattr(args, "db", None):
            check_db(Path(args.db))
        trials = TrialOptions(schema=schema, seed=args.seed, task=args.task, skill=args.skill,
                              optics=float(getattr(args, "optics", 0)))
        access = PageAccess(token=token,
                            experimenter_port=getattr(args, "experimenter_port", None))
        app = ViewerApp(args.host, args.port, scene=scene, db=getattr(args, "db", None),
                        trials=trials, access=access)
        db = getattr(args, "db", None)
        stored = f"trials stored in {db}" if db else "demo only: no --db"
        what = f"schema {schema}, task {args.task}, scene {scene}, {stored}"
        if protocol is not None:   # queued: the controller thread applies them at start
            from vasim.viewer.controller import Command

            app.submit(Command("mode", "protocol"))
            app.submit(Command("protocol", protocol))
            what = f"protocol {protocol}, scene {scene}, {stored}"
    app.start()
    previous = _stop_on_sigterm()
    try:
        if app.port != args.port and args.port != 0:
            print(f"port {args.port} is busy; using {app.port}", file=sys.stderr)
        exp_url = getattr(app, "experimenter_url", None)
        pages = f"trainee {app.url}, experimenter {exp_url}" if exp_url else app.url
        print(f"vasim viewer: {pages}  ({what}; Ctrl-C stops)", flush=True)
        t_end = None if args.duration is None else time.monotonic() + args.duration
        while t_end is None or time.monotonic() < t_end:
            time.sleep(0.2)
            if not app.alive():
                print("vasim serve: a viewer thread stopped unexpectedly; see the log",
                      file=sys.stderr)
                return 1
    except KeyboardInterrupt:
        print("vasim serve: stopping", file=sys.stderr)
    finally:
        app.stop()
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)
    return 0


def check_protocol(name: str | None, db: str | None) -> str | None:
    """``--protocol``: a shipped study protocol, with a ``--db`` to store its trials.

    Raises:
        ConfigError: an unknown protocol (the known ones listed) or no ``--db``.
    """
    if name is None:
        return None
    from vasim.study.protocol import available_protocols

    known = available_protocols()
    if name not in known:
        raise InputError(f"unknown protocol {name!r} (available: {', '.join(known)})",
                         field="--protocol")
    if not db:
        raise InputError("--protocol needs --db FILE (a session's trials are stored there)",
                         field="--protocol")
    return name


def check_db(path: Path) -> None:
    """Opens the viewer's study database for writing once, before the server starts, so
    that a garbage file, a newer vasim's store or a read-only file is refused at once (one
    line naming the file) rather than at the first trial; a missing file is created.

    Raises:
        StoreError: the file cannot serve as a writable vasim store.
    """
    from vasim.study.store import TrialStore

    TrialStore(path).close()


def _stop_on_sigterm() -> Any:
    """Makes SIGTERM stop the server like Ctrl-C (main thread only); returns the old handler."""
    if threading.current_thread() is not threading.main_thread():
        return None

    def handler(signum: int, frame: object) -> None:
        raise KeyboardInterrupt

    return signal.signal(signal.SIGTERM, handler)


__all__ = ["check_db", "exposure_warning", "register", "serve"]
