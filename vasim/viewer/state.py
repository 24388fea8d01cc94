"""The viewer's immutable state and its small pure helpers: the commands GUI callbacks queue,
the per-trial :class:`TrialInfo`, the experimenter panel's :class:`PanelState`, and the
f5PL editing and schema-menu helpers (split from :mod:`vasim.viewer.controller`, which
re-exports them)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.core.config import expect
from vasim.core.errors import ConfigError
from vasim.fixtures.gain import AdaptiveRule, GainRule
from vasim.fixtures.logistic import Logistic5
from vasim.fixtures.schema import Schema, available_schemas
from vasim.trials.configs import AnyTrialConfig
from vasim.trials.configs import VfTrialConfig as TrialConfig
from vasim.viewer.trainee import ScoreCard, trial_title

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class Command:
    """A request to the controller thread.

    Attributes:
        kind: ``mode`` (value: a ``MODES`` name), ``schema``, ``task``, ``input``
            (``INPUTS``), ``subject`` (a subject code), ``protocol`` (a protocol name),
            ``start``, ``stop``, ``restart``, ``f5pl`` (value: (fixture instance,
            ``Logistic5``)), ``auto_advance`` (value: bool), ``input_mapping`` (value: an
            ``InputMapping``), ``label`` (value: a free-practice label, "" clears it).
        value: the argument.
    """

    kind: str
    value: Any = None


def gain_plan(rule: GainRule, schedule_text: str = "") -> str:
    """How a trial's fixture gain is set, for the experimenter: ``"adaptive 25-100 %"``
    (assist-as-needed), ``"scheduled (gain 75 %)"`` (a faded block's stage,
    ``vasim.study.gain_plan.gain_text``) or ``"constant"`` (a constant gain, 1 included).

    >>> gain_plan(0.75, "gain 75 %"), gain_plan(0.5), gain_plan(1.0)
    ('scheduled (gain 75 %)', 'constant', 'constant')
    """
    if isinstance(rule, AdaptiveRule):
        return f"adaptive {rule.gain_min * 100:.0f}-{rule.gain_max * 100:.0f} %"
    if schedule_text:
        return f"scheduled ({schedule_text})"
    return "constant"


@dataclass(frozen=True, eq=False)
class TrialInfo:
    """What does not change during one trial (built once per trial).

    Attributes:
        number: trial counter since the server started (1, 2, ...).
        config: the trial's configuration. schema: schema name. fixtures: its fixture
        names. task_name: e.g. ``"trajectory/v3"``. points: (N, 3) POIs [m]. normals:
        (N, 3) or None. reach_radius: [m]. start: (3,) tool start [m]. mode: the mode it
        runs in. input: ``INPUTS``. trial_id: store id (None when not stored).
        schedule_index: 0-based scheduled trial (protocol mode). condition: the protocol's
        condition label (protocol mode). gain_plan: how its fixture gain is set
        (``panel.gain_plan``: ``"constant"``, ``"scheduled (gain 75 %)"``,
        ``"adaptive 25-100 %"``); the current value is each frame's ``gain``.
        schedule_total: the session's scheduled trials (protocol mode), for the title.
    """

    number: int
    config: AnyTrialConfig
    schema: str
    fixtures: tuple[str, ...]
    task_name: str
    points: FloatArray
    normals: FloatArray | None
    reach_radius: float
    start: FloatArray
    mode: str = "demo"
    input: str = "scripted"
    trial_id: int | None = None
    schedule_index: int | None = None
    condition: str | None = None
    gain_plan: str = "constant"
    schedule_total: int | None = None

    @property
    def title(self) -> str:
        """The trial's name on every page (``trainee.trial_title``: "trial 1 of 38" in a
        protocol's schedule, else the store id)."""
        pos = None if self.schedule_index is None else self.schedule_index + 1
        return trial_title(self.trial_id, self.number, pos, self.schedule_total)


@dataclass(frozen=True)
class PanelState:
    """What the experimenter panel shows (published by the controller, immutable).

    Attributes:
        mode, input: current choices. schema, task: free-training / demo choices.
        subject, protocol: chosen subject code and protocol (or None). label: the
        free-practice label of free trials without a subject (or None). session_id: the
        session of the last protocol trial. position: 1-based scheduled trial running or
        next. total: scheduled trials. completed: completed scheduled trials.
        condition: condition of that trial. running: a trial runs. status: one line.
        summary: last finished trial's summary (plain values) or None.
        curve: learning curve so far of the subject, ``(n, completion_time, mean_latency)``
        per completed stored trial (protocol trials of the session, or the subject's free
        trials). auto_advance: start the next scheduled trial by itself.
        f5pl: editable f5PL curves of the current schema: fixture instance -> params.
        scorecard: the score card of the last stored trial (or None).
        again: the reason to run a completed protocol again for the subject, stored with
        the next new session (``history.session_rule``), or None.
        version: increments with every change.
    """

    mode: str = "demo"
    input: str = "scripted"
    schema: str = "trajectory_following"
    task: str = "trajectory"
    subject: str | None = None
    label: str | None = None
    protocol: str | None = None
    session_id: int | None = None
    position: int | None = None
    total: int | None = None
    completed: int | None = None
    condition: str | None = None
    running: bool = False
    status: str = ""
    summary: dict[str, Any] | None = None
    curve: tuple[tuple[int, float, float], ...] = ()
    auto_advance: bool = False
    f5pl: tuple[tuple[str, Logistic5], ...] = ()
    scorecard: ScoreCard | None = None
    again: str | None = None
    version: int = 0


def f5pl_fields(schema: Schema) -> tuple[tuple[str, Logistic5], ...]:
    """The f5PL parameter sets of a schema's fixtures, by instance name (MS has none)."""
    out = []
    for fx in schema.fixtures:
        p = getattr(fx.params, "f5pl", None)
        if isinstance(p, Logistic5):
            out.append((fx.name, p))
    return tuple(out)


def with_f5pl(schema: Schema, instance: str, params: Logistic5) -> Schema:
    """A copy of ``schema`` whose fixture ``instance`` has the f5PL ``params``.

    Raises:
        ConfigError: no such fixture, or it has no f5PL.
    """
    fixtures = []
    found = False
    for fx in schema.fixtures:
        if fx.name == instance:
            expect(isinstance(getattr(fx.params, "f5pl", None), Logistic5), instance,
                   "a fixture with an f5PL to edit", field=f"fixtures.{instance}.f5pl")
            fx = replace(fx, params=replace(fx.params, f5pl=params))
            found = True
        fixtures.append(fx)
    expect(found, instance, f"a fixture of schema {schema.name!r} (it has "
           f"{', '.join(schema.fixture_names) or 'none'})", field="fixtures")
    return replace(schema, fixtures=tuple(fixtures))


def plain(v: Any) -> Any:
    """A summary value as plain JSON-able Python (NaN -> None)."""
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def plain_dict(d: dict[str, Any]) -> dict[str, Any]:
    return {k: plain(v) for k, v in d.items()}


def schema_choices(current: str) -> tuple[str, ...]:
    """The schema menu: the shipped schemas (plus ``current`` if it is a file path)."""
    names = available_schemas()
    return names if current in names else (*names, current)

__all__ = ["Command", "PanelState", "TrialInfo", "demo_config", "f5pl_fields", "gain_plan", "plain",
           "plain_dict", "schema_choices", "with_f5pl"]


def demo_config(info: TrialInfo) -> TrialConfig:
    """The VF config of a demo trial's info (a demo is always a VF trial: a teleoperation
    trial runs only from a protocol's schedule)."""
    if not isinstance(info.config, TrialConfig):
        raise ConfigError(f"{info.title} is a {info.config.kind} trial: it has no demo",
                          field="mode")
    return info.config
