"""Runs a scenario through the MRCP kernel and keeps what the seed plots (Figs. 4.23-4.26).

Every cycle the runner calls the scenario's ``on_cycle`` hook (moving obstacles), asks the
operator (:class:`TrackingOperator` following the scenario's script) for the commanded task
pose, steps :class:`~vasim.mrcp.kernel.MRCPKernel`, and
checks the invariants of the platform (issue #7 §5): the task is never ungrasped (some robot
holds it, RSel among the holders, and RSel's TCP is at the held point), RSel never collides,
no joint leaves its limits. Violations are collected (:attr:`RunResult.violations`), never
raised, so a run always yields its log and plot.

**Decision** (a safety stop, issue #26 §4): the kernel refuses RSel's step into a collision
and stops (FAULT) until an operator acknowledges it; a scripted run has no operator, so the
run ends at the stop with its cause (:attr:`RunResult.stop`, the kernel's event naming the
nearest body) instead of logging "fault: no motion" every cycle, and its invariant line
(:meth:`RunResult.invariant_summary`) says that RSel was kept out of collision by the stop.

**Decision** (the controller): the kernel poses its world at the commanded configurations
and the scenario runs with an ideal controller (the measured configuration is the
commanded one, as in the kernel's own tests); the kernel already bounds every joint step by
the robots' speed limits, which is the controller emulator's safety layer.

Per cycle the runner keeps, for every robot, the pair the seed plots: RSel at CuTP, a
candidate at its best point (largest ``tus``) — its index values, ``texec`` per index and
their minimum, ``ttransf*`` and ``tus`` — and NTT and RSel (:class:`Sample`).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from vasim.core.config import check_array, expect
from vasim.core.geometry import matrix_from_rotvec, rotvec_from_matrix
from vasim.mrcp.interfaces import FloatArray
from vasim.mrcp.kernel import CycleRecord, MRCPKernel
from vasim.mrcp.modes import KernelState
from vasim.mrcp.scenarios.base import Scenario, ScenarioOptions, Setup


@dataclass(frozen=True)
class RobotSample:
    """One robot's evaluation in one cycle (at CuTP for RSel, at its best point otherwise)."""

    point: int
    values: dict[str, float]
    texec: dict[str, float]
    texec_min: float
    ttransf: float
    tus: float


@dataclass(frozen=True)
class Sample:
    """One cycle: mode, roles, NTT and the per-robot evaluations (TOp cycles only), the
    commanded configurations, the achieved task pose (behind the operator's script after a
    transfer until :class:`TrackingOperator` has caught up) and the robots in collision
    (candidates included: the planner's moves must avoid obstacles too). A scenario with a
    state graph of subtasks (``suture_combined``) adds the current ``subtask``, the pairing
    ``mode`` (``"StdT"`` / ``"MRCP"``) and ``scene``: what the viewer draws besides the
    station (the thread's nodes, world frame)."""

    t: float
    state: str
    rsel: str
    cutp: int
    holders: tuple[str, ...]
    rcnt: str | None
    ntt: float
    robots: dict[str, RobotSample]
    events: tuple[str, ...]
    configs: dict[str, FloatArray]
    task_position: FloatArray
    task_rotation: FloatArray | None
    colliding: tuple[str, ...] = ()
    subtask: str | None = None
    mode: str | None = None
    scene: dict[str, Any] | None = None


@dataclass
class RunResult:
    """A finished run: samples, the event log, invariant violations, the final state, and
    the safety stop that ended it (``stop``: ``"t=5.670: rsel_collision R4: safety stop
    (nearest body R3 at -0.4 mm)"``; None when the run reached its duration)."""

    scenario: str
    robots: list[str]
    samples: list[Sample]
    violations: list[str]
    notes: dict[str, Any] = field(default_factory=dict)
    extra: dict[str, Any] = field(default_factory=dict)
    """Scenario-specific sections of the summary (the suture's ``subtasks``)."""
    stop: str | None = None

    def invariant_summary(self) -> str:
        """One line on the invariants that never contradicts a safety stop of the run: RSel
        was kept out of collision *by* the stop, and the run says so (issue #26 §4)."""
        if self.violations:
            end = "" if self.stop is None else f"; the safety stop ({self.stop}) ended the run"
            return f"INVARIANTS VIOLATED ({len(self.violations)}){end}"
        if self.stop is not None:
            return (f"invariants: task always grasped, joint limits kept; RSel was kept out of "
                    f"collision only by the safety stop ({self.stop}), which ended the run")
        return "invariants: task always grasped, RSel never in collision, joint limits kept"

    def events(self, prefix: str = "") -> list[tuple[float, str]]:
        """``(t, event)`` of every event starting with ``prefix``."""
        return [(s.t, e) for s in self.samples for e in s.events if e.startswith(prefix)]

    def transfers(self) -> list[dict[str, Any]]:
        """The task transfers: start time, giving and receiving robot, point, NTT, cause,
        and the completion time (None when aborted or unfinished)."""
        out: list[dict[str, Any]] = []
        for s in self.samples:
            for e in s.events:
                if e.startswith("transfer_start"):
                    parse = _parse_start(e)
                    out.append({"t_start": s.t, "from": s.rsel, **parse, "t_done": None})
                elif e.startswith("transfer_done") and out:
                    out[-1]["t_done"] = s.t
        return out

    def to_dict(self) -> dict[str, Any]:
        return {"scenario": self.scenario, "robots": self.robots,
                "duration": self.samples[-1].t if self.samples else 0.0,
                "cycles": len(self.samples), "transfers": self.transfers(),
                "events": [{"t": round(t, 4), "event": e} for t, e in self.events()],
                "violations": self.violations, "final_rsel": self.samples[-1].rsel
                if self.samples else None, "safety_stop": self.stop,
                "invariants": self.invariant_summary(), "notes": self.notes, **self.extra}


def _parse_start(event: str) -> dict[str, Any]:
    """``"transfer_start r1@3 (ntt=0.93, cause=rj)"`` -> to, point, ntt, cause."""
    head, _, tail = event.partition(" (")
    who = head.split()[1]
    robot, _, point = who.partition("@")
    fields = dict(kv.split("=", 1) for kv in tail.rstrip(")").split(", ") if "=" in kv)
    return {"to": robot, "point": int(point), "ntt": float(fields.get("ntt", "nan")),
            "cause": fields.get("cause", "")}


def _robot_samples(rec: CycleRecord, robots: list[str]) -> dict[str, RobotSample]:
    out: dict[str, RobotSample] = {}
    if not rec.evaluations:
        return out
    for r in robots:
        keys = [k for k in rec.evaluations if k[0] == r]
        if not keys:
            continue
        key = ((r, rec.cutp) if (r, rec.cutp) in rec.evaluations and r == rec.rsel
               else max(keys, key=lambda k: (rec.evaluations[k].tus, -k[1])))
        ev = rec.evaluations[key]
        out[r] = RobotSample(key[1], dict(ev.values), dict(ev.texec), ev.texec_min,
                             ev.ttransf, ev.tus)
    return out


def check_invariants(kernel: MRCPKernel, setup: Setup, rec: CycleRecord) -> list[str]:
    """The platform's invariants after one cycle (empty when all hold)."""
    bad = []
    t = rec.t
    if not rec.holders:
        bad.append(f"t={t:.3f}: task ungrasped")
    if rec.rsel not in rec.holders:
        bad.append(f"t={t:.3f}: RSel {rec.rsel} not among the holders {rec.holders}")
    if setup.world.in_collision(rec.rsel):
        bad.append(f"t={t:.3f}: RSel {rec.rsel} in collision")
    for name, arm in setup.arms.items():
        q = setup.world.configuration(name)
        if np.any(q < arm.joint_lower - 1e-9) or np.any(q > arm.joint_upper + 1e-9):
            bad.append(f"t={t:.3f}: {name} outside its joint limits: {np.round(q, 4)}")
    rot = rec.task_rotation if rec.task_rotation is not None else np.eye(3)
    for holder, point in ((rec.rsel, rec.cutp),):
        held, _ = kernel.point_pose(point, rec.task_position, rot)
        tcp, _ = setup.arms[holder].tcp_pose(setup.world.configuration(holder))
        gap = float(np.linalg.norm(tcp - held))
        if gap > 1e-4:
            bad.append(f"t={t:.3f}: {holder} is {gap * 1e3:.1f} mm off its task point {point}")
    return bad


@dataclass(frozen=True)
class TrackingOperator:
    """The operator's hand on the master: each cycle it moves the task from where it is
    toward where the script wants it, at a bounded speed.

    **Decision**: the kernel applies the master's *increments* in TOp and discards them in
    TT (the operator is decoupled while the task changes hands). A script replayed as
    absolute poses would then leave the task behind by every increment lost in TT — a cube
    put down "on the table" would end below it. A human watches the task and steers it to
    the target instead; so does this operator: increment = target - achieved pose, limited
    to ``max_speed`` [m/s] and ``max_rate`` [rad/s] (it catches up after a transfer at that
    rate, as a person would, rather than in one jump the robot would refuse).
    """

    max_speed: float = 0.2
    max_rate: float = float(np.radians(120.0))

    def command(self, target: tuple[FloatArray, FloatArray | None],
                achieved: tuple[FloatArray, FloatArray | None],
                last: tuple[FloatArray, FloatArray | None], dt: float
                ) -> tuple[FloatArray, FloatArray | None]:
        """The next commanded master pose, given the script's target, the achieved task
        pose and the last command."""
        err = np.asarray(target[0], float) - np.asarray(achieved[0], float)
        n = float(np.linalg.norm(err))
        step = err if n <= self.max_speed * dt else err * (self.max_speed * dt / n)
        pos = np.asarray(last[0], float) + step
        if target[1] is None or last[1] is None:
            return pos, None
        ach = np.eye(3) if achieved[1] is None else np.asarray(achieved[1], float)
        rv = rotvec_from_matrix(np.asarray(target[1], float) @ ach.T)
        a = float(np.linalg.norm(rv))
        if a > self.max_rate * dt:
            rv = rv * (self.max_rate * dt / a)
        return pos, matrix_from_rotvec(rv) @ np.asarray(last[1], float)


#: A target pose source: time [s] -> task position ``(3,)`` and rotation ``(3, 3)`` or None.
TargetSource = Callable[[float], tuple[FloatArray, FloatArray | None]]

OPERATOR_MODES = ("scripted", "browser")


class OperatorSwitch:
    """Where the operator's target comes from: the scenario's script (``"scripted"``, the
    default) or a pose set from outside — the viewer's transform gizmo (``"browser"``).

    The runner's :class:`TrackingOperator` steers the task toward either target at the
    same bounded speed, so a gizmo dragged far away is followed at 0.2 m/s and 120 deg/s;
    the kernel still decides which robot holds the task.

    **Decision** (releasing the gizmo): the browser target is the last pose set, held until
    the next one (a released gizmo keeps the task where it was dragged). Before any pose is
    set, browser mode follows the script. A scenario whose script has no rotation ignores
    the gizmo's rotation (a position-only task). Thread-safe: the view thread sets, the
    scenario thread reads.

    Args:
        script: the scenario's scripted operator (``Setup.operator``).
    """

    def __init__(self, script: TargetSource):
        self.script = script
        self._lock = threading.Lock()
        self._mode = "scripted"
        self._pose: tuple[FloatArray, FloatArray] | None = None

    @property
    def mode(self) -> str:
        return self._mode

    def set_mode(self, mode: str) -> None:
        """``"scripted"`` or ``"browser"``.

        Raises:
            ConfigError: for another mode.
        """
        expect(mode in OPERATOR_MODES, mode, f"an operator mode of {OPERATOR_MODES}",
               field="operator")
        with self._lock:
            self._mode = mode

    def set_pose(self, position: FloatArray, rotation: FloatArray) -> None:
        """The browser target: position ``(3,)`` [m], rotation ``(3, 3)``.

        Raises:
            ConfigError: for a non-finite or mis-shaped pose.
        """
        p = check_array(position, "operator", shape=(3,),
                        what="a finite (3,) position (the operator pose)")
        r = check_array(rotation, "operator", shape=(3, 3),
                        what="a finite (3, 3) rotation (the operator pose)")
        with self._lock:
            self._pose = (p.copy(), r.copy())

    def pose(self) -> tuple[FloatArray, FloatArray] | None:
        """The last browser target (None before the first)."""
        with self._lock:
            return self._pose

    def __call__(self, t: float) -> tuple[FloatArray, FloatArray | None]:
        script = self.script(t)
        with self._lock:
            mode, pose = self._mode, self._pose
        if mode == "scripted" or pose is None:
            return script
        return pose[0].copy(), None if script[1] is None else pose[1].copy()


def run_setup(name: str, setup: Setup, duration: float | None = None,
              progress: Callable[[Sample], None] | None = None,
              operator: TargetSource | None = None) -> RunResult:
    """Runs a built scenario for ``duration`` (default: its own) and closes it.

    ``operator`` replaces the script as the source of the operator's target after t = 0
    (e.g. an :class:`OperatorSwitch`); None (default) follows ``setup.operator``.
    """
    if setup.custom_run is not None:       # a scenario with its own loop (the suture)
        try:
            out = setup.custom_run(name, duration, progress)
        finally:
            setup.close()
        assert isinstance(out, RunResult)
        return out
    cfg = setup.config
    source = setup.operator if operator is None else operator
    pos0, rot0 = setup.operator(0.0)
    hand = TrackingOperator()
    last: tuple[FloatArray, FloatArray | None] = (np.asarray(pos0, float), rot0)
    achieved: tuple[FloatArray, FloatArray | None] = last
    kernel = MRCPKernel(setup.arms, setup.world, setup.task_points, setup.rsel, setup.cutp,
                        pos0, rot0, config=cfg)
    robots = list(setup.arms)
    samples: list[Sample] = []
    violations: list[str] = []
    stop: str | None = None
    total = setup.duration if duration is None else duration
    try:
        for i in range(math.floor(total / cfg.dt + 1e-9)):
            t = (i + 1) * cfg.dt
            if setup.on_cycle is not None:
                setup.on_cycle(t, setup.world)
            pos, rot = hand.command(source(t), achieved, last, cfg.dt)
            extras = setup.extras(t) if setup.extras is not None else None
            rec = kernel.step(t, pos, rot, extras=extras)
            last = (pos, rot)
            achieved = (rec.task_position, rec.task_rotation)
            violations.extend(check_invariants(kernel, setup, rec))
            ntt = rec.continuity.ntt if rec.continuity is not None else math.nan
            s = Sample(t, rec.state.value, rec.rsel, rec.cutp, rec.holders, rec.rcnt, ntt,
                       _robot_samples(rec, robots), tuple(rec.events),
                       {r: q.copy() for r, q in rec.commands.items()},
                       rec.task_position.copy(),
                       None if rec.task_rotation is None else rec.task_rotation.copy(),
                       tuple(r for r in robots if setup.world.in_collision(r)))
            samples.append(s)
            if progress is not None:
                progress(s)
            if rec.state is KernelState.FAULT:
                # The safety stop ends a scripted run: nobody acknowledges it, and the
                # cycles after it would only log "fault: no motion" (issue #26 §4).
                cause = next((e for e in rec.events if e.startswith("rsel_collision")),
                             "fault")
                stop = f"t={t:.3f}: {cause}"
                break
    finally:
        setup.close()
    return RunResult(name, robots, samples, violations, dict(setup.notes), stop=stop)


def run(scenario: Scenario, options: ScenarioOptions | None = None,
        progress: Callable[[Sample], None] | None = None,
        operator: Callable[[Setup], TargetSource] | None = None) -> RunResult:
    """Builds and runs a scenario; ``operator`` (optional) makes the target source from the
    built setup (e.g. ``OperatorSwitch``)."""
    opts = options or ScenarioOptions()
    setup = scenario.build(opts)
    return run_setup(scenario.name, setup, opts.duration, progress,
                     None if operator is None else operator(setup))
