"""Where a trial's records go: the sink protocol every trial runner writes through.

The trial engine does not know the study store: it writes a trial through a ``TrialSink``
(``vasim.study.store.TrialStore`` is the one the study layer provides; tests may pass any
object with these methods) and replays one from a ``TrialSource``.

The life cycle of a stored trial is always the same (``vasim.trials.lifecycle``): a row is
begun as 'running' before the first step; at the end everything becomes durable at once
(``finish_trial``); any failure keeps what was recorded and marks the row 'interrupted'
(``keep_interrupted``), never leaving it 'running'.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any, Protocol, runtime_checkable

import pandas as pd

from vasim.records.samples import SampleBuffer
from vasim.records.trial_meta import TrialMeta

Event = tuple[float | None, str, str]
"""A trial event: (time [s] or None, kind, detail)."""


@runtime_checkable
class TrialSink(Protocol):
    """What a trial runner needs of a store."""

    @property
    def path(self) -> Path:
        """The database file (recordings are written beside it)."""
        ...

    def begin_trial(self, meta: TrialMeta) -> int:
        """Creates the trial's row as 'running'; returns its id."""
        ...

    def finish_trial(self, trial_id: int, samples: SampleBuffer, point_metrics: pd.DataFrame,
                     summary: Mapping[str, Any], *, events: Iterable[Event] = (),
                     timing: Mapping[str, Any] | None = None,
                     trial_metrics: Mapping[str, float] | None = None) -> None:
        """Makes everything a completed trial recorded durable in one transaction."""
        ...

    def keep_interrupted(self, trial_id: int, reason: str, partial: Callable[[], Any], *,
                         samples: SampleBuffer | None = None,
                         events: Iterable[Event] = ()) -> None:
        """Marks a failed trial 'interrupted' keeping as much as can be kept."""
        ...

    def mark_interrupted(self, trial_id: int, *, reason: str = "",
                         samples: SampleBuffer | None = None,
                         point_metrics: pd.DataFrame | None = None,
                         summary: Mapping[str, Any] | None = None,
                         events: Iterable[Event] = (),
                         trial_metrics: Mapping[str, float] | None = None) -> bool:
        """Marks a running trial 'interrupted' with the given partial data."""
        ...

    def add_event(self, trial_id: int, kind: str, detail: str = "", *,
                  t: float | None = None) -> None:
        """Appends an event to a trial."""
        ...


@runtime_checkable
class TrialSource(Protocol):
    """What replaying a stored trial needs of a store."""

    @property
    def path(self) -> Path:
        ...

    def trial(self, trial_id: int) -> dict[str, Any]:
        ...

    def events(self, trial_id: int) -> pd.DataFrame:
        ...

    def sample_buffer(self, trial_id: int) -> SampleBuffer:
        ...

    def point_metrics(self, trial_id: int) -> pd.DataFrame:
        ...

    def trial_metrics(self, trial_id: int) -> pd.DataFrame:
        ...


def check_sink(store: object | None) -> TrialSink | None:
    """``store`` as a ``TrialSink`` (or None); anything else is a ``TypeError``."""
    if store is not None and not isinstance(store, TrialSink):
        raise TypeError(f"store must be a TrialSink (e.g. a TrialStore), got "
                        f"{type(store).__name__}")
    return store


__all__ = ["Event", "TrialSink", "TrialSource", "check_sink"]
