"""Argument types of the command line, bounded at parse time (``argparse`` ``type=``).

A number outside its plausibility bound (:mod:`vasim.core.bounds`), an invalid subject
code or bind address is refused by argparse before any work starts (before a cohort
allocates memory or a server prints its exposure warning), with the toolkit's wording
``got <value>, expected <what>`` and long values truncated.
"""

from __future__ import annotations

import argparse
import ipaddress
import re
from collections.abc import Callable
from pathlib import Path

from vasim.core.bounds import Bound, workers_bound
from vasim.core.config import check_int, check_number, show
from vasim.core.errors import ConfigError
from vasim.records.trial_meta import SUBJECT_CODE_PATTERN

_SUBJECT_RE = re.compile(SUBJECT_CODE_PATTERN)
_HOST_LABEL = re.compile(r"[A-Za-z0-9](?:[A-Za-z0-9-]{0,61}[A-Za-z0-9])?")


def _argument_error(exc: ConfigError) -> argparse.ArgumentTypeError:
    return argparse.ArgumentTypeError(exc.reason)


def bounded_int(bound: Bound | Callable[[], Bound]) -> Callable[[str], int]:
    """An ``argparse`` type: an integer within ``bound`` (or ``bound()``, evaluated late)."""

    def parse(text: str) -> int:
        b = bound() if callable(bound) else bound
        try:
            value = int(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"got {show(text)}, expected an integer") from None
        try:
            return check_int(value, bound=b)
        except ConfigError as exc:
            raise _argument_error(exc) from None

    parse.__name__ = "integer"  # argparse names the type in its messages
    return parse


def bounded_float(bound: Bound, *, gt: float | None = None) -> Callable[[str], float]:
    """An ``argparse`` type: a finite number within ``bound`` (and > ``gt``)."""

    def parse(text: str) -> float:
        try:
            value = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"got {show(text)}, expected a number") from None
        try:
            return check_number(value, bound=bound, gt=gt)
        except ConfigError as exc:
            raise _argument_error(exc) from None

    parse.__name__ = "number"
    return parse


def workers(text: str) -> int:
    """``--workers``: 1 to 4 x the CPU count."""
    return bounded_int(workers_bound)(text)


def subject_code(text: str) -> str:
    """``--subject``: 1-32 letters, digits, '_' or '-' (echoed truncated when refused)."""
    if not _SUBJECT_RE.fullmatch(text):
        raise argparse.ArgumentTypeError(
            f"got {show(text)}, expected a subject code of 1-32 letters, digits, '_' or '-' "
            "(a pseudonym, never a name)")
    return text


def host_address(text: str) -> str:
    """``--host``: an IPv4/IPv6 address or a host name (RFC 1123), checked before use.

    **Decision**: syntax only (no DNS lookup at parse time): ``999.1.1.1`` (all-numeric
    labels that are no IPv4 address) and ``bad_name!`` are refused; a well-formed name that
    does not resolve is left to the server's bind error.
    """
    try:
        ipaddress.ip_address(text)
        return text
    except ValueError:
        pass
    labels = text.rstrip(".").split(".")
    ok = (0 < len(text) <= 253 and all(_HOST_LABEL.fullmatch(lb) for lb in labels)
          and not all(lb.isdigit() for lb in labels))
    if not ok:
        raise argparse.ArgumentTypeError(
            f"got {show(text)}, expected an IP address (e.g. 127.0.0.1, ::1) or a host name")
    return text


def output_folder(text: str) -> Path:
    """``--out``: a folder (created if missing), refused at parse time when it, or a folder
    above it, is a file (issue #30 item 8: "afile: File exists" named neither the option
    nor what was wrong).

    Example:
        >>> output_folder("report/")
        PosixPath('report')
    """
    if not text:
        raise argparse.ArgumentTypeError("got '', expected a folder")
    path = Path(text)
    for p in (path, *path.parents):
        if p.exists() and not p.is_dir():
            what = "" if p == path else f" (under {show(str(p))})"
            raise argparse.ArgumentTypeError(
                f"got {show(text)}{what}: {p} is a file, not a folder; expected a folder "
                "(created if missing)")
    return path


__all__ = ["bounded_float", "bounded_int", "host_address", "output_folder", "subject_code",
           "workers"]
