"""The VF trial engine's data: the frozen model (what the trial is) apart from its state
(what changes per step), as dm_control's composer keeps a task apart from its physics.

* :class:`VfTrialModel` -- frozen: the config, the schema, the task, the control step, the
  limits, and what is derived from them once (reach radius squared, the velocity filter's
  coefficient, the tool's fulcrum, whether Mag drives the camera, the buffer capacity).
* :class:`VfGeometry` -- the POIs where they are now (they ride on the tissue, so a physics
  snapshot replaces the geometry), with the loop's float caches: goals, normals, path
  segments and look-ahead points.
* :class:`VfTrialState` -- everything a control step changes: step index, time, TCP, master,
  velocity, goal index, reach times, the last render (cues), MS factors, the tissue's force
  and stiffness, the physics snapshot, the samples and events, ``done``.
* :class:`VfPercept` -- what the operator perceives at a step (``vasim.operator.port``),
  refreshed in place by the engine's observe phase (no allocation per step).

All fields are public: the real-time plant, the servo child process and the viewer read the
state through ``runner.state`` instead of private attributes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vasim.core.config import expect
from vasim.fixtures.schema import Schema, load_schema
from vasim.haptics.observation import OperatorObservation
from vasim.records.samples import SampleBuffer
from vasim.tasks import Task
from vasim.tasks.base import polyline_lookahead
from vasim.trials.ports import tool_trocar
from vasim.trials.vf_config import TrialConfig, make_task

if TYPE_CHECKING:
    from vasim.abdomen.contact import ContactPatch
    from vasim.abdomen.snapshot import AbdomenSnapshot

GUIDANCE_SEEN = 0.05
"""The operator notices the VG arrow when its opacity exceeds this."""

MAX_PREALLOCATED = 1_000_000
"""Sample rows preallocated at most (~170 MB); longer trials grow the buffer."""

_ZERO3: tuple[float, ...] = (0.0, 0.0, 0.0)


@dataclass(frozen=True, eq=False)
class VfTrialModel:
    """What a VF trial is (never changes while it runs).

    Attributes:
        config: the trial's configuration. schema: its fixture schema. task: its task.
        dt: control step [s]. max_time: time limit [s].
        n: number of POIs. r2: reach radius squared [m^2]. scale: the task's scale.
        kind: the task's kind. trajectory: True for trajectory following.
        start_xyz: the tool's start (3 floats) [m]. fulcrum: (3,) the tool's trocar [m].
        alpha: coefficient of the TCP velocity's first-order low-pass filter.
        mag_camera: True when Mag drives the camera (``in_view`` per step).
        capacity: sample rows preallocated.
    """

    config: TrialConfig
    schema: Schema
    task: Task
    dt: float
    max_time: float
    n: int
    r2: float
    scale: float
    kind: str
    trajectory: bool
    start_xyz: tuple[float, ...]
    fulcrum: np.ndarray
    alpha: float
    mag_camera: bool
    capacity: int

    @classmethod
    def build(cls, config: TrialConfig, schema: Schema | None = None) -> VfTrialModel:
        """The model of ``config`` (``schema``: an already loaded schema overriding
        ``config.schema``).

        Raises:
            ConfigError: the schema is for another task.
        """
        sch = schema if schema is not None else load_schema(config.schema)
        task = make_task(config)
        expect(sch.task in ("any", task.kind), sch.name, f"a schema for {task.kind!r} tasks "
               f"({sch.name!r} is for {sch.task!r} tasks)", field="schema")
        start = np.asarray(task.start, dtype=np.float64)
        return cls(
            config=config, schema=sch, task=task, dt=config.dt, max_time=config.max_time,
            n=len(task.points), r2=task.reach_radius ** 2, scale=task.scale,
            kind=task.kind, trajectory=task.kind == "trajectory",
            start_xyz=tuple(start.tolist()),
            fulcrum=np.asarray(tool_trocar(task.kind, task.start), dtype=np.float64),
            alpha=1.0 - math.exp(-2.0 * math.pi * config.velocity_cutoff_hz * config.dt),
            mag_camera=sch.camera is not None,
            capacity=min(int(config.max_time / config.dt) + 2, MAX_PREALLOCATED))


class VfGeometry:
    """The POIs where they are now and the loop's float caches derived from them.

    Goals, path segments and normals are kept as tuples of floats for the loop; look-ahead
    points (Mag's aim) and segments are computed on first use per geometry.

    Args:
        points: (n, 3) POIs [m]. normals: (n, 3) their surface normals, or None.
        start_xyz: the tool's start (the first segment starts there).
    """

    __slots__ = ("goal_xyz", "lookahead_xyz", "normal_xyz", "normals", "points",
                 "segments", "start_xyz")

    def __init__(self, points: np.ndarray, normals: np.ndarray | None,
                 start_xyz: tuple[float, ...]) -> None:
        self.points = np.asarray(points, dtype=np.float64)
        self.normals = None if normals is None else np.asarray(normals, dtype=np.float64)
        self.start_xyz = start_xyz
        self.goal_xyz = [tuple(p) for p in self.points.tolist()]
        self.normal_xyz = (None if self.normals is None
                           else [tuple(nv) for nv in self.normals.tolist()])
        self.lookahead_xyz: dict[int, tuple[float, ...]] = {}
        self.segments: dict[int, tuple[tuple[float, ...], tuple[float, ...], float]] = {}

    def segment(self, i: int) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        """Path segment [p_(i-1), p_i] (the tool's start for i = 0) for the fixture goal
        (``vasim.trials.vf`` docstring, decision): start a, direction ab and 1/|ab|^2."""
        seg = self.segments.get(i)
        if seg is None:
            a = self.start_xyz if i == 0 else self.goal_xyz[i - 1]
            b = self.goal_xyz[i]
            ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
            n2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]
            seg = self.segments[i] = (a, ab, 1.0 / n2 if n2 > 0 else 0.0)
        return seg

    def lookahead(self, i: int) -> tuple[float, ...]:
        """Mag's aim point for goal i (``Task.lookahead``)."""
        la = self.lookahead_xyz.get(i)
        if la is None:
            la = self.lookahead_xyz[i] = tuple(
                polyline_lookahead(self.points, i).tolist())
        return la

    def fixture_goal(self, x: tuple[float, ...], i: int,
                     trajectory: bool) -> tuple[float, ...]:
        """g_f(k): nearest point of segment i to x (trajectory), or the POI (point task)."""
        if not trajectory:
            return self.goal_xyz[i]
        a, ab, inv = self.segment(i)
        u = ((x[0] - a[0]) * ab[0] + (x[1] - a[1]) * ab[1] + (x[2] - a[2]) * ab[2]) * inv
        u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        return (a[0] + u * ab[0], a[1] + u * ab[1], a[2] + u * ab[2])


@dataclass(slots=True, eq=False)
class VfTrialState:
    """Everything a control step changes (floats as tuples: the loop builds no arrays).

    Attributes:
        geometry: the POIs where they are now. k: step index (-1 before the first).
        t: simulated time [s]. x: TCP x(k). m: master (hand) position. v: filtered TCP
        velocity. i: index of the current goal. err: Manhattan error accumulated for it.
        reach_times: reach time of each reached POI. ms: MS factors of the last step.
        cues: the last render (force x, y, z, zoom, audio pitch, period, volume, VG
        opacity). fc: tissue force on the tip [N]. tc: tissue torque. kt: dF/dx of the
        tissue force (row-major 9 floats) or None. contact, delicate: 0/1 flags.
        n_bad_input: non-finite increments dropped. done: the trial has ended.
        snap: the latest physics snapshot (None: static task). patch: its contact planes.
        samples: the sample buffer. events: (t, kind, detail) log.
    """

    geometry: VfGeometry
    samples: SampleBuffer
    x: tuple[float, ...]
    m: tuple[float, ...]
    v: tuple[float, ...] = _ZERO3
    k: int = -1
    t: float = 0.0
    i: int = 0
    err: float = 0.0
    reach_times: list[float] = field(default_factory=list)
    ms: tuple[float, ...] = (1.0, 1.0, 1.0)
    cues: tuple[float, ...] = ()
    fc: tuple[float, ...] = _ZERO3
    tc: tuple[float, ...] = _ZERO3
    kt: tuple[float, ...] | None = None
    contact: int = 0
    delicate: int = 0
    n_bad_input: int = 0
    done: bool = False
    snap: AbdomenSnapshot | None = None
    patch: ContactPatch | None = None
    events: list[tuple[float, str, str]] = field(default_factory=list)

    @classmethod
    def initial(cls, model: VfTrialModel) -> VfTrialState:
        """The state before the first step: the tool at the task's start, nothing logged."""
        x = model.start_xyz
        return cls(geometry=VfGeometry(np.asarray(model.task.points, dtype=np.float64),
                                       model.task.normals, x),
                   samples=SampleBuffer(capacity=model.capacity, active_fixtures=",".join(
                       model.schema.fixture_names)),
                   x=x, m=x)


class VfPercept:
    """What the operator perceives at a step (``vasim.operator.port.Percept``); the
    engine's observe phase refreshes it in place."""

    __slots__ = ("audio_volume", "cues", "dt", "force", "goal", "goal_index", "guidance",
                 "ms_factors", "t", "tcp", "zoom")

    def __init__(self, dt: float) -> None:
        self.dt = dt
        self.t = 0.0
        self.tcp: tuple[float, ...] = _ZERO3
        self.goal: tuple[float, ...] = _ZERO3
        self.goal_index = 0
        self.guidance = False
        self.audio_volume = 0.0
        self.zoom = 1.0
        self.ms_factors: tuple[float, ...] = (1.0, 1.0, 1.0)
        self.force: tuple[float, ...] = _ZERO3
        self.cues: tuple[float, ...] = ()

    def observe(self, st: VfTrialState, n: int) -> None:
        """Takes the step's view from the state: the last frame as the person sees it and
        the force on the hand (the fixtures' and the tissue's)."""
        cues = st.cues
        fc = st.fc
        i = st.i if st.i < n else n - 1
        self.t = st.t
        self.tcp = st.x
        self.goal = st.geometry.goal_xyz[i]
        self.goal_index = i
        self.guidance = cues[7] > GUIDANCE_SEEN
        self.audio_volume = cues[6]
        self.zoom = cues[3]
        self.ms_factors = st.ms
        self.force = (cues[0] + fc[0], cues[1] + fc[1], cues[2] + fc[2])
        self.cues = cues

    def observation(self) -> OperatorObservation:
        """The percept as an ``OperatorObservation`` (the force: the fixtures' only, as
        a device renders it; the tissue's is the device's own)."""
        cues = self.cues
        return OperatorObservation(
            t=self.t, dt=self.dt, tcp=np.array(self.tcp), goal=np.array(self.goal),
            goal_index=self.goal_index, force=np.array(cues[0:3]),
            ms_factors=np.array(self.ms_factors), guidance=self.guidance,
            audio_volume=self.audio_volume, audio_pitch_hz=cues[4], zoom=self.zoom,
        )


__all__ = ["GUIDANCE_SEEN", "MAX_PREALLOCATED", "VfGeometry", "VfPercept", "VfTrialModel",
           "VfTrialState"]
