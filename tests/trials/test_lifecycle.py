"""The stored-trial life cycle (``vasim.trials.lifecycle``): which sink calls a block makes,
with what, in which order -- against a sink that records every call."""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
import pytest

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.trials.lifecycle import StoredTrial, begin_stored_trial, stored_trial
from vasim.trials.sink import TrialSink


class RecordingSink:
    """A ``TrialSink`` that keeps every call (name, args, kwargs)."""

    def __init__(self, *, fail_keep: bool = False) -> None:
        self.calls: list[tuple[str, tuple[Any, ...], dict[str, Any]]] = []
        self.fail_keep = fail_keep

    @property
    def path(self) -> Path:
        return Path("/nonexistent/s.sqlite")

    def begin_trial(self, meta: TrialMeta) -> int:
        self.calls.append(("begin_trial", (meta,), {}))
        return 7

    def finish_trial(self, trial_id: int, *args: Any, **kw: Any) -> None:
        self.calls.append(("finish_trial", (trial_id, *args), kw))

    def keep_interrupted(self, trial_id: int, reason: str, partial: Any, **kw: Any) -> None:
        self.calls.append(("keep_interrupted", (trial_id, reason, partial), kw))

    def mark_interrupted(self, trial_id: int, **kw: Any) -> bool:
        self.calls.append(("mark_interrupted", (trial_id,), kw))
        if self.fail_keep:
            raise OSError("disk full")
        return True

    def add_event(self, trial_id: int, kind: str, detail: str = "", *,
                  t: float | None = None) -> None:
        self.calls.append(("add_event", (trial_id, kind, detail), {"t": t}))

    def names(self) -> list[str]:
        return [c[0] for c in self.calls]


@dataclass
class FakeResult:
    samples: SampleBuffer = field(default_factory=lambda: SampleBuffer(4))
    metrics: pd.DataFrame = field(default_factory=lambda: pd.DataFrame({"e": [1.5]}))
    summary: dict[str, Any] = field(default_factory=lambda: {"points_reached": 3})
    events: list[tuple[float | None, str, str]] = field(
        default_factory=lambda: [(0.5, "reach", "0")])
    trial_metrics: dict[str, float] = field(default_factory=lambda: {"ise": 2.0})


META = TrialMeta(subject="S01", task="trajectory", variant=0, schema="none",
                 operator="scripted", seed=1, dt=1e-3)


def test_the_sink_is_a_trial_sink() -> None:
    assert isinstance(RecordingSink(), TrialSink)


def test_a_finished_block_begins_then_finishes_once() -> None:
    sink, res = RecordingSink(), FakeResult()
    with stored_trial(sink, META) as rec:
        assert rec.trial_id == 7 and not rec.closed
        rec.finish(res, timing={"rate_hz": 999.0})
        rec.finish(res)                                     # a second finish does nothing
    assert sink.names() == ["begin_trial", "finish_trial"]
    assert sink.calls[0][1] == (META,)
    _, args, kw = sink.calls[1]
    assert args == (7, res.samples, res.metrics, res.summary)
    assert kw == {"events": res.events, "timing": {"rate_hz": 999.0},
                  "trial_metrics": res.trial_metrics}
    assert rec.closed


@pytest.mark.parametrize("exc", [ValueError("boom"), KeyboardInterrupt()])
def test_leaving_by_an_exception_keeps_what_was_recorded_and_reraises(
        exc: BaseException) -> None:
    sink, res = RecordingSink(), FakeResult()
    buf = SampleBuffer(4)
    evaluated: list[int] = []

    def events() -> list[tuple[float | None, str, str]]:
        evaluated.append(1)
        return [(None, "recording", '{"a": "b"}')]

    with pytest.raises(type(exc)), stored_trial(sink, META, partial=lambda: res,
                                                samples=buf, events=events) as rec:
        assert evaluated == []                      # only evaluated on interruption
        raise exc
    assert sink.names() == ["begin_trial", "keep_interrupted"]
    _, (tid, reason, partial), kw = sink.calls[1]
    assert tid == 7 and reason == f"{type(exc).__name__}: {exc}"
    assert partial() is res
    assert kw == {"samples": buf, "events": [(None, "recording", '{"a": "b"}')]}
    assert evaluated == [1] and rec.closed


def test_a_failure_in_finish_keeps_the_row() -> None:
    class FailingFinish(RecordingSink):
        def finish_trial(self, trial_id: int, *args: Any, **kw: Any) -> None:
            raise OSError("locked")

    sink = FailingFinish()
    with pytest.raises(OSError, match="locked"), stored_trial(sink, META,
                                                              partial=FakeResult) as rec:
        rec.finish(FakeResult())
    assert sink.names() == ["begin_trial", "keep_interrupted"]
    assert sink.calls[1][1][1] == "OSError: locked"


def test_without_a_partial_result_samples_and_events_are_marked() -> None:
    sink, buf = RecordingSink(), SampleBuffer(2)
    with pytest.raises(RuntimeError), stored_trial(sink, META, samples=buf,
                                                   events=[(1.0, "x", "y")]):
        raise RuntimeError("worker died")
    assert sink.calls[1] == ("mark_interrupted", (7,), {
        "reason": "RuntimeError: worker died", "samples": buf, "events": [(1.0, "x", "y")]})


def test_a_failing_mark_does_not_hide_the_original_error() -> None:
    sink = RecordingSink(fail_keep=True)
    with pytest.raises(ValueError, match="the real one"), stored_trial(sink, META):
        raise ValueError("the real one")
    assert sink.names() == ["begin_trial", "mark_interrupted"]


def test_a_block_that_forgets_to_finish_is_an_error_and_the_row_is_not_left_running(
        ) -> None:
    sink = RecordingSink()
    with pytest.raises(RuntimeError, match="without finish"), stored_trial(sink, META):
        pass
    assert sink.calls[1] == ("mark_interrupted", (7,), {"reason": "not finished",
                                                       "samples": None, "events": []})


def test_no_sink_is_a_no_op_that_never_builds_the_meta() -> None:
    def meta() -> TrialMeta:
        raise AssertionError("meta built without a sink")

    with stored_trial(None, meta) as rec:
        rec.finish(FakeResult())
    assert rec.trial_id is None and rec.closed
    with pytest.raises(ZeroDivisionError), stored_trial(None, meta):
        _ = 1 / 0
    quiet = StoredTrial(None, None)
    quiet.keep("x")
    quiet.interrupt("y", FakeResult())


def test_a_callable_meta_is_built_once_with_a_sink() -> None:
    sink, built = RecordingSink(), []

    def meta() -> TrialMeta:
        built.append(1)
        return META

    rec = begin_stored_trial(sink, meta)
    assert built == [1] and rec.trial_id == 7


def test_interrupt_stores_the_result_with_the_extra_events_after_its_own() -> None:
    sink, res = RecordingSink(), FakeResult()
    rec = begin_stored_trial(sink, META)
    rec.interrupt("stopped", res, summary={"plain": 1}, events=[(None, "recording", "f")])
    rec.interrupt("again", res)                          # closed: nothing more
    assert sink.calls[1] == ("mark_interrupted", (7,), {
        "reason": "stopped", "samples": res.samples, "point_metrics": res.metrics,
        "summary": {"plain": 1}, "events": [(0.5, "reach", "0"), (None, "recording", "f")],
        "trial_metrics": res.trial_metrics})
    assert len(sink.calls) == 2
    bare = begin_stored_trial(sink, META)
    bare.interrupt("cohort run stopped: KeyboardInterrupt")
    assert sink.calls[-1] == ("mark_interrupted", (7,), {
        "reason": "cohort run stopped: KeyboardInterrupt", "events": []})


def test_a_bad_sink_is_refused() -> None:
    with pytest.raises(TypeError, match="TrialSink"):
        begin_stored_trial(np.zeros(3), META)  # type: ignore[arg-type]
