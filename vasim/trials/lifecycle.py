"""The life cycle of a stored trial, written once for every caller.

A stored trial's row is begun as 'running' before the first step; at the end everything it
recorded becomes durable at once (``TrialSink.finish_trial``); a failure keeps what was
recorded and marks the row 'interrupted' (``TrialSink.keep_interrupted`` /
``mark_interrupted``), never leaving it 'running'. The headless runners
(``vasim.trials.vf``, ``vasim.trials.teleop``), the real-time trial
(``vasim.trials.realtime.stored``) and the in-process cohort writer use the block form::

    with stored_trial(sink, meta, partial=runner.result, samples=runner.samples) as rec:
        ...                     # run the trial
        rec.finish(result)      # completed, in one transaction

Leaving the block by an exception (Ctrl-C included) keeps the partial result (or the raw
samples, or only the status) and re-raises; ``sink=None`` makes every call a no-op, so a
runner has one code path with and without a store.

**Decision**: a life cycle that does not fit one block (the viewer begins a trial in one
callback and ends it in another; the cohort's writer keeps several worker trials in
flight) uses the same :class:`StoredTrial` object through :func:`begin_stored_trial` and its
``finish`` / ``keep`` / ``interrupt`` methods, so the sink calls are still written only
here.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
from typing import Any, Protocol

import pandas as pd

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta
from vasim.trials.sink import Event, TrialSink, check_sink

log = logging.getLogger(__name__)

Events = Iterable[Event] | Callable[[], Iterable[Event]]
"""Events to add when a trial is interrupted: a list, or a callable evaluated then (e.g.
one that saves a recording and names it)."""


class ResultLike(Protocol):
    """What a finished (or partial) trial hands to its sink (``TrialResult`` is one)."""

    @property
    def samples(self) -> SampleBuffer: ...

    @property
    def metrics(self) -> pd.DataFrame: ...

    @property
    def summary(self) -> Mapping[str, Any]: ...

    @property
    def events(self) -> Sequence[Event]: ...

    @property
    def trial_metrics(self) -> Mapping[str, float]: ...


class StoredTrial:
    """One trial row of a sink, from 'running' to 'completed' or 'interrupted'.

    Attributes:
        sink: the sink, or None (every method is then a no-op).
        trial_id: the row's id (None without a sink).
        closed: True once the row was finished or interrupted (later calls do nothing).
        partial: ``fn() -> ResultLike`` computing the partial result on interruption.
        samples: the raw samples to keep when ``partial`` fails.
        events: events added on interruption (a list or a callable, :data:`Events`).
    """

    def __init__(self, sink: TrialSink | None, trial_id: int | None, *,
                 partial: Callable[[], ResultLike] | None = None,
                 samples: SampleBuffer | None = None, events: Events = ()):
        self.sink = sink
        self.trial_id = trial_id
        self.closed = sink is None or trial_id is None
        self.partial = partial
        self.samples = samples
        self.events = events

    def finish(self, result: ResultLike, *, timing: Mapping[str, Any] | None = None) -> None:
        """Makes the completed trial durable in one transaction (``finish_trial``)."""
        if self.closed:
            return
        assert self.sink is not None and self.trial_id is not None
        self.sink.finish_trial(self.trial_id, result.samples, result.metrics, result.summary,
                               events=result.events, timing=timing,
                               trial_metrics=result.trial_metrics)
        self.closed = True

    def _extra_events(self) -> list[Event]:
        return list(self.events() if callable(self.events) else self.events)

    def keep(self, reason: str) -> None:
        """Marks the row 'interrupted' keeping as much as can be kept: ``partial()``, else
        ``samples``, else the bare status (``TrialSink.keep_interrupted``); with no
        ``partial``, the samples (if any) and the events. Never raises (for an ``except``
        block): the interruption's own failures are logged.

        **Decision**: without a partial result (the cohort writer, whose trial ran in a
        worker) a failing ``mark_interrupted`` is logged, not raised, like the sink's own
        ``keep_interrupted``: the exception that stopped the trial is the one to report.
        """
        if self.closed:
            return
        assert self.sink is not None and self.trial_id is not None
        self.closed = True
        try:
            extra = self._extra_events()
        except Exception as exc:  # e.g. the recording could not be saved: keep the row
            log.warning("trial %s: its interruption events failed: %s", self.trial_id, exc)
            extra = []
        if self.partial is not None:
            self.sink.keep_interrupted(self.trial_id, reason, self.partial,
                                       samples=self.samples, events=extra)
            return
        try:
            self.sink.mark_interrupted(self.trial_id, reason=reason, samples=self.samples,
                                       events=extra)
        except Exception as exc:
            log.warning("trial %s: marking it interrupted failed: %s", self.trial_id, exc)

    def interrupt(self, reason: str, result: ResultLike | None = None, *,
                  summary: Mapping[str, Any] | None = None,
                  events: Iterable[Event] = ()) -> None:
        """Marks the row 'interrupted' with ``result`` as its partial data (``events``
        after the result's; ``summary`` replaces the result's), or with the bare status
        (``TrialSink.mark_interrupted``). Unlike :meth:`keep` its failures raise."""
        if self.closed:
            return
        assert self.sink is not None and self.trial_id is not None
        self.closed = True
        if result is None:
            self.sink.mark_interrupted(self.trial_id, reason=reason, events=list(events))
            return
        self.sink.mark_interrupted(
            self.trial_id, reason=reason, samples=result.samples, point_metrics=result.metrics,
            summary=result.summary if summary is None else summary,
            events=[*result.events, *events], trial_metrics=result.trial_metrics)


def interruption_reason(exc: BaseException) -> str:
    """The reason stored with an interrupted trial: ``"<ExceptionType>: <message>"``."""
    return f"{type(exc).__name__}: {exc}"


def begin_stored_trial(sink: TrialSink | None, meta: TrialMeta | Callable[[], TrialMeta], *,
                       partial: Callable[[], ResultLike] | None = None,
                       samples: SampleBuffer | None = None,
                       events: Events = ()) -> StoredTrial:
    """Begins the trial's row as 'running' (``TrialSink.begin_trial``); with ``sink=None``
    a no-op record (``trial_id`` None; ``meta`` is then not built when it is a callable).

    Raises:
        TypeError: ``sink`` is not a ``TrialSink``.
    """
    sink = check_sink(sink)
    if sink is None:
        return StoredTrial(None, None, partial=partial, samples=samples, events=events)
    trial_id = sink.begin_trial(meta() if callable(meta) else meta)
    return StoredTrial(sink, trial_id, partial=partial, samples=samples, events=events)


@contextmanager
def stored_trial(sink: TrialSink | None, meta: TrialMeta | Callable[[], TrialMeta], *,
                 partial: Callable[[], ResultLike] | None = None,
                 samples: SampleBuffer | None = None,
                 events: Events = ()) -> Iterator[StoredTrial]:
    """A stored trial as a block: begun on entry; ``rec.finish(result)`` inside it
    completes the row; leaving it by an exception keeps what was recorded
    (:meth:`StoredTrial.keep`, reason ``"<Type>: <message>"``) and re-raises. Leaving it
    normally without ``finish`` is a programming error: the row is kept as interrupted
    (reason ``"not finished"``) and ``RuntimeError`` is raised.

    Args:
        sink: the sink or None (no-op). meta: the row's ``TrialMeta`` (or a callable
            building it only when there is a sink). partial, samples, events: what
            :meth:`StoredTrial.keep` keeps (also settable on the record inside the block).
    """
    rec = begin_stored_trial(sink, meta, partial=partial, samples=samples, events=events)
    try:
        yield rec
    except BaseException as exc:
        rec.keep(interruption_reason(exc))
        raise
    if not rec.closed:
        rec.keep("not finished")
        raise RuntimeError(f"stored trial {rec.trial_id}: the block ended without finish()")


__all__ = ["Events", "ResultLike", "StoredTrial", "begin_stored_trial",
           "interruption_reason", "stored_trial"]
