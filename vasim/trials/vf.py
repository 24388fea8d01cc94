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
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Literal

import numpy as np
import pandas as pd

from vasim.abdomen.contact import ContactPatch, ToolPose, patch_force
from vasim.core.errors import ConfigError
from vasim.fixtures.gain import GainRule, rule_from_record
from vasim.fixtures.gain_runtime import GainedRuntime
from vasim.fixtures.runtime import FixtureOutputs, SchemaRuntime
from vasim.fixtures.schema import Schema, load_schema
from vasim.fixtures.types import TaskState, Vec3
from vasim.haptics.observation import OperatorObservation
from vasim.operator.scripted import OperatorProfile, ScriptedOperator
from vasim.operator.teleop_profile import TeleopEffects
from vasim.records.point_metrics import evaluate_trial
from vasim.records.samples import SampleBuffer
from vasim.records.trial_metrics import MetricParams, trial_metrics
from vasim.tasks import Task, point_task, trajectory_task
from vasim.tasks.base import polyline_lookahead
from vasim.trials.endoscope import DEFAULT_ENDOSCOPE
from vasim.trials.kinds import TELEOPERATION_MODES, check_trial_time
from vasim.trials.ports import tool_trocar

if TYPE_CHECKING:
    from vasim.abdomen.snapshot import AbdomenSnapshot
    from vasim.abdomen.world import Abdomen

TaskName = Literal["trajectory", "point"]

SkillName = Literal["novice", "intermediate", "expert"]


@dataclass(frozen=True)
class TrialConfig:
    """Everything that defines one trial (stored with it; same config + seed = same trial).

    Attributes:
        task: ``"trajectory"`` (trajectory following) or ``"point"`` (point targeting).
        variant: trajectory variant, 0 = original, 1..6 mirrored/rotated.
        schema: fixture schema name (``protocols/schemas/NAME.toml``) or path to a TOML file.
        operator: input device; ``"scripted"`` is the only one in this release.
        skill: scripted operator preset.
        seed: random seed of the operator (noise, tremor).
        practice: number of earlier trials of this subject (learning).
        dt: control step [s] (1 ms: the haptic rate).
        max_time: simulated time limit [s]; the trial ends there even if points remain.
        subject: subject code (never a name), or None for a trial without a subject.
        label: a free-practice label (``TrialMeta.label``), or None.
        velocity_cutoff_hz: low-pass cutoff of the TCP velocity FF's damping uses [Hz].
        reach_radius: r_reach [m] (a protocol parameter); None: the task's default (5 mm).
        poi_spacing: arc length between the trajectory's POIs [m] (a protocol parameter);
            None: the task's default (10.5 mm, 30 POIs).
        profile: the operator profile; None: the ``skill`` preset.
        scene: the virtual abdomen the task lives in: a scene name
            (``protocols/scenes/NAME.toml``) or TOML path, or ``"none"`` for a static task
            with no tissue (no breathing, no contact).
        mode: None for a trial of ``task`` under ``schema`` (this module's runner), or a
            teleoperation mode of the MRCP study (``"stdt"``, ``"mrcp"``, ``"mrcp_cam"``):
            the needle task on the MRCP slave station (``vasim.trials.teleop``, 18 ms
            control cycle), where ``task``, ``variant``, ``schema``, ``dt`` and
            ``velocity_cutoff_hz`` are not used.
        gain: the fixture gain (``vasim.fixtures.gain``): a constant in [0, 1] (1: the
            schema as written) or an ``AdaptiveRule``; logged per sample (``gain``).
        mode_practice: earlier trials of this teleoperation mode in the session (the
            mode-specific learning of ``vasim.operator.teleop_profile``); None: ``practice``.
        mode_effects: the scripted person's mode penalties in a teleoperation trial
            (``vasim.operator.teleop_profile.TeleopEffects``, from the session's declared
            teleoperation scenario); None: none (``NEUTRAL``, the mechanism alone). A
            stored record's dict becomes the dataclass.
    """

    task: TaskName = "trajectory"
    variant: int = 0
    schema: str = "none"
    operator: str = "scripted"
    skill: SkillName = "intermediate"
    seed: int = 0
    practice: int = 0
    dt: float = 1e-3
    max_time: float = 180.0
    subject: str | None = None
    velocity_cutoff_hz: float = 30.0
    profile: OperatorProfile | None = field(default=None, compare=False)
    reach_radius: float | None = None
    scene: str = "default"
    poi_spacing: float | None = None
    mode: str | None = None
    label: str | None = None
    gain: GainRule = 1.0
    mode_practice: int | None = None
    mode_effects: TeleopEffects | None = None

    def __post_init__(self) -> None:
        # the fixture gain (vasim.fixtures.gain): a constant, or the adaptive rule (a stored
        # record's table becomes the rule)
        object.__setattr__(self, "gain", rule_from_record(self.gain, "gain"))
        if self.mode is not None and self.mode not in TELEOPERATION_MODES:
            raise ConfigError(f"unknown teleoperation mode {self.mode!r} (expected one of "
                              f"{', '.join(TELEOPERATION_MODES)} or None)", field="mode")
        if self.task not in ("trajectory", "point"):
            raise ConfigError(f"unknown task {self.task!r} (expected 'trajectory' or 'point')",
                              field="task")
        if self.task == "point" and self.variant != 0:
            raise ConfigError(f"the point task has no variants, got variant {self.variant!r}",
                              field="variant")
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or not (
                0 <= self.seed < 2**63):
            raise ConfigError(f"seed must be an integer in [0, 2**63), got {self.seed!r}",
                              field="seed")
        from vasim.records.trial_meta import validate_subject_code

        if self.subject is not None:
            validate_subject_code(self.subject)
        if self.operator != "scripted":
            raise ConfigError(f"unknown operator {self.operator!r} (available: 'scripted')",
                              field="operator")
        if self.skill not in ("novice", "intermediate", "expert"):
            raise ConfigError(f"unknown skill {self.skill!r} (novice, intermediate, expert)",
                              field="skill")
        if not (math.isfinite(self.dt) and 0 < self.dt <= 0.02):
            raise ConfigError(f"dt must be in (0, 0.02] s, got {self.dt!r}", field="dt")
        try:
            check_trial_time(self.max_time, "max_time")
        except ConfigError as exc:
            raise ConfigError(f"max_time {exc.reason}", field="max_time") from None
        if self.practice < 0:
            raise ConfigError(f"practice must be >= 0, got {self.practice!r}", field="practice")
        if not (math.isfinite(self.velocity_cutoff_hz) and self.velocity_cutoff_hz > 0):
            raise ConfigError(f"velocity_cutoff_hz must be > 0, got {self.velocity_cutoff_hz!r}",
                              field="velocity_cutoff_hz")
        r = self.reach_radius
        if r is not None and (isinstance(r, bool) or not isinstance(r, int | float)
                              or not math.isfinite(r) or not r > 0):
            raise ConfigError(f"reach_radius must be > 0 m, got {r!r}", field="reach_radius")
        if not isinstance(self.scene, str) or not self.scene.strip():
            raise ConfigError(f"scene must be a scene name, a TOML path or 'none', got "
                              f"{self.scene!r}", field="scene")
        if self.profile is not None and not isinstance(self.profile, OperatorProfile):
            raise ConfigError(f"profile must be an OperatorProfile, got {self.profile!r}",
                              field="profile")
        mp = self.mode_practice
        if mp is not None and (isinstance(mp, bool) or not isinstance(mp, int) or mp < 0):
            raise ConfigError(f"mode_practice must be an integer >= 0 or None, got {mp!r}",
                              field="mode_practice")
        me = self.mode_effects
        if isinstance(me, Mapping):
            try:
                object.__setattr__(self, "mode_effects", TeleopEffects(**me))
            except (TypeError, ValueError) as exc:
                raise ConfigError(f"mode_effects: {exc}", field="mode_effects") from None
        elif me is not None and not isinstance(me, TeleopEffects):
            raise ConfigError(f"mode_effects must be TeleopEffects or None, got {me!r}",
                              field="mode_effects")


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

    config: TrialConfig
    schema: Schema
    task: Task
    samples: SampleBuffer
    metrics: pd.DataFrame
    summary: dict[str, float | int | bool | str]
    events: list[tuple[float, str, str]]
    wall_time: float
    trial_metrics: dict[str, float] = field(default_factory=dict)
    """``vasim.records.trial_metrics.trial_metrics`` of the trial (see ``TRIAL_METRICS``)."""


def make_task(config: TrialConfig) -> Task:
    """Builds the task a config names (with its reach radius and POI spacing, if the config
    sets them)."""
    kw: dict[str, float] = {}
    if config.reach_radius is not None:
        kw["reach_radius"] = float(config.reach_radius)
    if config.task == "trajectory":
        if config.poi_spacing is not None:
            kw["poi_spacing"] = float(config.poi_spacing)
        return trajectory_task(config.variant, **kw)
    if config.reach_radius is not None:
        return point_task(reach_radius=float(config.reach_radius))
    return point_task()


def make_profile(config: TrialConfig) -> OperatorProfile:
    if config.profile is not None:
        return config.profile
    if config.skill == "novice":
        return OperatorProfile.novice()
    if config.skill == "expert":
        return OperatorProfile.expert()
    return OperatorProfile.intermediate()


PhysicsFeed = Callable[[int, ToolPose], "AbdomenSnapshot | None"]
"""``feed(k, pose) -> snapshot or None``: the physics of a trial run outside its steps
(``TrialRunner.set_physics_feed``): k the control step, pose the tool before the step."""


class MasterIncrement:
    """An operator whose master increment dX_M is set from outside before each step.

    The real-time trial's servo loop reads the device, applies guard and clutch, and hands
    the increment of the master position to the runner through this object
    (``set(dx)`` then ``TrialRunner.step()``); each increment is used once (``take``
    returns zero motion when none was set). ``profile`` is None: no simulated person.
    """

    profile = None

    def __init__(self) -> None:
        self._dx: tuple[float, float, float] = (0.0, 0.0, 0.0)

    def reset(self, start: object) -> None:
        del start
        self._dx = (0.0, 0.0, 0.0)

    def set(self, dx: tuple[float, float, float]) -> None:
        """The increment [m] the next step uses."""
        self._dx = dx

    def take(self) -> tuple[float, float, float]:
        """The pending increment (then zero)."""
        dx, self._dx = self._dx, (0.0, 0.0, 0.0)
        return dx

    def step(self, obs: OperatorObservation) -> tuple[float, float, float]:
        """The operator protocol (``OperatorObservation`` ignored): ``take()``."""
        del obs
        return self.take()


class TrialRunner:
    """Runs one trial step by step (a thin stateful shell around the pure fixtures).

    Example:
        >>> runner = TrialRunner(TrialConfig(schema="ff", seed=1, max_time=0.01))
        >>> frame = runner.advance(0.005)
        >>> frame.k
        4
    """

    def __init__(self, config: TrialConfig, schema: Schema | None = None):
        self.config = config
        self.schema = schema if schema is not None else load_schema(config.schema)
        self.task = make_task(config)
        if self.schema.task not in ("any", self.task.kind):
            raise ConfigError(
                f"schema {self.schema.name!r} is for {self.schema.task!r} tasks, "
                f"not {self.task.kind!r}", field="schema")
        self.runtime = (SchemaRuntime(self.schema) if config.gain == 1.0
                        else GainedRuntime(self.schema, config.gain))
        self.operator = ScriptedOperator(make_profile(config), self.task, seed=config.seed,
                                         practice=config.practice)
        capacity = min(int(config.max_time / config.dt) + 2, _MAX_PREALLOCATED)
        self.samples = SampleBuffer(capacity=capacity,
                                    active_fixtures=",".join(self.schema.fixture_names))
        self.events: list[tuple[float, str, str]] = []
        self._n_bad_input = 0
        # in_view: Mag's camera per step, else the fixed endoscope after the loop
        self._mag_camera = self.schema.camera is not None
        self._points = np.asarray(self.task.points, dtype=np.float64)
        self._n = len(self._points)
        self._r2 = self.task.reach_radius ** 2
        self._scale = self.task.scale
        self._trajectory = self.task.kind == "trajectory"
        self._start_xyz = tuple(np.asarray(self.task.start, dtype=np.float64).tolist())
        self._set_geometry(self._points, self.task.normals)
        # The virtual abdomen: the POIs ride on the tissue, the tool touches it.
        self.abdomen: Abdomen | None = None
        self._snap: AbdomenSnapshot | None = None
        self._patch: ContactPatch | None = None
        self._fulcrum = np.asarray(tool_trocar(self.task.kind, self.task.start),
                                   dtype=np.float64)
        self._fc: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._tc: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._contact = 0
        self._delicate = 0
        self._kt: tuple[float, ...] | None = None  # dF/dx of the tissue force, row-major
        self._physics_feed: PhysicsFeed | None = None
        if config.scene != "none":
            from vasim.abdomen.world import Abdomen

            self.abdomen = Abdomen(config.scene)
            self.abdomen.bind_targets(self._points)
            self._phys_every = max(1, round(self.abdomen.dt / config.dt))
            self._snap = self.abdomen.latest
        # TCP x(k), master (hand) position and filtered TCP velocity, as tuples of floats
        start = np.array(self.task.start, dtype=np.float64)
        self._x: tuple[float, ...] = tuple(start.tolist())
        self._m: tuple[float, ...] = self._x
        self._v: tuple[float, ...] = (0.0, 0.0, 0.0)
        self._alpha = 1.0 - math.exp(-2.0 * math.pi * config.velocity_cutoff_hz * config.dt)
        self._k = -1
        self._t = 0.0
        self._i = 0
        self._reach_times: list[float] = []
        self._err = 0.0
        self.runtime.reset(start)
        self.operator.reset(start)
        self.done = False
        # The first render (t = 0, no motion): what the operator perceives at the first step.
        zero = (0.0, 0.0, 0.0)
        state = self._state(zero) if self.runtime.needs_state else None
        self._ms: tuple[float, ...] = self.runtime.scale_motion_xyz(
            self._x, self._fixture_goal(self._x, 0), zero, self._scale, state)[3:]
        self._cues = self._render(zero)
        self._publish()

    # -- helpers -----------------------------------------------------------------------
    def _set_geometry(self, points: np.ndarray, normals: np.ndarray | None) -> None:
        """Sets the current POIs (they move with the tissue) and what derives from them.

        Goals, path segments and normals are kept as tuples of floats for the loop;
        look-ahead points (Mag's aim) are computed on first use per geometry update.
        """
        self._points = np.asarray(points, dtype=np.float64)
        self._normals = None if normals is None else np.asarray(normals, dtype=np.float64)
        self._goal_xyz = [tuple(p) for p in self._points.tolist()]
        self._normal_xyz = (None if self._normals is None
                            else [tuple(nv) for nv in self._normals.tolist()])
        self._lookahead_xyz: dict[int, tuple[float, ...]] = {}
        self._segment_cache: dict[int, tuple[tuple[float, ...], tuple[float, ...], float]] = {}

    def _segment(self, i: int) -> tuple[tuple[float, ...], tuple[float, ...], float]:
        """Path segment [p_(i-1), p_i] (the tool's start for i = 0) for the fixture goal
        (module docstring, decision): start a, direction ab and 1/|ab|^2, on the current
        geometry (computed on first use after each geometry update)."""
        seg = self._segment_cache.get(i)
        if seg is None:
            a = self._start_xyz if i == 0 else self._goal_xyz[i - 1]
            b = self._goal_xyz[i]
            ab = (b[0] - a[0], b[1] - a[1], b[2] - a[2])
            n2 = ab[0] * ab[0] + ab[1] * ab[1] + ab[2] * ab[2]
            seg = self._segment_cache[i] = (a, ab, 1.0 / n2 if n2 > 0 else 0.0)
        return seg

    def _lookahead_at(self, i: int) -> tuple[float, ...]:
        """Mag's aim point for goal i on the current geometry (``Task.lookahead``)."""
        la = self._lookahead_xyz.get(i)
        if la is None:
            la = self._lookahead_xyz[i] = tuple(
                polyline_lookahead(self._points, i).tolist())
        return la

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

    def _physics(self) -> None:
        """One physics step with the tool where it is; the POIs follow the tissue."""
        assert self.abdomen is not None
        if self._physics_feed is not None:
            fed = self._physics_feed(self._k, ToolPose(self._fulcrum, np.array(self._x)))
            if fed is not None:
                self._apply_snapshot(fed)
            return
        self._apply_snapshot(self.abdomen.step(ToolPose(self._fulcrum, np.array(self._x))))

    def _apply_snapshot(self, snap: AbdomenSnapshot) -> None:
        """Takes a physics snapshot: the POIs follow the tissue, the contact planes renew."""
        self._snap = snap
        self._set_geometry(snap.targets, snap.target_normals
                           if self.task.normals is not None else None)
        self._patch = snap.patch if snap.patch.size else None
        self._tc = tuple(snap.torque.tolist())
        self._delicate = 1 if snap.delicate_contact else 0
        for kind, detail in snap.events:
            self.events.append((snap.t, kind, detail))

    def _fixture_goal(self, x: tuple[float, ...], i: int) -> tuple[float, ...]:
        """g_f(k): nearest point of segment i to x (trajectory), or the POI (point task)."""
        if not self._trajectory:
            return self._goal_xyz[i]
        a, ab, inv = self._segment(i)
        u = ((x[0] - a[0]) * ab[0] + (x[1] - a[1]) * ab[1] + (x[2] - a[2]) * ab[2]) * inv
        u = 0.0 if u < 0.0 else (1.0 if u > 1.0 else u)
        return (a[0] + u * ab[0], a[1] + u * ab[1], a[2] + u * ab[2])

    def _goal(self) -> Vec3:
        return self._points[min(self._i, self._n - 1)]

    def _state(self, dx_master: tuple[float, ...]) -> TaskState:
        """The step as a ``TaskState`` (only for schemas with a fixture that needs one)."""
        i = min(self._i, self._n - 1)
        normals = self._normals
        return TaskState(
            tcp=np.array(self._x), goal=np.array(self._fixture_goal(self._x, i)),
            tcp_velocity=np.array(self._v),
            dx_master=np.array(dx_master), scale=self._scale, t=self._t,
            kind=self.task.kind, lookahead=np.array(self._lookahead_at(i)),
            normal=None if normals is None else normals[i],
        )

    def _render(self, dx_master: tuple[float, ...]) -> tuple[float, ...]:
        """Renders the fixtures' parallel channels for the current x(k) (phase 2).

        Returns ``SchemaRuntime.render_xyz``'s values: (force x, y, z, zoom, audio pitch,
        period, volume, guidance-arrow opacity).
        """
        i = min(self._i, self._n - 1)
        rt = self.runtime
        state = self._state(dx_master) if rt.needs_state else None
        # The error rate is the TCP velocity: the goals' own motion (breathing, at most a
        # few mm/s) is left out of FF's damping term. Only Mag aims at the look-ahead point.
        gf = self._fixture_goal(self._x, i)
        return rt.render_xyz(
            self._x, gf, self._v, self._t, self._scale, self.task.kind,
            self._lookahead_at(i) if self._mag_camera else gf,
            None if self._normal_xyz is None else self._normal_xyz[i], state)

    def _observation(self) -> OperatorObservation:
        """What the operator perceives (for devices without ``step_floats``)."""
        cues = self._cues
        return OperatorObservation(
            t=self._t, dt=self.config.dt, tcp=np.array(self._x), goal=self._goal(),
            goal_index=min(self._i, self._n - 1), force=np.array(cues[0:3]),
            ms_factors=np.array(self._ms), guidance=cues[7] > _GUIDANCE_SEEN,
            audio_volume=cues[6], audio_pitch_hz=cues[4], zoom=cues[3],
        )

    # -- the loop ------------------------------------------------------------------------
    @property
    def frame(self) -> TrialFrame:
        """The latest published snapshot (immutable: safe to read from another thread).

        ``step()`` publishes after every step, ``advance()`` once at the end of its run.
        """
        return self._frame

    def step(self) -> TrialFrame:
        """Advances one control step; returns the new frame."""
        if not self.done:
            self._tick()
            self._publish()
        return self._frame

    def advance(self, seconds: float) -> TrialFrame:
        """Runs the control loop for ``seconds`` of simulated time (or until done)."""
        n = max(1, round(seconds / self.config.dt))
        for _ in range(n):
            if self.done:
                break
            self._tick()
        self._publish()
        return self._frame

    def _tick(self) -> None:
        """One control step (module docstring, steps 1-5).

        The loop works on floats: x, the master and the velocity are tuples, and it calls
        the float-level entry points of the operator (``step_floats``) and of the runtime
        (``scale_motion_xyz``, ``render_xyz``). These do the same arithmetic in the same
        order as the array API (bit-identical samples) but build no observation, TaskState,
        effect objects or arrays per step (~1-5 µs each); ``_publish`` builds the frame.
        """
        dt = self.config.dt
        k = self._k = self._k + 1
        t = self._t = (k + 1) * dt
        if self.abdomen is not None and k % self._phys_every == 0:
            self._physics()
        x, i = self._x, self._i  # i < n: the trial is done once every point is reached
        g = self._goal_xyz[i]
        cues = self._cues  # the last render, as perceived now
        op = self.operator
        if type(op) is ScriptedOperator:
            fc = self._fc  # the hand feels the fixtures' force and the tissue's
            dx = op.step_floats(dt, x, g, i, cues[7] > _GUIDANCE_SEEN, cues[6], cues[3],
                                self._ms, (cues[0] + fc[0], cues[1] + fc[1], cues[2] + fc[2]))
        elif type(op) is MasterIncrement:  # the servo loop's master (real-time trials)
            dx = op.take()
        else:  # any other device: the OperatorObservation protocol
            dx = np.asarray(op.step(self._observation()), dtype=np.float64).tolist()
        d0, d1, d2 = dx
        if not (math.isfinite(d0) and math.isfinite(d1) and math.isfinite(d2)):
            # Dropped; the first few are logged, then one event per second of dropout.
            self._n_bad_input += 1
            if self._n_bad_input <= _BAD_INPUT_EVENTS or k % round(1.0 / dt) == 0:
                self.events.append((t, "nonfinite_input",
                                    f"dX_M={list(map(float, dx))!r} "
                                    f"(dropped; {self._n_bad_input} so far)"))
            d0 = d1 = d2 = 0.0
        m = self._m
        self._m = (m[0] + d0, m[1] + d1, m[2] + d2)
        dxm = (d0, d1, d2)
        rt = self.runtime
        state = self._state(dxm) if rt.needs_state else None
        s0, s1, s2, f0, f1, f2 = rt.scale_motion_xyz(x, self._fixture_goal(x, i), dxm,
                                                     self._scale, state)
        self._ms = (f0, f1, f2)
        x = self._x = (x[0] + s0, x[1] + s1, x[2] + s2)
        v, a = self._v, self._alpha
        self._v = (v[0] + a * (s0 / dt - v[0]), v[1] + a * (s1 / dt - v[1]),
                   v[2] + a * (s2 / dt - v[2]))
        e0, e1, e2 = x[0] - g[0], x[1] - g[1], x[2] - g[2]
        self._err += abs(e0) + abs(e1) + abs(e2)
        if e0 * e0 + e1 * e1 + e2 * e2 <= self._r2:
            self._reach_times.append(t)
            self._i = i + 1
            self._err = 0.0
        cues = self._cues = self._render(dxm)
        if self._patch is not None:
            # 1 kHz tissue force against the contact planes of the last physics step
            f, kt = patch_force(self._patch, ToolPose(self._fulcrum, np.array(x)))
            fc = self._fc = tuple(f.tolist())
            self._kt = tuple(kt.reshape(9).tolist())
            self._contact = 1 if (fc[0] or fc[1] or fc[2]) else 0
        elif self._contact:
            self._fc, self._contact = (0.0, 0.0, 0.0), 0
            self._kt = None
        gain = getattr(rt, "gain", 1.0)  # a GainedRuntime's gain of this render
        if self._mag_camera:
            view = self._tip_in_mag_view(x)
            self.samples.append(k, t, x, g, i, cues[0:3], self._ms, cues[3], cues[4],
                                cues[5], cues[6], self._contact, self._fc, self._tc,
                                self._delicate, 0, view, gain)
        elif self._contact or self._delicate:
            self.samples.append(k, t, x, g, i, cues[0:3], self._ms, cues[3], cues[4],
                                cues[5], cues[6], self._contact, self._fc, self._tc,
                                self._delicate, gain=gain)
        else:
            self.samples.append(k, t, x, g, i, cues[0:3], self._ms, cues[3], cues[4],
                                cues[5], cues[6], 0, gain=gain)
        self.done = self._i >= self._n or t >= self.config.max_time - 1e-12

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
        rt = self._reach_times
        last_latency = None
        if rt:
            last_latency = rt[-1] - (rt[-2] if len(rt) > 1 else 0.0)
        self._frame = TrialFrame(
            k=self._k, t=self._t, tcp=np.array(self._x), master=np.array(self._m),
            goal=self._points[min(self._i, self._n - 1)], goal_index=self._i,
            n_points=self._n, done=self.done, outputs=self.runtime.outputs(),
            last_latency=last_latency, error_l1=self._err, abdomen=self._snap,
            tissue_force=np.array(self._fc) if self.abdomen is not None else None,
            gain=float(getattr(self.runtime, "gain", 1.0)),
        )

    def result(self, wall_time: float = 0.0, *,
               metric_params: MetricParams | None = None) -> TrialResult:
        """The trial's samples, per-point metrics (spec/study.md §2), summary and trial
        metrics (``vasim.records.trial_metrics``, with ``metric_params`` or the defaults).

        Without Mag, the ``in_view`` column is filled here from the fixed endoscope.
        """
        if not self._mag_camera and len(self.samples):
            self.samples.set_column(
                "in_view", DEFAULT_ENDOSCOPE.contains(self.samples.view()["x"]).astype(np.int8))
        view = self.samples.view()
        # The reach times recorded by the loop are passed on, so the reach rule lives once.
        metrics, summary = evaluate_trial(
            view["t"], view["x"], view["g"], view["goal_index"], self._points,
            r_reach=self.task.reach_radius,
            t_reached=self._reach_times + [math.nan] * (self._n - len(self._reach_times)),
            start=self.task.start,
            tolerance=(metric_params or MetricParams()).path_tolerance_m,
        )
        summary.update({
            "finished": bool(self._i >= self._n), "sim_time": self._t, "steps": self._k + 1,
            # how the trial ended (vasim.study.store.vocabulary.TRIAL_OUTCOMES); "stopped":
            # a result taken before the end (the store overrides it when closing early)
            "outcome": ("reached_all" if self._i >= self._n else "timed_out"
                        if self._t >= self.config.max_time - 1e-12 else "stopped"),
            "schema": self.schema.name, "active_fixtures": ",".join(self.schema.fixture_names),
            "nonfinite_inputs": self._n_bad_input,
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
                           samples=self.samples, metrics=metrics, summary=summary,
                           events=list(self.events), wall_time=wall_time, trial_metrics=tm)


_GUIDANCE_SEEN = 0.05
"""The operator notices the VG arrow when its opacity exceeds this."""

_BAD_INPUT_EVENTS = 10
"""Non-finite device increments logged one by one before logging once per second."""

_MAX_PREALLOCATED = 1_000_000
"""Sample rows preallocated at most (~170 MB); longer trials grow the buffer."""


__all__ = [
    "MasterIncrement",
    "PhysicsFeed",
    "TrialConfig",
    "TrialFrame",
    "TrialResult",
    "TrialRunner",
    "make_task",
]


def with_schema(config: TrialConfig, schema: str) -> TrialConfig:
    """A copy of ``config`` with another schema (used by the viewer's schema menu)."""
    return replace(config, schema=schema)
