"""Progress bars for long work (cohorts, sessions, reports, exports) on stderr.

On a terminal a tqdm bar redraws in place. Anywhere else (a log file, ``nohup``, CI) a
redrawn bar would pile ``\\r`` frames into one line, and the CLIs used to switch it off: a
cohort piped to a file then said nothing for minutes. :func:`progress_bar` keeps the bar
on and turns it into plain log lines instead: nothing for work done within
:data:`LOG_INTERVAL` seconds (a short command or an error stays one clean line), then at most
one line every :data:`LOG_INTERVAL` seconds and a last one at the end, e.g.::

    cohort mrcp_vs_stdt:  25%|##5       | 54/216 [01:00<03:00,  0.90trial/s, SIM004 trial 7 MRCP]
"""

from __future__ import annotations

import sys
from typing import IO, Any

from tqdm import tqdm

LOG_INTERVAL = 15.0
"""Seconds between two progress lines when stderr is not a terminal."""


class LineStream:
    """A text stream for tqdm that writes each redraw as its own line.

    tqdm writes ``"\\r" + status`` for every refresh; this drops the carriage returns and
    ends every non-empty status with a newline.

    Example:
        >>> import io
        >>> out = io.StringIO()
        >>> s = LineStream(out)
        >>> _ = s.write("\\rjob: 1/2"); _ = s.write("\\rjob: 2/2"); _ = s.write("\\n")
        >>> out.getvalue()
        'job: 1/2\\njob: 2/2\\n'
    """

    def __init__(self, target: IO[str]) -> None:
        self.target = target

    def write(self, s: str) -> int:
        text = s.replace("\r", "").rstrip("\n")
        if text.strip():
            self.target.write(text + "\n")
        return len(s)

    def flush(self) -> None:
        self.target.flush()


class _LogBar(tqdm):
    """A tqdm bar for log files: a new postfix or description waits for the next periodic
    line instead of forcing one (a forced line would bypass the quiet first interval)."""

    def set_postfix_str(self, s: str = "", refresh: bool = True) -> None:
        super().set_postfix_str(s, refresh=False)

    def set_postfix(self, ordered_dict: Any = None, refresh: bool = True, **kwargs: Any) -> None:
        super().set_postfix(ordered_dict, refresh=False, **kwargs)

    def set_description(self, desc: str | None = None, refresh: bool = True) -> None:
        super().set_description(desc, refresh=False)


def is_terminal(stream: IO[str] | None = None) -> bool:
    """Whether ``stream`` (stderr by default) is an interactive terminal."""
    stream = sys.stderr if stream is None else stream
    isatty = getattr(stream, "isatty", None)
    return bool(isatty and isatty())


def progress_bar(total: int | None, desc: str, unit: str, *, enabled: bool = True,
                 initial: int = 0, leave: bool = True, stream: IO[str] | None = None,
                 interval: float = LOG_INTERVAL, **kwargs: Any) -> tqdm:
    """A tqdm bar on ``stream`` (stderr): redrawn in place on a terminal, elsewhere plain
    lines every ``interval`` s once the work has lasted that long; ``enabled=False``
    silences it (``--no-progress``).

    Example:
        >>> import io
        >>> out = io.StringIO()
        >>> with progress_bar(3, "demo", "step", stream=out) as bar:
        ...     _ = bar.update(3)
        >>> out.getvalue()                  # done within the interval: no noise in the log
        ''
        >>> with progress_bar(3, "demo", "step", stream=out, interval=0.0) as bar:
        ...     _ = bar.update(3)
        >>> out.getvalue().splitlines()[-1].startswith("demo: 100%")
        True
    """
    stream = sys.stderr if stream is None else stream
    if is_terminal(stream):
        return tqdm(total=total, desc=desc, unit=unit, initial=initial, leave=leave,
                    disable=not enabled, file=stream, dynamic_ncols=True, **kwargs)
    return _LogBar(total=total, desc=desc, unit=unit, initial=initial, leave=True,
                   disable=not enabled, file=LineStream(stream), ncols=100, ascii=True,
                   delay=interval, mininterval=interval, maxinterval=max(interval, 1.0),
                   **kwargs)
