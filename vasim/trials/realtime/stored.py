"""A stored real-time trial: the loop (threaded or in its own process) run to its end and
written through a sink with its timing and its recording."""

from __future__ import annotations

import json
import logging
import time
from dataclasses import replace
from typing import Any

from vasim.core.config import expect
from vasim.core.errors import DeviceError
from vasim.fixtures.schema import Schema
from vasim.haptics.device import Device
from vasim.operator.device import ScriptedDevice
from vasim.records.trial_meta import TrialMeta
from vasim.trials.lifecycle import stored_trial
from vasim.trials.realtime.loop import RealtimeTrial
from vasim.trials.realtime.plant import PhysicsMode
from vasim.trials.realtime.process import ProcessRealtimeTrial
from vasim.trials.realtime.timing import RealtimeTiming
from vasim.trials.sink import Event, TrialSink, check_sink
from vasim.trials.vf import TrialConfig, TrialResult, make_profile
from vasim.trials.vf_run import trial_meta

log = logging.getLogger(__name__)


def run_realtime_trial(config: TrialConfig, sink: TrialSink | None = None,
                       device: Device | None = None, *, schema: Schema | None = None,
                       physics: PhysicsMode = "thread", process: bool = False,
                       device_factory: Any = None, device_name: str | None = None,
                       poll_s: float = 0.05, on_poll: Any = None,
                       ) -> tuple[TrialResult, int | None, RealtimeTiming]:
    """Runs one trial in real time and stores it like ``run_trial``, with its timing and
    its recording.

    With a sink (e.g. a ``TrialStore``) the trial row is created as 'running' once the
    loop runs and completed in one transaction when the trial is done (samples, per-point and trial
    metrics, events, and the timing as ``timing_json``); the device stream and the physics
    log are written next to the database (``stream_path``, ``realtime_path``; the file
    names are in the timing's ``recording``). Ctrl-C or an error marks it 'interrupted'
    with the partial result (and still writes the recording, named by a ``recording``
    event) and re-raises (``vasim.trials.lifecycle.stored_trial``).

    Args:
        config: the trial. sink: a ``TrialSink`` or None. device: the input device
            (None: the scripted operator). schema: overrides ``config.schema``.
        physics: ``"thread"`` (real time) or ``"off"``.
        process: run the servo loop in its own process
            (``vasim.trials.realtime.process``: measured steadier on a loaded host); the
            device is then built there by ``device_factory`` (picklable; None: the
            scripted operator) and stored under ``device_name``.
        poll_s: how often the caller's thread checks for the end [s].
        on_poll: optional ``fn(trial)`` called at every poll (progress display).

    Returns:
        (result, trial_id or None, timing).
    """
    expect(physics != "inline", physics, "'thread' or 'off' ('inline' cannot keep real "
           "time)", field="physics")
    sink = check_sink(sink)
    trial: RealtimeTrial | ProcessRealtimeTrial
    if process:
        expect(device is None, type(device).__name__, "no device object: it cannot move to "
               "the servo process (pass device_factory, or process=False)", field="device")
        trial = ProcessRealtimeTrial(config, device_factory, schema=schema, physics=physics)
        scripted = device_factory is None
        name = "scripted" if scripted else (device_name or "device")
    else:
        trial = RealtimeTrial(config, device, schema=schema, physics=physics)
        scripted = isinstance(trial.device, ScriptedDevice)
        name = getattr(trial.device, "name", "device")

    def meta() -> TrialMeta:  # built only with a sink
        m = trial_meta(config, trial.runner.schema, make_profile(config))
        if scripted:
            return m
        cfg = dict(m.config or {})
        cfg["operator"] = name
        cfg.pop("profile", None)  # no simulated person behind a device
        return replace(m, operator=name, config=cfg)

    def save_recording(trial_id: int | None) -> dict[str, str] | None:
        if sink is None or trial_id is None:
            return None
        p_dev, p_rt = trial.recording().save(sink.path, trial_id)
        return {"device_stream": p_dev.name, "realtime": p_rt.name}

    def recording_event() -> list[Event]:
        """On interruption: the trial stopped, its recording saved and named (an event)."""
        trial.stop()
        try:
            files = save_recording(rec.trial_id)
        except Exception as rec_exc:  # the store's row matters more than the recording
            log.warning("trial %s: the recording could not be saved: %s", rec.trial_id,
                        rec_exc)
            log.debug("recording failure", exc_info=True)
            files = None
        return [(None, "recording", json.dumps(files))]

    try:
        # The row is created once the device runs: a device that cannot start leaves no
        # stray 'interrupted' trial behind, only its one-line error.
        trial.start()
        with stored_trial(sink, meta, partial=trial.result, events=recording_event) as rec:
            while not trial.done and trial.running:
                time.sleep(poll_s)
                if on_poll is not None:
                    on_poll(trial)
            trial.stop()
            err = trial.error
            if err is not None:
                raise DeviceError(f"the real-time trial stopped: {err!s}") from (
                    err if isinstance(err, BaseException) else None)
            result = trial.result()
            timing = trial.timing()
            if rec.trial_id is not None:  # (no recording files without a sink)
                rec.finish(result, timing={**timing.to_dict(),
                                           "recording": save_recording(rec.trial_id)})
    except BaseException:
        trial.stop()
        raise
    return result, rec.trial_id, timing


__all__ = ["run_realtime_trial"]
