"""Running a teleoperation trial headless and storing it: the ``"stdt"``, ``"mrcp"`` and
``"mrcp_cam"`` trial kinds' runner, row builder and cohort job (``vasim.trials.registry``).
"""

from __future__ import annotations

import os
import socket
import time
from typing import TYPE_CHECKING, Any

import numpy as np

from vasim.fixtures.schema import Schema, dumps_schema, load_schema
from vasim.records.trial_meta import TrialMeta
from vasim.records.trial_metrics import MetricParams
from vasim.trials.lifecycle import stored_trial
from vasim.trials.sink import TrialSink
from vasim.trials.teleop import CYCLE_DT, TeleopTrial
from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.vf import TrialResult, make_profile
from vasim.trials.vf_run import config_record

if TYPE_CHECKING:
    from vasim.abdomen.world import Abdomen


def teleop_meta(config: TeleopTrialConfig, *, schema: Schema | None = None,
                session_id: int | None = None, schedule_index: int | None = None,
                protocol: str | None = None) -> TrialMeta:
    """The store's ``TrialMeta`` of a teleoperation trial (task ``"needle"``, schema
    ``"none"``: a ``schema`` argument is ignored; it is there for the trial-kind registry's
    common signature)."""
    profile = make_profile(config)  # the configured profile, else the skill's preset
    return TrialMeta(
        subject=config.subject, task="needle", variant=0, schema="none",
        operator=config.operator, seed=config.seed, dt=CYCLE_DT, active_fixtures="",
        pid=os.getpid(), host=socket.gethostname(), config=config_record(config, profile),
        schema_toml=dumps_schema(load_schema("none")), session_id=session_id,
        schedule_index=schedule_index, protocol=protocol)


def simulate_teleop(config: TeleopTrialConfig, params: MetricParams) -> dict[str, Any]:
    """``vasim.study.cohort.simulate_trial`` for a teleoperation trial (same dict)."""
    t0 = time.perf_counter()
    trial = TeleopTrial(config)
    try:
        for _ in trial.cycles():
            pass
        result = trial.result(wall_time=time.perf_counter() - t0, metric_params=params)
    finally:
        trial.station.close()
    cols = {k: np.array(v) for k, v in result.samples.columns().items()}
    return {"columns": cols, "active_fixtures": "", "metrics": result.metrics,
            "summary": result.summary, "events": result.events,
            "trial_metrics": result.trial_metrics, "wall_time": result.wall_time,
            "sim_time": float(result.summary["sim_time"])}


def run_teleop_trial(config: TeleopTrialConfig, sink: TrialSink | None = None, *,
                     progress: bool = False, session_id: int | None = None,
                     schedule_index: int | None = None,
                     protocol: str | None = None, metric_params: MetricParams | None = None,
                     n_rings: int | None = None, abdomen: Abdomen | None = None,
                     ) -> tuple[TrialResult, int | None]:
    """``vasim.trials.vf.run_vf_trial`` for a teleoperation mode (the ``"stdt"``,
    ``"mrcp"`` and ``"mrcp_cam"`` kinds of ``vasim.trials.registry``): runs the trial
    headless and, with a sink, stores it the same way (row 'running' first, everything in one
    transaction at the end, 'interrupted' with the partial samples on any exception).

    ``n_rings`` and ``abdomen`` are passed to :class:`TeleopTrial` (shorter tasks, a shared
    abdomen in tests). ``progress`` is accepted for the registry's common signature and
    ignored (a teleoperation trial shows no progress bar, as before)."""
    trial = TeleopTrial(config, n_rings=n_rings, abdomen=abdomen)
    t0 = time.perf_counter()

    def partial() -> TrialResult:
        return trial.result(wall_time=time.perf_counter() - t0, metric_params=metric_params)

    def meta() -> TrialMeta:  # built only with a sink
        return teleop_meta(config, session_id=session_id, schedule_index=schedule_index,
                           protocol=protocol)

    try:
        with stored_trial(sink, meta, partial=partial) as rec:
            t0 = time.perf_counter()
            for _ in trial.cycles():
                pass
            result = trial.result(wall_time=time.perf_counter() - t0,
                                  metric_params=metric_params)
            rec.finish(result)
    finally:
        trial.station.close()
    return result, rec.trial_id


__all__ = ["run_teleop_trial", "simulate_teleop", "teleop_meta"]
