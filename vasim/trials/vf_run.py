"""Running a virtual-fixture trial headless and storing it: the ``"vf"`` trial kind's
runner, row builder and cohort job (``vasim.trials.registry``)."""

from __future__ import annotations

import os
import socket
import time
from dataclasses import asdict, fields
from typing import Any

import numpy as np

from vasim.core.progress import progress_bar
from vasim.fixtures.gain import rule_record
from vasim.fixtures.schema import Schema, dumps_schema, load_schema
from vasim.operator.scripted import OperatorProfile
from vasim.operator.teleop_profile import TeleopEffects
from vasim.records.trial_meta import TrialMeta
from vasim.records.trial_metrics import MetricParams
from vasim.trials.configs import AnyTrialConfig
from vasim.trials.lifecycle import stored_trial
from vasim.trials.sink import TrialSink
from vasim.trials.vf import TrialConfig, TrialResult, TrialRunner, make_profile


def config_record(config: AnyTrialConfig, profile: OperatorProfile) -> dict[str, object]:
    """The trial configuration (of any kind) as plain JSON-able data (stored with the
    trial): its fields in order, the profile last."""
    # label, poi_spacing and the mode fields only when set: older records stay as they were
    rec: dict[str, object] = {
        f.name: getattr(config, f.name) for f in fields(config) if f.name != "profile"
        and not (f.name in ("label", "poi_spacing", "mode_practice", "mode_effects")
                 and getattr(config, f.name) is None)}
    effects = rec.get("mode_effects")
    if isinstance(effects, TeleopEffects):  # the teleoperation scenario's penalties
        rec["mode_effects"] = asdict(effects)
    rec["profile"] = {f.name: getattr(profile, f.name) for f in fields(profile)}
    if "gain" in rec:
        if rec["gain"] == 1.0:  # the schema as written: the record stays as it was
            del rec["gain"]
        else:
            rec["gain"] = rule_record(rec["gain"])  # type: ignore[arg-type]  # a GainRule field
    return rec


def trial_meta(config: TrialConfig, schema: Schema, profile: OperatorProfile, *,
               session_id: int | None = None, schedule_index: int | None = None,
               protocol: str | None = None) -> TrialMeta:
    """The store's ``TrialMeta`` of a trial about to run in this process.

    Args:
        config: the trial. schema: its loaded schema. profile: the operator's profile.
        session_id, schedule_index: the scheduled trial this is an attempt at, if any.
        protocol: the protocol name, if any.
    """
    return TrialMeta(
        subject=config.subject, task=config.task, variant=config.variant,
        schema=schema.name, operator=config.operator, seed=config.seed,
        dt=config.dt, active_fixtures=",".join(schema.fixture_names),
        pid=os.getpid(), host=socket.gethostname(),
        config=config_record(config, profile), schema_toml=dumps_schema(schema),
        session_id=session_id, schedule_index=schedule_index, protocol=protocol,
        label=config.label,
    )


def run_vf_trial(config: TrialConfig, sink: TrialSink | None = None, *,
                 progress: bool = False, session_id: int | None = None,
                 schedule_index: int | None = None, protocol: str | None = None,
                 metric_params: MetricParams | None = None,
                 ) -> tuple[TrialResult, int | None]:
    """Runs a whole virtual-fixture trial headless, as fast as the machine allows (the
    ``"vf"`` kind of ``vasim.trials.registry``; call ``registry.run_trial``).

    With a sink, the trial row is created as 'running' before the first step and made
    durable (samples + per-point metrics + trial metrics + status 'completed') in one
    transaction at the end; any exception or Ctrl-C marks it 'interrupted' (keeping the
    partial samples) and re-raises (``vasim.trials.lifecycle.stored_trial``).

    Args:
        config: the trial. sink: a ``TrialSink`` (e.g. a ``TrialStore``) or None.
        progress: a tqdm bar over POIs.
        session_id, schedule_index, protocol: the scheduled trial of a session this run is
            an attempt at (see ``TrialStore.begin_trial``).
        metric_params: constants of the trial metrics (default ``MetricParams()``).

    Returns:
        (result, trial_id) — trial_id is None without a sink.
    """
    runner = TrialRunner(config)
    t0 = time.perf_counter()

    def partial() -> TrialResult:
        return runner.result(wall_time=time.perf_counter() - t0, metric_params=metric_params)

    def meta() -> TrialMeta:  # built only with a sink
        return trial_meta(config, runner.schema, runner.person.profile,
                          session_id=session_id, schedule_index=schedule_index,
                          protocol=protocol)

    with stored_trial(sink, meta, partial=partial, samples=runner.samples) as rec:
        t0 = time.perf_counter()
        bar = (progress_bar(runner.model.n, f"trial {config.schema}", "pt", leave=False)
               if progress else None)
        chunk = 0.25
        last_i = 0
        while not runner.done:
            frame = runner.advance(chunk)
            if bar is not None and frame.goal_index != last_i:
                bar.update(frame.goal_index - last_i)
                last_i = frame.goal_index
        if bar is not None:
            bar.close()
        result = runner.result(wall_time=time.perf_counter() - t0, metric_params=metric_params)
        rec.finish(result)
    return result, rec.trial_id


def vf_meta(config: TrialConfig, *, schema: Schema | None = None,
            session_id: int | None = None, schedule_index: int | None = None,
            protocol: str | None = None) -> TrialMeta:
    """The ``"vf"`` kind's ``TrialMeta`` builder (``vasim.trials.registry``): ``trial_meta``
    with ``config.schema`` loaded unless ``schema`` is given and the operator's profile
    of ``make_profile``."""
    sch = schema if schema is not None else load_schema(config.schema)
    return trial_meta(config, sch, make_profile(config), session_id=session_id,
                      schedule_index=schedule_index, protocol=protocol)


def simulate_vf(config: TrialConfig, params: MetricParams) -> dict[str, Any]:
    """Runs one virtual-fixture trial without a sink (a cohort worker's job); returns what
    the writer stores (``vasim.study.cohort.simulate_trial``).

    Returns:
        dict with ``columns`` (flat sample columns, copies), ``active_fixtures``,
        ``metrics`` (per-point frame), ``summary``, ``events``, ``trial_metrics``,
        ``wall_time`` [s], ``sim_time`` [s].
    """
    t0 = time.perf_counter()
    runner = TrialRunner(config)
    while not runner.done:
        runner.advance(1.0)
    result = runner.result(wall_time=time.perf_counter() - t0, metric_params=params)
    cols = {k: np.array(v) for k, v in result.samples.columns().items()}
    return {"columns": cols, "active_fixtures": result.samples.active_fixtures,
            "metrics": result.metrics, "summary": result.summary, "events": result.events,
            "trial_metrics": result.trial_metrics, "wall_time": result.wall_time,
            "sim_time": float(result.summary["sim_time"])}


__all__ = ["config_record", "run_vf_trial", "simulate_vf", "trial_meta", "vf_meta"]
