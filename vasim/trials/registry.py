"""The trial kinds and the one entry point that runs a trial of any kind.

A trial kind names how a configuration (``vasim.trials.configs.AnyTrialConfig``) is run
and stored: its headless runner (with a
``TrialSink``), the ``TrialMeta`` of its row, and the sink-free job a cohort worker runs.
``run_trial`` and the study layer (``vasim.study.cohort``, ``vasim.study.session``) look
the kind up here instead of choosing between the modules themselves.

**Decision** (kind names): a configuration's kind is ``config.kind``: ``"vf"`` for a
``VfTrialConfig`` (a virtual-fixture trial), the mode (``"stdt"``, ``"mrcp"``,
``"mrcp_cam"``: spec/study.md §4) for a ``TeleopTrialConfig``, because ``mode`` is what the
protocols already write; the three teleoperation kinds share one runner, which reads the
mode from the config. Each kind names its configuration class (``config_type``); a kind
refuses a configuration of another class.

Example:
    >>> from vasim.trials.teleop_config import TeleopTrialConfig
    >>> TRIAL_KINDS.names()
    ('mrcp', 'mrcp_cam', 'stdt', 'vf')
    >>> TRIAL_KINDS.of(TeleopTrialConfig(mode="stdt")).name
    'stdt'
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

from vasim.fixtures.schema import Schema
from vasim.records.trial_meta import TrialMeta
from vasim.records.trial_metrics import MetricParams
from vasim.trials.configs import AnyTrialConfig
from vasim.trials.kinds import TELEOPERATION_MODES
from vasim.trials.sink import TrialSink
from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.teleop_run import run_teleop_trial, simulate_teleop, teleop_meta
from vasim.trials.vf import TrialResult
from vasim.trials.vf_config import VfTrialConfig
from vasim.trials.vf_run import run_vf_trial, simulate_vf, vf_meta


class TrialRun(Protocol):
    """``run(config, sink, *, progress, session_id, schedule_index, protocol,
    metric_params) -> (result, trial_id)``; ``config``: of the kind's ``config_type``."""

    def __call__(self, config: Any, sink: TrialSink | None = None, *,
                 progress: bool = False, session_id: int | None = None,
                 schedule_index: int | None = None,
                 protocol: str | None = None, metric_params: MetricParams | None = None,
                 ) -> tuple[TrialResult, int | None]: ...


class TrialMetaBuilder(Protocol):
    """``meta(config, *, schema, session_id, schedule_index, protocol) -> TrialMeta``;
    ``config``: of the kind's ``config_type``."""

    def __call__(self, config: Any, *, schema: Schema | None = None,
                 session_id: int | None = None, schedule_index: int | None = None,
                 protocol: str | None = None) -> TrialMeta: ...


@dataclass(frozen=True, eq=False)
class TrialKind:
    """One kind of trial.

    Attributes:
        name: the kind's name (lower-case identifier).
        run: runs a trial headless, storing it through a sink if given.
        meta: the ``TrialMeta`` of a trial about to run (``schema``: an already loaded
            schema, to spare reloading it).
        simulate: ``simulate(config, params) -> dict`` runs it without a sink (a cohort
            worker's job; the dict of ``vasim.study.cohort.simulate_trial``).
        summary: one line for humans.
        config_type: the configuration class of this kind.
    """

    name: str
    run: TrialRun
    meta: TrialMetaBuilder
    simulate: Callable[[Any, MetricParams], dict[str, Any]]
    summary: str = ""
    config_type: type = VfTrialConfig


class TrialKinds:
    """Name -> ``TrialKind``; adding a name twice raises ``ValueError``."""

    def __init__(self) -> None:
        self._kinds: dict[str, TrialKind] = {}

    def add(self, kind: TrialKind) -> TrialKind:
        """Registers ``kind``; returns it.

        Raises:
            ValueError: ``kind.name`` is already registered or not a lower-case identifier.
        """
        name = kind.name
        if not (isinstance(name, str) and name.isidentifier() and name == name.lower()):
            raise ValueError(f"trial kind name must be a lower-case identifier, got {name!r}")
        if name in self._kinds:
            raise ValueError(f"trial kind {name!r} is already registered")
        self._kinds[name] = kind
        return kind

    def __getitem__(self, name: str) -> TrialKind:
        try:
            return self._kinds[name]
        except KeyError:
            raise KeyError(f"unknown trial kind {name!r} (known: {', '.join(self.names())})"
                           ) from None

    def __contains__(self, name: object) -> bool:
        return name in self._kinds

    def __iter__(self) -> Iterator[str]:
        return iter(sorted(self._kinds))

    def __len__(self) -> int:
        return len(self._kinds)

    def names(self) -> tuple[str, ...]:
        """Registered names, sorted."""
        return tuple(sorted(self._kinds))

    def of(self, config: AnyTrialConfig) -> TrialKind:
        """The kind that runs ``config`` (:func:`kind_name`).

        Raises:
            TypeError: the configuration is not of the kind's ``config_type`` (a caller's
                mistake, not bad user input).
        """
        kind = self[kind_name(config)]
        if not isinstance(config, kind.config_type):
            raise TypeError(f"trial kind {kind.name!r} runs a {kind.config_type.__name__}, "
                            f"got a {type(config).__name__}")
        return kind


def kind_name(config: AnyTrialConfig) -> str:
    """``config.kind``: the mode of a teleoperation trial, ``"vf"`` for a virtual-fixture
    trial (module docstring)."""
    return config.kind


TRIAL_KINDS = TrialKinds()
"""Every trial kind vasim runs."""

TRIAL_KINDS.add(TrialKind("vf", run=run_vf_trial, meta=vf_meta, simulate=simulate_vf,
                          summary="virtual-fixture trial: a fixture schema assists one tool"))
for _mode in TELEOPERATION_MODES:
    TRIAL_KINDS.add(TrialKind(_mode, run=run_teleop_trial, meta=teleop_meta,
                              simulate=simulate_teleop, config_type=TeleopTrialConfig,
                              summary=f"teleoperation trial ({_mode}) on the MRCP station's "
                                      "needle task"))


def run_trial(config: AnyTrialConfig, sink: TrialSink | None = None, *,
              progress: bool = False, session_id: int | None = None,
              schedule_index: int | None = None, protocol: str | None = None,
              metric_params: MetricParams | None = None,
              ) -> tuple[TrialResult, int | None]:
    """Runs a whole trial of its kind (``TRIAL_KINDS.of(config)``) headless and, with a
    sink, stores it (row 'running' first, everything in one transaction at the end,
    'interrupted' with what was recorded on any exception: ``vasim.trials.lifecycle``).

    Args:
        config: the trial. sink: a ``TrialSink`` (e.g. a ``TrialStore``) or None.
        progress: a progress bar over POIs (virtual-fixture trials; teleoperation trials
            show none).
        session_id, schedule_index, protocol: the scheduled trial of a session this run is
            an attempt at (see ``TrialStore.begin_trial``).
        metric_params: constants of the trial metrics (default ``MetricParams()``).

    Returns:
        (result, trial_id) — trial_id is None without a sink.
    """
    return TRIAL_KINDS.of(config).run(
        config, sink, progress=progress, session_id=session_id, schedule_index=schedule_index,
        protocol=protocol, metric_params=metric_params)


__all__ = ["TRIAL_KINDS", "TrialKind", "TrialKinds", "TrialMetaBuilder", "TrialRun",
           "kind_name", "run_trial"]
