"""``vasim devices``: which input/force devices can be used here, and what the others lack.

``register(subparsers)`` adds the subcommand. Exit code 0 whatever is available (a missing
device is information, not an error); ``--json`` prints a machine-readable list.
"""

from __future__ import annotations

import argparse
import json
import sys

from vasim.haptics.devices import Availability, DeviceInfo, probe_all

_EPILOG = """\
For each device that is not available, the lines below it say exactly what is missing:
a Python package, a runtime library, or the hardware, and how to get it.

examples:
  vasim devices
  vasim devices --json
"""


def register(subparsers: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Adds ``vasim devices`` to the ``vasim`` command line."""
    p = subparsers.add_parser(
        "devices",
        help="list the haptic/input devices and what the unavailable ones need",
        description="List the input/force devices (emulator, scripted operator, browser, "
                    "replay, OpenHaptics Phantom Omni / Touch): available or not, and for "
                    "each unavailable one what is missing (package, runtime library, "
                    "hardware).",
        epilog=_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("--json", action="store_true", help="print a JSON list instead of a table")
    p.set_defaults(func=cmd_devices)


def _report(rows: list[tuple[DeviceInfo, Availability]]) -> list[dict[str, object]]:
    return [{"name": info.name, "summary": info.summary, **avail.to_dict()}
            for info, avail in rows]


def cmd_devices(args: argparse.Namespace) -> int:
    """Prints the device table (or JSON); always exits 0."""
    out = getattr(args, "out", None) or sys.stdout
    rows = probe_all()
    if args.json:
        print(json.dumps(_report(rows), indent=2), file=out)
        return 0
    width = max(len(info.name) for info, _ in rows)
    for info, avail in rows:
        status = "available" if avail.available else "unavailable"
        print(f"{info.name:<{width}}  {status:<11}  {info.summary}", file=out)
        pad = " " * (width + 2)
        if avail.detail:
            print(f"{pad}{avail.detail}", file=out)
        for m in avail.missing:
            print(f"{pad}missing {m.kind}: {m.what} -- {m.hint}", file=out)
    return 0


__all__ = ["cmd_devices", "register"]
