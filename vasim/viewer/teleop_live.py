"""Teleoperation trials a person runs in the viewer (issue #28): the ``stdt``, ``mrcp`` and
``mrcp_cam`` trials of a protocol such as ``mrcp_suture_dynamic``, driven by the page's
input instead of the scripted operator.

The trial is :class:`vasim.trials.teleop.TeleopTrial`, the same one ``vasim study
simulate`` runs: the station, the MRCP kernel, the needle route, the abdomen's contact
model and the trial metrics (ET, EM, contact time, accumulated force and torque, Q ...)
are the simulated sessions', and the controller stores the result through the same
``stored_trial`` lifecycle and tables (``teleop_meta``), so ``vasim report`` reads a store
that mixes simulated and person-run sessions. What changes is who moves the masters:

* :class:`DeviceHand` stands where the trial has a scripted hand (``teleop_hands.Hand``:
  ``move``, ``check``, ``done``, ``j``): its master increment is the change of the page's
  device reading (the dragged gizmo's ``BrowserDevice`` or the keyboard/mouse
  instrument's ``LaparoscopicDevice``) since the previous one, read through
  :class:`vasim.viewer.live.DeviceOperator` (an invalid reading or a held clutch button
  moves nothing). Its goals are checked with the scripted hand's reach rule.
* :func:`person_teleop_trial` is the trial with every hand a :class:`DeviceHand` on one
  device: ``TeleopTrial``'s public operator hook, its ``hand_factory``
  (``vasim.operator.port.HandFactory``), gets :class:`DeviceHands`.
  ``tests/viewer/test_teleop_session.py`` fails if the page's input stops moving the
  needle.
* :class:`LiveTeleopTrial` runs it in real time on its own thread with the viewer's
  ``LiveTrial`` shape (``start``, ``stop``, ``done``, ``frame``, ``timing``, ``result``),
  publishing a ``TrialFrame`` per 18 ms cycle: ``tcp`` and ``master`` the needle centre
  (the task the person moves), ``goal`` the current ring where it is now (it rides on the
  breathing tissue), ``abdomen`` the latest physics snapshot (organs and rings drawn as
  for a VF trial).

**Decisions**:

* One input device drives whichever master the trial's phase moves: in ``mrcp`` and
  ``mrcp_cam`` the needle (the kernel chooses the robot and transfers it; the master is
  decoupled during a transfer, as in the simulated trials); in ``stdt`` the instrument
  holding the needle while carrying it, and the free instrument during a hand-over (to the
  pre-grasp point within 5 mm, then the grasp point within 3 mm, after which the jaw
  closes by itself). The seed's StdT has two masters; a page has one pointer and one
  keyboard, so the trial's phase, not the person, picks the master (a simplification,
  stated in docs/experimenter.md). The ``mrcp_cam`` camera follows the needle
  automatically as in the simulated trials (no second input).
* No simulated person is added to a person's movements: the trial's profile gets
  ``perception_noise = 0``, so StdT's jaw placement error is the person's own tip error
  (the simulated jaw misjudgement, ``needle.grasp_sigma``, is 0). The profile's reaction
  delay still times the gripper (``GRIPPER_TIME`` after it) and the acknowledgement of a
  safety stop (``FAULT_ACK_TIME`` after it), which the trial does automatically.
* Pacing: the thread runs as many 18 ms cycles as the wall time elapsed allows (times
  ``speed``), at most ``max_catch_up_s`` per iteration, so a slow cycle slows the trial
  down rather than fast-forwarding it (``live.PacedThread``, shared with the VF trials'
  ``SimThreadTrial``).
"""

from __future__ import annotations

import logging
import math
from collections.abc import Iterator
from dataclasses import replace
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.core.errors import ConfigError
from vasim.fixtures.runtime import FixtureOutputs
from vasim.fixtures.types import CameraView
from vasim.haptics.device import Device
from vasim.haptics.observation import OperatorObservation
from vasim.operator.needle import RING_RADIUS, RING_SITES, needle_task
from vasim.operator.port import HandRequest
from vasim.tasks import Task
from vasim.trials.configs import AnyTrialConfig, TeleopTrialConfig
from vasim.trials.kinds import TELEOPERATION_MODES
from vasim.trials.teleop import CYCLE_DT, TeleopTrial
from vasim.trials.vf import TrialFrame, TrialResult, make_profile
from vasim.viewer.live import DeviceOperator, PacedThread

log = logging.getLogger(__name__)

FloatArray = NDArray[np.float64]

NO_FIXTURES = FixtureOutputs(active=(), dx_slave=np.zeros(3), ms_factors=np.ones(3),
                             ghost=None, force=None, arrows=(), audio=None, camera=None)
"""The fixture outputs of a teleoperation frame: a teleoperation trial has no fixtures."""


def is_teleop(config: AnyTrialConfig) -> bool:
    """True for a teleoperation trial (its own config, ``TeleopTrialConfig``)."""
    return isinstance(config, TeleopTrialConfig)


def teleop_task(config: TeleopTrialConfig) -> Task:
    """The task of a teleoperation trial as the viewer draws it: the rings at rest, in
    visiting order, and the needle's start (``TeleopTrial``'s task: all of ``RING_SITES``,
    pass radius the protocol's ``reach_radius``, else ``RING_RADIUS``)."""
    radius = config.reach_radius if config.reach_radius is not None else RING_RADIUS
    task = needle_task(len(RING_SITES), ring_radius=radius)
    return task.operator_task(task.rings, task.start)


def person_config(config: TeleopTrialConfig) -> TeleopTrialConfig:
    """The config of a trial a person drives: its profile without simulated perception
    noise (module docstring, decisions)."""
    return replace(config, profile=replace(make_profile(config), perception_noise=0.0))


def camera_outputs(trial: TeleopTrial) -> FixtureOutputs:
    """The frame's outputs: none, but in ``mrcp_cam`` the camera robot's view as the
    viewer's endoscope can give it (``CameraView``, which the app maps to its scope as it
    maps Mag's: ``endoscope.scope_from_mag``).

    **Decision**: the trainee's scope aims at the camera robot's aim point (which follows
    the needle with the trial's dead zone and time constant, ``teleop_hands.Camera``) from
    the viewer's camera port, at the robot's lens distance, with the scope's own field of
    view (``fov`` = Mag's, which ``scope_from_mag`` maps to the scope's): the robot's
    narrower 70 deg optics (``CAMERA_ZOOM``, shown as the zoom) is not reproduced.
    """
    if not trial.camera.follows:
        return NO_FIXTURES
    from vasim.fixtures.mag import MagParams

    aim = np.array(trial.camera.aim, dtype=np.float64)
    view = CameraView(position=np.array(trial.camera.robot.lens(aim), dtype=np.float64),
                      look_at=aim, up=np.array([0.0, 0.0, 1.0]),
                      fov=math.radians(MagParams().fov_deg), zoom=trial.camera.zoom)
    return replace(NO_FIXTURES, camera=view)


class DeviceHand:
    """A hand whose master increments come from a device (module docstring): the
    interface of ``vasim.trials.teleop_hands.Hand``.

    Args:
        operator: the device, read as increments (shared by every hand of a trial).
        points: ``(n, 3)`` goals of this path [m]. reach: the reach of each goal [m].
    """

    def __init__(self, operator: DeviceOperator, points: FloatArray,
                 reach: float | tuple[float, ...]) -> None:
        self.operator = operator
        self.points = np.asarray(points, dtype=float).reshape(-1, 3)
        self.reach = np.broadcast_to(np.asarray(reach, dtype=float), (len(self.points),))
        self.j = 0
        self.t = 0.0

    @property
    def done(self) -> bool:
        return self.j >= len(self.points)

    def move(self, dt: float, seen: FloatArray, goal: FloatArray, zoom: float) -> FloatArray:
        """The master increment [m] since the previous reading of the device."""
        self.t += dt
        obs = OperatorObservation(t=self.t, dt=dt, tcp=np.asarray(seen, dtype=np.float64),
                                  goal=np.asarray(goal, dtype=np.float64),
                                  goal_index=min(self.j, len(self.points) - 1))
        d = np.asarray(self.operator.step(obs), dtype=float)
        return np.where(np.isfinite(d), d, 0.0)

    def check(self, position: FloatArray, goal: FloatArray) -> bool:
        """Advances the goal when ``position`` is within reach of it (the scripted hand's
        rule); True if it did."""
        if float(np.linalg.norm(position - goal)) <= self.reach[min(self.j,
                                                                     len(self.reach) - 1)]:
            self.j += 1
            return True
        return False


class DeviceHands:
    """The ``HandFactory`` (``vasim.operator.port``) of a trial a person drives: every
    path's hand is a :class:`DeviceHand` on the same device (module docstring).

    Args:
        operator: the started device, read as increments.
    """

    def __init__(self, operator: DeviceOperator) -> None:
        self.operator = operator

    def __call__(self, request: HandRequest) -> DeviceHand:
        return DeviceHand(self.operator, request.points, request.reach)


def person_teleop_trial(config: TeleopTrialConfig, device: Device,
                        **kw: Any) -> TeleopTrial:
    """A ``TeleopTrial`` whose hands are :class:`DeviceHand` s on ``device`` (its
    ``hand_factory``; ``person_config`` applied by the caller); ``kw``: ``TeleopTrial``'s
    keyword arguments (``n_rings``, ``abdomen``, ...)."""
    return TeleopTrial(config, hand_factory=DeviceHands(DeviceOperator(device)), **kw)


class LiveTeleopTrial(PacedThread):
    """A teleoperation trial in real time on its own thread (module docstring; the pacing
    is ``live.PacedThread``'s, one step = one 18 ms control cycle).

    Args:
        config: the trial (``config.mode`` a teleoperation mode).
        device: the person's input device; None: the scripted operator of ``config`` (a
            protocol session run with the scripted input).
        schema: ignored (the viewer's common factory signature; no fixtures here).
        speed: simulated seconds per wall second (1: real time).
        loop_hz: iterations per second of the thread.
        max_catch_up_s: most simulated time one iteration may advance [s].
        **kw: passed to the trial (``n_rings``, ``abdomen``: shorter tasks in tests).

    Raises:
        ConfigError: not a teleoperation mode, or a bad speed.
    """

    def __init__(self, config: AnyTrialConfig, device: Device | None = None, *,
                 schema: Any = None, speed: float = 1.0, loop_hz: float = 120.0,
                 max_catch_up_s: float = 0.1, **kw: Any) -> None:
        if not isinstance(config, TeleopTrialConfig):
            raise ConfigError(f"not a teleoperation trial: a {config.kind!r} trial's config "
                              f"(a teleoperation mode is one of "
                              f"{', '.join(TELEOPERATION_MODES)})", field="mode")
        super().__init__(device, dt=CYCLE_DT, speed=speed, loop_hz=loop_hz,
                         max_catch_up_s=max_catch_up_s)
        self.config = config
        self.trial: TeleopTrial = (TeleopTrial(config, **kw) if device is None
                                   else person_teleop_trial(config, device, **kw))
        self._cycles: Iterator[int] = self.trial.cycles()
        self._exhausted = False
        self._closed = False
        self._frame = self._make_frame()

    # -- PacedThread ---------------------------------------------------------------------
    def _finished(self) -> bool:
        return bool(self.trial.state.done) or self._exhausted

    def _clock(self) -> tuple[float, int]:
        return max(0.0, self.trial.state.t), self.trial.state.k + 1

    def _advance(self, n: int) -> None:
        self.advance(n)

    def stop(self, timeout: float = 5.0) -> None:
        """Stops the loop and the device; closes the station once the loop is gone."""
        super().stop(timeout)
        if self._closed or self.running:
            return
        self._closed = True
        try:   # the station's physics client (pybullet)
            self.trial.station.close()
        except Exception:
            log.exception("closing the teleoperation station failed")

    # -- LiveTrial -----------------------------------------------------------------------
    def frame(self) -> TrialFrame:
        return self._frame

    def result(self, **kw: Any) -> TrialResult:
        """The trial's result so far (call after ``stop()`` or once ``done``);
        ``metric_params`` as ``TeleopTrial.result`` takes it."""
        with self._lock:
            return self.trial.result(wall_time=self._wall,
                                     metric_params=kw.get("metric_params"))

    # -- stepping ------------------------------------------------------------------------
    def advance(self, n: int) -> int:
        """Runs up to ``n`` control cycles now (the loop's step; tests call it directly
        without starting the thread); returns the cycles run."""
        ran = 0
        with self._lock:
            while ran < n and not self.done:
                try:
                    next(self._cycles)
                except StopIteration:
                    self._exhausted = True
                    break
                ran += 1
            if ran or self.done:
                self._frame = self._make_frame()
        return ran

    def _make_frame(self) -> TrialFrame:
        tr = self.trial
        n = tr.task.n_rings
        needle = np.array(tr.state.needle, dtype=np.float64)
        snap = tr.abdomen.latest if tr.abdomen is not None else None
        st = tr.state
        return TrialFrame(k=st.k, t=max(0.0, st.t), tcp=needle, master=needle.copy(),
                          goal=np.array(st.rings[min(st.i, n - 1)], dtype=np.float64),
                          goal_index=int(st.i), n_points=n,
                          done=self.done, outputs=camera_outputs(tr), abdomen=snap)


def make_live_teleop_trial(config: AnyTrialConfig, device: Device | None = None, *,
                           schema: Any = None, speed: float = 1.0) -> LiveTeleopTrial:
    """The viewer's factory of teleoperation trials (``TrainingController``)."""
    return LiveTeleopTrial(config, device, schema=schema, speed=speed)


__all__ = [
    "NO_FIXTURES",
    "DeviceHand",
    "DeviceHands",
    "LiveTeleopTrial",
    "camera_outputs",
    "is_teleop",
    "make_live_teleop_trial",
    "person_config",
    "person_teleop_trial",
    "teleop_task",
]
