"""Progress output for long work: a redrawn bar on a terminal, plain lines in a log file."""

from __future__ import annotations

import io

from vasim.core.progress import progress_bar


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_log_file_gets_one_line_per_refresh_and_no_carriage_returns() -> None:
    out = io.StringIO()
    with progress_bar(4, "cohort demo", "trial", stream=out, interval=0.0) as bar:
        for k in range(4):
            bar.set_postfix_str(f"S{k:02d}")
            bar.update(1)
    text = out.getvalue()
    assert "\r" not in text
    lines = text.splitlines()
    assert lines[-1].startswith("cohort demo: 100%") and "4/4" in lines[-1]
    assert any("1/4" in line for line in lines)
    assert "S03" in lines[-1]


def test_short_work_in_a_log_file_prints_nothing() -> None:
    out = io.StringIO()
    with progress_bar(10, "report", "step", stream=out) as bar:   # default 15 s quiet start
        for _ in range(10):
            bar.set_postfix_str("a step")      # must not force a line either
            bar.update(1)
    assert out.getvalue() == ""


def test_disabled_prints_nothing() -> None:
    out = io.StringIO()
    with progress_bar(3, "x", "step", stream=out, interval=0.0, enabled=False) as bar:
        bar.update(3)
    assert out.getvalue() == ""


def test_terminal_gets_a_bar_redrawn_in_place() -> None:
    out = Terminal()
    with progress_bar(3, "x", "step", stream=out, mininterval=0.0) as bar:
        for _ in range(3):
            bar.update(1)
    assert "\r" in out.getvalue() and "3/3" in out.getvalue()


def test_iterable_form_passes_every_item_through() -> None:
    out = io.StringIO()
    items = list(progress_bar(None, "samples", "trial", stream=out, iterable=range(5)))
    assert items == [0, 1, 2, 3, 4]
