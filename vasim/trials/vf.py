"""One trial: the 1 kHz control loop that ties operator, fixtures and task together.

The same runner serves a headless trial (``vasim trial``), the viewer's demo and (later) the
study sessions; only the input device differs. Per control step k (``dt`` = 1 ms by default),
in the order of spec/fixtures.md §4:

1. the operator (a device: here the scripted operator) perceives the last frame and moves the
   master by ``dX_M``; a non-finite increment is dropped (zero motion) and logged as an event,
   so NaN/inf never reaches the task or the force output;
2. MS (stage 1 of the schema) scales the increment: ``dX_S = dX_M / MS``;
3. the task updates: ``x(k) = x(k-1) + dX_S``; the goal advances when ``|x - p_i| <= r_reach``
   (spec/study.md §2 **decision**, ``r_reach`` = ``task.reach_radius``, default 5 mm), and the
   reach time ``t_p`` is stored;
4. the parallel channels (FF + cone walls, AG, VG, Mag) are rendered from the updated state;
   MS (step 2) and these channels act on the *fixture goal* g_f(k) defined below;
5. the sample (k, t, x, g, goal index, force, MS factors, zoom, audio) is appended to a
   preallocated buffer (no allocation per sample).

**decision** (spec/fixtures.md §2 names the goal "the POI, or the nearest/next point of the
planned trajectory"; §2 also asks that AG be silent, FF negligible, MS small and VG faded
*on the path*): in trajectory following the fixtures act on the deviation from the path.
Their goal g_f(k) is the point of the current path segment [p_(i-1), p_i] nearest to x(k)
(the segment from the tool's start point for i = 0). With the POIs ~1 cm apart, using p_i
itself would make every fixture fire while the tool lies exactly on the path. In point
targeting g_f(k) is the POI. The logged goal g(k), the reach test and the metrics e_i and
l_i always use the POI p_i (spec/study.md eq. 6.5), and the operator aims at p_i.

Samples: row k holds t = (k + 1) dt, x(k) after the step and the goal g(k) = p_i it was
compared with (the goal advances after the row is logged); the start state (t = 0) is not
a row. The buffer is preallocated for ``max_time`` so the loop never reallocates.

Camera view (``in_view`` sample column, **decision**): whether the tool tip lies inside the
endoscope camera's field of view, taken as the cone of half-angle fov/2 around the optical
axis (an endoscope's image is circular). With a Mag fixture active the camera is Mag's
smoothed camera of that step. Otherwise it is the fixed ``DEFAULT_ENDOSCOPE``: lens at the
camera trocar (``vasim.abdomen.anatomy.trocar_points()[0]``, near the umbilicus), optical
axis toward the workspace centre (``vasim.tasks.WORKSPACE_CENTRE``), full field of view
100 deg -- a wide-angle scope, chosen so that every POI and start point of the seven
trajectory variants (at most 48 deg off axis) and of the point task (33 deg) is in view:
out-of-view time then measures excursions away from the task, not the task's own layout.
For the fixed camera the column is computed from x after the loop (vectorised).

The TCP velocity used by FF's damping term is the finite difference of x filtered by a
first-order low-pass (``velocity_cutoff_hz``, default 30 Hz): raw 1 kHz differences of a
tremor-laden hand would make the damping force buzz.

The engine (**issue #29**, as dm_control's composer): the trial is a frozen
:class:`~vasim.trials.vf_model.VfTrialModel` (config, schema, task, limits) plus a
:class:`~vasim.trials.vf_model.VfTrialState` (what a step changes), and one control step
is a fixed sequence of named phases, each a method of :class:`TrialRunner`:

===================  =======================================================================
``before_step``      the clock: k += 1, t = (k + 1) dt
``physics_phase``    the abdomen's step when due (every ``abdomen.dt``, or a physics feed):
                     the POIs follow the tissue, the contact planes renew
``observe``          the percept (``vasim.operator.port.Percept``) from the last frame
``operator_phase``   the operator's dX_M (``TrialOperator.act``; any operator, no dispatch)
``master_phase``     the guard (a non-finite dX_M is dropped and logged), the master moves
``task_phase``       MS scales the motion, x(k) moves, the velocity filter, the reach test
``fixtures_phase``   the fixtures' parallel channels rendered for x(k)
``contact_phase``    the tissue force against the last physics step's contact planes
``record_phase``     the sample row
``after_step``       ``done = should_terminate()`` (every POI reached, or ``max_time``)
===================  =======================================================================

``_tick`` only calls them in this order (steps 1-5 above: operator = 1, master + task = 2-3,
fixtures = 4, record = 5).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING

import numpy as np
import pandas as pd

from vasim.abdomen.contact import ToolPose, patch_force
from vasim.core.errors import ConfigError
from vasim.fixtures.gain_runtime import GainedRuntime
from vasim.fixtures.runtime import FixtureOutputs, SchemaRuntime
from vasim.fixtures.schema import Schema
from vasim.fixtures.types import TaskState, Vec3
from vasim.haptics.observation import OperatorObservation
from vasim.operator.port import MasterIncrement, TrialOperator
from vasim.operator.scripted import ScriptedOperator
from vasim.records.point_metrics import evaluate_trial
from vasim.records.samples import SampleBuffer
from vasim.records.trial_metrics import MetricParams, trial_metrics
from vasim.tasks import Task
from vasim.trials.configs import AnyTrialConfig
from vasim.trials.endoscope import DEFAULT_ENDOSCOPE
from vasim.trials.ports import tool_trocar
from vasim.trials.vf_config import SkillName, TaskName, TrialConfig, make_profile, make_task
from vasim.trials.vf_model import VfGeometry, VfPercept, VfTrialModel, VfTrialState

if TYPE_CHECKING:
    from vasim.abdomen.snapshot import AbdomenSnapshot
    from vasim.abdomen.world import Abdomen


@dataclass(frozen=True, eq=False)
class TrialFrame:
    """An immutable snapshot of the trial after step k (what the viewer and recorder read).

    Attributes:
        k: step index. t: simulated time [s]. tcp: (3,) slave TCP [m]. master: (3,) master
        (hand) position [m]. goal: (3,) current goal point [m]. goal_index: index of the goal
        (== n_points when all are reached). outputs: the fixture outputs of this step.
        last_latency: latency l_i of the last reached point [s] (None before the first).
        error_l1: cumulative Manhattan error accumulated for the current goal so far [m].
        abdomen: the latest physics snapshot (deforming organs, moving targets, contact), or
            None for a static task.
        tissue_force: (3,) tissue contact force on the tool tip this step [N], or None.
        gain: the fixture gain of this step's render (``vasim.fixtures.gain``; 1: the
            schema as written).
    """

    k: int
    t: float
    tcp: Vec3
    master: Vec3
    goal: Vec3
    goal_index: int
    n_points: int
    done: bool
    outputs: FixtureOutputs
    last_latency: float | None = None
    error_l1: float = 0.0
    abdomen: AbdomenSnapshot | None = None
    tissue_force: Vec3 | None = None
    gain: float = 1.0


@dataclass(frozen=True, eq=False)
class TrialResult:
    """A finished (or stopped) trial: config, samples, per-point metrics and summary."""

    config: AnyTrialConfig
    schema: Schema
    task: Task
    samples: SampleBuffer
    metrics: pd.DataFrame
    summary: dict[str, float | int | bool | str]
    events: list[tuple[float, str, str]]
    wall_time: float
    trial_metrics: dict[str, float] = field(default_factory=dict)
    """``vasim.records.trial_metrics.trial_metrics`` of the trial (see ``TRIAL_METRICS``)."""


PhysicsFeed = Callable[[int, ToolPose], "AbdomenSnapshot | None"]
"""``feed(k, pose) -> snapshot or None``: the physics of a trial run outside its steps
(``TrialRunner.set_physics_feed``): k the control step, pose the tool before the step."""


class TrialRunner:
    """Runs one trial step by step: the phases of the module docstring over a frozen model
    and a mutable state (a thin stateful shell around the pure fixtures).

    Attributes:
        model: what the trial is (``VfTrialModel``). state: what a step changes
            (``VfTrialState``). percept: what the operator perceives (``VfPercept``).
        config, schema, task: the model's (shortcuts). runtime: the fixtures' runtime.
        person: the config's simulated person (``ScriptedOperator``), the default operator.
        operator: the input source (``vasim.operator.port.TrialOperator``); replace it to
            drive the trial from elsewhere (``MasterIncrement``, ``ObservingOperator``).
        abdomen: the virtual abdomen, or None for a static task (scene ``"none"``).

    Example:
        >>> runner = TrialRunner(TrialConfig(schema="ff", seed=1, max_time=0.01))
        >>> frame = runner.advance(0.005)
        >>> frame.k
        4
    """

    def __init__(self, config: TrialConfig, schema: Schema | None = None):
        self.model = model = VfTrialModel.build(config, schema)
        self.config = config
        self.schema = model.schema
        self.task = model.task
        self.runtime = (SchemaRuntime(self.schema) if config.gain == 1.0
                        else GainedRuntime(self.schema, config.gain))
        self.person = ScriptedOperator(make_profile(config), self.task, seed=config.seed,
                                       practice=config.practice)
        self.operator: TrialOperator = self.person
        self.state = st = VfTrialState.initial(model)
        self.percept = VfPercept(model.dt)
        # The virtual abdomen: the POIs ride on the tissue, the tool touches it.
        self.abdomen: Abdomen | None = None
        self._physics_feed: PhysicsFeed | None = None
        self._phys_every = 1
        if config.scene != "none":
            from vasim.abdomen.world import Abdomen

            self.abdomen = Abdomen(config.scene)
            self.abdomen.bind_targets(st.geometry.points)
            self._phys_every = max(1, round(self.abdomen.dt / config.dt))
            st.snap = self.abdomen.latest
        start = np.array(self.task.start, dtype=np.float64)
        self.runtime.reset(start)
        self.operator.reset(start)
        # The first render (t = 0, no motion): what the operator perceives at the first step.
        zero = (0.0, 0.0, 0.0)
        state = self._task_state(zero) if self.runtime.needs_state else None
        st.ms = self.runtime.scale_motion_xyz(
            st.x, self._fixture_goal(st.x, 0), zero, model.scale, state)[3:]
        st.cues = self._render(zero)
        self._publish()

    # -- the state's outputs, as attributes of the runner -------------------------------
    @property
    def samples(self) -> SampleBuffer:
        """The sample buffer (``state.samples``)."""
        return self.state.samples

    @samples.setter
    def samples(self, value: SampleBuffer) -> None:
        self.state.samples = value

    @property
    def events(self) -> list[tuple[float, str, str]]:
        """The (t, kind, detail) log (``state.events``)."""
        return self.state.events

    @events.setter
    def events(self, value: list[tuple[float, str, str]]) -> None:
        self.state.events = value

    @property
    def done(self) -> bool:
        """The trial has ended (``state.done``)."""
        return self.state.done

    @done.setter
    def done(self, value: bool) -> None:
        self.state.done = value

    # -- helpers -------------------------------------------------------------------------
    def set_physics_feed(self, feed: PhysicsFeed | None) -> None:
        """Lets ``feed`` supply the physics instead of stepping the abdomen inline.

        With a feed, every control step calls ``feed(k, pose)`` with the tool pose before
        the step's motion (the pose the inline step would use); a returned snapshot is
        applied as an inline step's would be (POIs, contact planes, torque, events), None
        keeps the current one. The real-time trial (``vasim.trials.realtime``) feeds the
        latest snapshot of a physics thread this way, and a replay feeds the recorded ones
        at the recorded steps. None restores inline stepping every ``abdomen.dt``.
        """
        if self.abdomen is None:
            raise ConfigError("this trial has no abdomen (scene 'none'): nothing to feed",
                              field="scene")
        self._physics_feed = feed
        self._phys_every = 1 if feed is not None else max(
            1, round(self.abdomen.dt / self.config.dt))

    def _apply_snapshot(self, snap: AbdomenSnapshot) -> None:
        """Takes a physics snapshot: the POIs follow the tissue, the contact planes renew."""
        st = self.state
        st.snap = snap
        st.geometry = VfGeometry(snap.targets, snap.target_normals
                                 if self.task.normals is not None else None,
                                 self.model.start_xyz)
        st.patch = snap.patch if snap.patch.size else None
        st.tc = tuple(snap.torque.tolist())
        st.delicate = 1 if snap.delicate_contact else 0
        for kind, detail in snap.events:
            st.events.append((snap.t, kind, detail))

    def _fixture_goal(self, x: tuple[float, ...], i: int) -> tuple[float, ...]:
        """g_f(k): nearest point of segment i to x (trajectory), or the POI (point task)."""
        return self.state.geometry.fixture_goal(x, i, self.model.trajectory)

    def _task_state(self, dx_master: tuple[float, ...]) -> TaskState:
        """The step as a ``TaskState`` (only for schemas with a fixture that needs one)."""
        st = self.state
        i = min(st.i, self.model.n - 1)
        geo = st.geometry
        return TaskState(
            tcp=np.array(st.x), goal=np.array(self._fixture_goal(st.x, i)),
            tcp_velocity=np.array(st.v),
            dx_master=np.array(dx_master), scale=self.model.scale, t=st.t,
            kind=self.task.kind, lookahead=np.array(geo.lookahead(i)),
            normal=None if geo.normals is None else geo.normals[i],
        )

    def _render(self, dx_master: tuple[float, ...]) -> tuple[float, ...]:
        """Renders the fixtures' parallel channels for the current x(k).

        Returns ``SchemaRuntime.render_xyz``'s values: (force x, y, z, zoom, audio pitch,
        period, volume, guidance-arrow opacity).
        """
        st = self.state
        i = min(st.i, self.model.n - 1)
        geo = st.geometry
        rt = self.runtime
        state = self._task_state(dx_master) if rt.needs_state else None
        # The error rate is the TCP velocity: the goals' own motion (breathing, at most a
        # few mm/s) is left out of FF's damping term. Only Mag aims at the look-ahead point.
        gf = self._fixture_goal(st.x, i)
        return rt.render_xyz(
            st.x, gf, st.v, st.t, self.model.scale, self.task.kind,
            geo.lookahead(i) if self.model.mag_camera else gf,
            None if geo.normal_xyz is None else geo.normal_xyz[i], state)

    def observation(self) -> OperatorObservation:
        """What the operator perceives now, as an ``OperatorObservation`` (the real-time
        plant's scripted device reads it between steps)."""
        self.observe()
        return self.percept.observation()

    # -- the loop ------------------------------------------------------------------------
    @property
    def frame(self) -> TrialFrame:
        """The latest published snapshot (immutable: safe to read from another thread).

        ``step()`` publishes after every step, ``advance()`` once at the end of its run.
        """
        return self._frame

    def step(self) -> TrialFrame:
        """Advances one control step; returns the new frame."""
        if not self.state.done:
            self._tick()
            self._publish()
        return self._frame

    def advance(self, seconds: float) -> TrialFrame:
        """Runs the control loop for ``seconds`` of simulated time (or until done)."""
        n = max(1, round(seconds / self.config.dt))
        st = self.state
        for _ in range(n):
            if st.done:
                break
            self._tick()
        self._publish()
        return self._frame

    def _tick(self) -> None:
        """One control step: the phases in order (module docstring).

        The phases work on floats: x, the master and the velocity are tuples, the operator
        reads a percept refreshed in place, and the runtime's float-level entry points
        (``scale_motion_xyz``, ``render_xyz``) do the same arithmetic in the same order as
        the array API (bit-identical samples) without building a TaskState, effect objects
        or arrays per step; ``_publish`` builds the frame.
        """
        self.before_step()
        self.physics_phase()
        self.observe()
        dxm = self.master_phase(self.operator_phase())
        g, i = self.task_phase(dxm)
        self.fixtures_phase(dxm)
        self.contact_phase()
        self.record_phase(g, i)
        self.after_step()

    def before_step(self) -> None:
        """The clock: k(k) = k + 1, t = (k + 1) dt (row k holds the state after the step)."""
        st = self.state
        k = st.k = st.k + 1
        st.t = (k + 1) * self.model.dt

    def physics_phase(self) -> None:
        """The abdomen's step when due, with the tool where it is (before this step's
        motion); the POIs follow the tissue. A physics feed answers every step."""
        ab = self.abdomen
        if ab is None or self.state.k % self._phys_every:
            return
        st = self.state
        pose = ToolPose(self.model.fulcrum, np.array(st.x))
        if self._physics_feed is not None:
            fed = self._physics_feed(st.k, pose)
            if fed is not None:
                self._apply_snapshot(fed)
            return
        self._apply_snapshot(ab.step(pose))

    def observe(self) -> None:
        """The percept of this step: the last render as perceived now, and the felt force
        (the fixtures' and the tissue's)."""
        self.percept.observe(self.state, self.model.n)

    def operator_phase(self) -> Sequence[float]:
        """The operator's master increment dX_M (``TrialOperator.act``)."""
        return self.operator.act(self.percept)

    def master_phase(self, dx: Sequence[float]) -> tuple[float, float, float]:
        """The guard and the master: a non-finite dX_M is dropped (zero motion; the first
        few are logged, then one event per second of dropout); the master moves by dX_M.
        Returns the increment used."""
        st = self.state
        d0, d1, d2 = dx
        if not (math.isfinite(d0) and math.isfinite(d1) and math.isfinite(d2)):
            st.n_bad_input += 1
            dt = self.model.dt
            if st.n_bad_input <= _BAD_INPUT_EVENTS or st.k % round(1.0 / dt) == 0:
                st.events.append((st.t, "nonfinite_input",
                                  f"dX_M={list(map(float, dx))!r} "
                                  f"(dropped; {st.n_bad_input} so far)"))
            d0 = d1 = d2 = 0.0
        m = st.m
        st.m = (m[0] + d0, m[1] + d1, m[2] + d2)
        return (d0, d1, d2)

    def task_phase(self, dxm: tuple[float, ...]) -> tuple[tuple[float, ...], int]:
        """MS scales the increment (stage 1 of the schema) and the task updates: x(k), the
        filtered velocity, the error and the reach test. Returns the goal and goal index
        this row is compared with (the goal advances after the row)."""
        st, md = self.state, self.model
        x, i = st.x, st.i  # i < n: the trial is done once every point is reached
        g = st.geometry.goal_xyz[i]
        rt = self.runtime
        state = self._task_state(dxm) if rt.needs_state else None
        s0, s1, s2, f0, f1, f2 = rt.scale_motion_xyz(x, self._fixture_goal(x, i), dxm,
                                                     md.scale, state)
        st.ms = (f0, f1, f2)
        x = st.x = (x[0] + s0, x[1] + s1, x[2] + s2)
        v, a, dt = st.v, md.alpha, md.dt
        st.v = (v[0] + a * (s0 / dt - v[0]), v[1] + a * (s1 / dt - v[1]),
                v[2] + a * (s2 / dt - v[2]))
        e0, e1, e2 = x[0] - g[0], x[1] - g[1], x[2] - g[2]
        st.err += abs(e0) + abs(e1) + abs(e2)
        if e0 * e0 + e1 * e1 + e2 * e2 <= md.r2:
            st.reach_times.append(st.t)
            st.i = i + 1
            st.err = 0.0
        return g, i

    def fixtures_phase(self, dxm: tuple[float, ...]) -> None:
        """The fixtures' parallel channels (FF + walls, AG, VG, Mag) for x(k)."""
        self.state.cues = self._render(dxm)

    def contact_phase(self) -> None:
        """The 1 kHz tissue force against the contact planes of the last physics step."""
        st = self.state
        if st.patch is not None:
            f, kt = patch_force(st.patch, ToolPose(self.model.fulcrum, np.array(st.x)))
            fc = st.fc = tuple(f.tolist())
            st.kt = tuple(kt.reshape(9).tolist())
            st.contact = 1 if (fc[0] or fc[1] or fc[2]) else 0
        elif st.contact:
            st.fc, st.contact = (0.0, 0.0, 0.0), 0
            st.kt = None

    def record_phase(self, g: tuple[float, ...], i: int) -> None:
        """The sample row k: x(k), the goal g it was compared with, the cues, MS, contact,
        the camera view (Mag's camera per step) and the render's gain."""
        st = self.state
        cues, x = st.cues, st.x
        gain = getattr(self.runtime, "gain", 1.0)  # a GainedRuntime's gain of this render
        if self.model.mag_camera:
            view = self._tip_in_mag_view(x)
            st.samples.append(st.k, st.t, x, g, i, cues[0:3], st.ms, cues[3], cues[4],
                              cues[5], cues[6], st.contact, st.fc, st.tc,
                              st.delicate, 0, view, gain)
        elif st.contact or st.delicate:
            st.samples.append(st.k, st.t, x, g, i, cues[0:3], st.ms, cues[3], cues[4],
                              cues[5], cues[6], st.contact, st.fc, st.tc,
                              st.delicate, gain=gain)
        else:
            st.samples.append(st.k, st.t, x, g, i, cues[0:3], st.ms, cues[3], cues[4],
                              cues[5], cues[6], 0, gain=gain)

    def should_terminate(self) -> bool:
        """Every POI reached, or the time limit."""
        st = self.state
        return st.i >= self.model.n or st.t >= self.model.max_time - 1e-12

    def after_step(self) -> None:
        """``done`` from :meth:`should_terminate`."""
        self.state.done = self.should_terminate()

    def _tip_in_mag_view(self, x: tuple[float, ...]) -> int:
        """1 if the TCP is inside the smoothed Mag camera's view cone of this step, else 0.

        Reads the runtime's smoothed camera as floats (position, look-at, fov, zoom): the
        same numbers ``outputs().camera`` wraps in arrays, without building them per step
        (that would double the cost of a Mag step). Same rule as ``in_view_cone``.
        """
        cam = self.runtime.camera_floats  # [p0, p1, p2, l0, l1, l2, fov, zoom]
        if cam is None:
            return 0
        f0, f1, f2 = cam[3] - cam[0], cam[4] - cam[1], cam[5] - cam[2]
        d0, d1, d2 = x[0] - cam[0], x[1] - cam[1], x[2] - cam[2]
        fn = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        dn = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        if fn == 0.0:
            return 0
        inside = (d0 * f0 + d1 * f1 + d2 * f2) >= math.cos(0.5 * cam[6]) * dn * fn - 1e-15
        return 1 if inside else 0

    def _publish(self) -> None:
        st = self.state
        rt = st.reach_times
        last_latency = None
        if rt:
            last_latency = rt[-1] - (rt[-2] if len(rt) > 1 else 0.0)
        n = self.model.n
        self._frame = TrialFrame(
            k=st.k, t=st.t, tcp=np.array(st.x), master=np.array(st.m),
            goal=st.geometry.points[min(st.i, n - 1)], goal_index=st.i,
            n_points=n, done=st.done, outputs=self.runtime.outputs(),
            last_latency=last_latency, error_l1=st.err, abdomen=st.snap,
            tissue_force=np.array(st.fc) if self.abdomen is not None else None,
            gain=float(getattr(self.runtime, "gain", 1.0)),
        )

    def result(self, wall_time: float = 0.0, *,
               metric_params: MetricParams | None = None) -> TrialResult:
        """The trial's samples, per-point metrics (spec/study.md §2), summary and trial
        metrics (``vasim.records.trial_metrics``, with ``metric_params`` or the defaults).

        Without Mag, the ``in_view`` column is filled here from the fixed endoscope.
        """
        st, n = self.state, self.model.n
        if not self.model.mag_camera and len(st.samples):
            st.samples.set_column(
                "in_view", DEFAULT_ENDOSCOPE.contains(st.samples.view()["x"]).astype(np.int8))
        view = st.samples.view()
        # The reach times recorded by the loop are passed on, so the reach rule lives once.
        metrics, summary = evaluate_trial(
            view["t"], view["x"], view["g"], view["goal_index"], st.geometry.points,
            r_reach=self.task.reach_radius,
            t_reached=st.reach_times + [math.nan] * (n - len(st.reach_times)),
            start=self.task.start,
            tolerance=(metric_params or MetricParams()).path_tolerance_m,
        )
        summary.update({
            "finished": bool(st.i >= n), "sim_time": st.t, "steps": st.k + 1,
            # how the trial ended (vasim.study.store.vocabulary.TRIAL_OUTCOMES); "stopped":
            # a result taken before the end (the store overrides it when closing early)
            "outcome": ("reached_all" if st.i >= n else "timed_out"
                        if st.t >= self.config.max_time - 1e-12 else "stopped"),
            "schema": self.schema.name, "active_fixtures": ",".join(self.schema.fixture_names),
            "nonfinite_inputs": st.n_bad_input,
            "scene": self.config.scene,
        })
        if self.config.gain != 1.0:  # a faded or adaptive trial: its mean gain in force
            summary["gain_mean"] = float(np.mean(view["gain"])) if len(view["gain"]) else 1.0
        if self.abdomen is not None:
            summary.update({f"tissue_{k}": v
                            for k, v in self.abdomen.quality.as_dict().items()})
        tm = trial_metrics(view, summary=summary,
                           params=metric_params if metric_params is not None else MetricParams())
        return TrialResult(config=self.config, schema=self.schema, task=self.task,
                           samples=st.samples, metrics=metrics, summary=summary,
                           events=list(st.events), wall_time=wall_time, trial_metrics=tm)


_BAD_INPUT_EVENTS = 10
"""Non-finite device increments logged one by one before logging once per second."""


__all__ = [
    "MasterIncrement",
    "PhysicsFeed",
    "SkillName",
    "TaskName",
    "TrialConfig",
    "TrialFrame",
    "TrialResult",
    "TrialRunner",
    "make_profile",
    "make_task",
    "tool_trocar",
]


def with_schema(config: TrialConfig, schema: str) -> TrialConfig:
    """A copy of ``config`` with another schema (used by the viewer's schema menu)."""
    return replace(config, schema=schema)
