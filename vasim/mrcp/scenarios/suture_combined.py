"""Experiment 4 of the seed (sec. 5.5, Figs. 5.34-5.37): a continuous suture with the
teleoperation modes combined — ``vasim mrcp run suture_combined``.

Two tool robots hold 5 mm instruments through trocars, a third holds the endoscope; the
task is a curved needle with a thread (:mod:`vasim.mrcp.thread`); the tissue is two lips
either side of an incision, moving with breathing (:mod:`.suture_geometry`).

**The state graph** (Figs. 5.34-5.35): :class:`SutureGraph` walks the subtasks
``pre_suture``, then per stitch ``approximation, insertion, pass_through,
needle_transfer, extraction, tighten_thread, needle_return``, then ``knot_tying``; each
subtask's pairing mode is :data:`vasim.mrcp.modes.SUTURE_SUBTASK_MODE` (StdT for
pre-suture and knot tying, MRCP for stitching), switched by
:func:`vasim.mrcp.modes.switch_mode` (never during a task transfer). A subtask ends on an
event, not a clock:

* ``approximation``: the needle reached the stitch's start pose (tip above the entry);
* ``insertion``: the tip is inside the tissue (the entry point is recorded);
* ``pass_through``: the MRCP kernel started a transfer — the tissue blocks the holding
  tool (the CR index of the kernel; nothing in the script forces it; the exit point is
  recorded when the tip comes out);
* ``needle_transfer``: the transfer completed (R1 holds the needle near its tip);
* ``extraction``: the needle's tail has left the tissue (the thread is pinned at the
  stitch's entry and exit);
* ``tighten_thread``: the stitch's slack is taken up (the thread is taut);
* ``needle_return``: the needle is back on the starting side and held by R0 again (the
  kernel hands it back: carried away from its trocar, R1 leaves its tool cone).

Each MRCP subtask has a timeout; a subtask that times out is recorded as a violation and
the graph moves on (the run never hangs). In StdT each master drives one robot: the
script gives each tool tip a target, approached at ``STDT_SPEED``; the needle stays in the
jaws of the robot that holds it. In MRCP one master drives the needle through the MRCP
kernel (:class:`~vasim.mrcp.kernel.MRCPKernel`, started afresh at each switch to MRCP:
**decision**, its windows then fill as after any gap), with the runner's
:class:`~vasim.mrcp.scenarios.runner.TrackingOperator` steering the needle to the script.

Checks every cycle (the run's ``violations``): the runner's invariants in MRCP (needle
always held, RSel never in collision, joint limits, the holder at its grasp point); in
StdT the same for both robots; the needle never inside a robot (outside the holders'
jaws, :data:`~.suture_geometry.JAW`); the thread attached to the needle (gap <= 0.5 mm).

The viewer's "Operator" control does not steer this scenario (its operator is the
graph's script; ``run_setup`` hands the loop to :meth:`SutureRun.run`).

**Decisions**: the indices are RJ, CR and the tool cone (Θ is left out: it costs most and
neither hand-over of the suture depends on dexterity); the camera robot is an obstacle,
not a kernel robot; the needle is not a collision body (the tissue does not stop it).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, cast

import numpy as np

from vasim.core.geometry import slerp_matrix
from vasim.mrcp.interfaces import ArmKinematics, FloatArray
from vasim.mrcp.kernel import CycleRecord, IndexSpec, MRCPKernel, TaskPoint
from vasim.mrcp.modes import SUTURE_SUBTASK_MODE, KernelState, TeleopMode, switch_mode
from vasim.mrcp.scenarios import suture_geometry as g
from vasim.mrcp.scenarios.base import ScenarioOptions, Setup, base_pose
from vasim.mrcp.scenarios.cube_rotation import kernel_config
from vasim.mrcp.scenarios.runner import (
    RunResult,
    Sample,
    TrackingOperator,
    _robot_samples,
    check_invariants,
)
from vasim.mrcp.thread import SutureThread
from vasim.mrcp.world_sweeps import HULL_MARGIN

STITCHES = 3
STITCH_SUBTASKS = ("approximation", "insertion", "pass_through", "needle_transfer",
                   "extraction", "tighten_thread", "needle_return")
#: Tool-tip speed of a robot driven by its own master in StdT [m/s].
STDT_SPEED = 0.04
#: The needle's turning rate while stitching [rad/s] and its travel speed [m/s].
TURN_RATE = 0.6
TRAVEL_SPEED = 0.04
PULL_SPEED = 0.03
#: Where the needle is handed back: this far left of the stitch line [m].
RETURN_X = -0.05
#: The thread's length [m] and its free chain at start.
THREAD_LENGTH = 0.32
THREAD_FREE = 0.06
#: Knot tying: R1 withdraws this far along its shaft, then takes the thread this far
#: from the last exit; R0 winds round it on a ring (radius, height over R1's tip) by
#: KNOT_TURN in KNOT_TURN_S, then both pull (R0's and R1's displacements).
KNOT_WITHDRAW = 0.025
KNOT_SITE = np.array([0.012, 0.0, 0.02])
KNOT_RING = (0.016, -0.008)
KNOT_TURN = 0.5 * math.pi
KNOT_TURN_S = 2.5
KNOT_PULL = (np.array([-0.015, -0.01, 0.004]), np.array([0.012, 0.0, 0.004]))
#: A subtask that has not ended after this long is a violation [s].
TIMEOUT = 8.0
#: The largest gap between the thread's end and the needle's tail [m].
ATTACH_TOL = 5e-4
#: A robot that let go of the needle withdraws its open jaws within this long [s].
RELEASE_S = 0.5


def subtask_sequence(stitches: int = STITCHES) -> list[str]:
    """The subtasks of a suture of ``stitches`` stitches, in order.

    Example:
        >>> seq = subtask_sequence(1)
        >>> seq[0], seq[-1], len(seq)
        ('pre_suture', 'knot_tying', 9)
    """
    return ["pre_suture", *[s for _ in range(stitches) for s in STITCH_SUBTASKS], "knot_tying"]


class SutureGraph:
    """The graph of states of the combined modes (seed Fig. 5.34): the current subtask, its
    stitch and the pairing mode, advanced by :meth:`advance`.

    Example:
        >>> gr = SutureGraph(1)
        >>> gr.subtask, gr.mode.value
        ('pre_suture', 'StdT')
        >>> gr.advance(KernelState.TOP); gr.subtask, gr.mode.value, gr.stitch
        ('approximation', 'MRCP', 0)
    """

    def __init__(self, stitches: int = STITCHES) -> None:
        self.sequence = subtask_sequence(stitches)
        self.index = 0
        self.mode = SUTURE_SUBTASK_MODE[self.sequence[0]]

    @property
    def subtask(self) -> str:
        return self.sequence[self.index]

    @property
    def stitch(self) -> int:
        """The stitch of the current subtask (0-based; -1 before the first, the number of
        stitches after the last)."""
        if self.index == 0:
            return -1
        return min((self.index - 1) // len(STITCH_SUBTASKS),
                   (len(self.sequence) - 2) // len(STITCH_SUBTASKS))

    @property
    def done(self) -> bool:
        return self.index >= len(self.sequence)

    def advance(self, kernel: KernelState) -> None:
        """Next subtask; switches the pairing mode when it changes.

        Raises:
            TransitionError: a mode switch while the kernel is not in TOp.
        """
        self.index += 1
        if not self.done:
            self.mode = switch_mode(self.mode, SUTURE_SUBTASK_MODE[self.subtask], kernel)


@dataclass
class _Stitch:
    entry: FloatArray | None = None        # tissue frame
    exit: FloatArray | None = None
    t_entry: float | None = None
    t_exit: float | None = None


@dataclass
class _Run:
    """One suture run's changing state (``run``): the subtask graph, the thread and
    stitches, the hand and kernel of the MRCP subtasks, the StdT script's stage and what
    has been recorded."""

    graph: SutureGraph
    thread: SutureThread
    stitches: list[_Stitch]
    hand: TrackingOperator
    last: tuple[FloatArray, FloatArray]
    achieved: tuple[FloatArray, FloatArray]
    sub_start: tuple[FloatArray, FloatArray]
    rsel: str = "R0"
    cutp: int = 0
    kernel: MRCPKernel | None = None
    sub_t0: float = 0.0
    sub_events: list[str] = field(default_factory=list)
    stdt_stage: int = 0
    stage_t0: float = 0.0
    subtasks: list[dict[str, Any]] = field(default_factory=list)
    samples: list[Sample] = field(default_factory=list)


@dataclass
class _Tick:
    """One cycle of the run: its time, the tissue's offset, the subtask and stitch, and
    what the cycle's mode step produced."""

    t: float
    off: FloatArray
    sub: str
    k: int
    events: list[str] = field(default_factory=list)
    rec: CycleRecord | None = None
    ended: bool = False
    holders: tuple[str, ...] = ()
    state: str = ""


@dataclass
class SutureRun:
    """One run of the suture (see the module docstring); :meth:`run` is the loop."""

    arms: dict[str, ArmKinematics]
    world: Any
    task_points: list[TaskPoint]
    config: Any
    duration: float
    stitches: int = STITCHES
    needle: tuple[FloatArray, FloatArray] = field(default_factory=lambda: (np.zeros(3),
                                                                            np.eye(3)))

    # ------------------------------------------------------------------ helpers
    def point(self, k: int, pose: tuple[FloatArray, FloatArray] | None = None) -> FloatArray:
        pos, rot = pose or self.needle
        return np.asarray(pos + rot @ self.task_points[k].position, dtype=float)

    def tail(self) -> FloatArray:
        pos, rot = self.needle
        return np.asarray(pos + rot @ g.TAIL, dtype=float)

    def tip(self) -> FloatArray:
        pos, rot = self.needle
        return np.asarray(pos + rot @ g.TIP, dtype=float)

    def tcp(self, robot: str) -> FloatArray:
        return np.asarray(self.arms[robot].tcp_pose(self.world.configuration(robot))[0])

    def beta(self, rot: FloatArray) -> float:
        """The stitching angle of a needle rotation, unwrapped near the last one."""
        b = -math.atan2(float(rot[0, 2]), float(rot[0, 0]))
        return b + 2 * math.pi * round((self._beta - b) / (2 * math.pi))

    # ------------------------------------------------------------------ checks
    def needle_in_robot(self, holders: tuple[str, ...]) -> list[str]:
        """Robots whose tool shaft contains a needle point outside the jaws (the in-body
        part of each shaft: a capsule from the tip up, of the radius the collision world
        gives it: ``TOOL_RADIUS`` grown by pybullet's hull margin).

        **Decision** (the jaws): points within ``JAW`` of the tip are exempt for a robot
        whose jaws are on the needle: a holder, the receiving robot of a transfer (its
        jaws open around the needle) and a robot that let go within ``RELEASE_S``."""
        pos, rot = self.needle
        pts = pos[None, :] + g.needle_points(37) @ rot.T
        bad = []
        for r in self.world.robot_names():
            arm = self._shafts[r]
            tip, trot = arm.tcp_pose(self.world.configuration(r))
            axis = trot[:, 2]
            rel = pts - tip[None, :]
            s = np.clip(-(rel @ axis), 0.0, 0.3)
            d = np.linalg.norm(rel + s[:, None] * axis[None, :], axis=1)
            keep = np.ones(len(pts), dtype=bool)
            if r in holders:
                keep = np.linalg.norm(rel, axis=1) > g.JAW
            if np.any(d[keep] < g.TOOL_RADIUS + HULL_MARGIN):
                bad.append(r)
        return bad

    # ------------------------------------------------------------------ StdT motion
    def _drive(self, robot: str, target: FloatArray, dt: float) -> bool:
        """One StdT step of ``robot``'s tip toward ``target``; False when held (unreachable,
        too fast or a collision, which is also a violation)."""
        arm = self.arms[robot]
        q = self.world.configuration(robot)
        tip = self.tcp(robot)
        d = np.asarray(target, float) - tip
        n = float(np.linalg.norm(d))
        step = d if n <= STDT_SPEED * dt else d * (STDT_SPEED * dt / n)
        if n < 1e-9:
            return True
        sol = arm.ik(tip + step, None, q)
        if sol is None or np.any(np.abs(sol - q) > arm.max_velocity * dt * (1 + 1e-9)):
            return False
        self.world.set_configuration(robot, sol)
        if self.world.in_collision(robot):
            self.world.set_configuration(robot, q)
            self._violation(f"StdT: {robot} would collide")
            return False
        return True

    def _violation(self, text: str) -> None:
        msg = f"t={self._t:.3f}: {text}"
        if msg not in self.violations[-1:]:
            self.violations.append(msg)

    # ------------------------------------------------------------------ the run
    def run(self, name: str, duration: float | None = None,
            progress: Callable[[Sample], None] | None = None) -> RunResult:
        cfg = self.config
        dt = cfg.dt
        self.violations: list[str] = []
        self._t = 0.0
        self._beta = g.BETA_START
        self._shafts = dict(self.arms)
        self._shafts.update(self._extra_arms)
        self._jaws: dict[str, float] = {}
        self._knot = {}
        self._sub_off = g.tissue_offset(0.0)
        offset0 = g.tissue_offset(0.0)
        start = (self.needle[0].copy(), self.needle[1].copy())
        run = _Run(SutureGraph(self.stitches),
                   SutureThread(g.ANCHOR, self.tail() - offset0, THREAD_LENGTH, THREAD_FREE),
                   [_Stitch() for _ in range(self.stitches)], TrackingOperator(),
                   last=start, achieved=start,
                   sub_start=(self.needle[0].copy(), self.needle[1].copy()))
        total = self.duration if duration is None else duration
        for i in range(math.floor(total / dt + 1e-9)):
            tick = self._begin_cycle(run, (i + 1) * dt)
            if run.graph.mode is TeleopMode.STDT:
                self._stdt_cycle(run, tick, dt)
            else:
                self._mrcp_cycle(run, tick, dt)
            self._after_cycle(run, tick)
            self._close_subtask(run, tick)
            s = self._sample(run, tick)
            run.samples.append(s)
            if progress is not None:
                progress(s)
            if run.graph.done:
                break
        if not run.graph.done and duration is None:    # its own time limit: the graph stuck
            self.violations.append(f"t={self._t:.3f}: the suture did not finish "
                                   f"(stopped in {run.graph.subtask})")
        return self._result(name, run)

    def _begin_cycle(self, run: _Run, t: float) -> _Tick:
        """The cycle at time ``t``: the tissue moved with the breathing, the subtask and
        stitch it works on."""
        self._t = t
        off = g.tissue_offset(t)
        for body, (_, centre) in g.tissue_boxes().items():
            self.world.set_obstacle_pose(body, centre + off)
        k = max(0, min(run.graph.stitch, self.stitches - 1))
        return _Tick(t, off, run.graph.subtask, k)

    def _stdt_cycle(self, run: _Run, tick: _Tick, dt: float) -> None:
        """A StdT cycle: each master drives its robot's tip along the script; the needle
        moves with RSel's jaws."""
        run.kernel = None
        sub, t = tick.sub, tick.t
        targets, stage_done = self._stdt_targets(sub, run.stdt_stage, t - run.stage_t0,
                                                 run.rsel, run.stitches)
        reached = True
        for r, goal in targets.items():
            self._drive(r, goal, dt)
            reached &= bool(np.linalg.norm(self.tcp(r) - goal) < 5e-4)
        held = self.tcp(run.rsel)
        pos = held - self.needle[1] @ self.task_points[run.cutp].position
        self.needle = (pos, self.needle[1])
        if reached and stage_done:
            run.stdt_stage += 1
            run.stage_t0 = t
            if run.stdt_stage >= self._stdt_stages(sub):
                tick.ended = True
        tick.holders = (run.rsel,)
        tick.state = "StdT"
        for r, arm in self.arms.items():
            q = self.world.configuration(r)
            if np.any(q < arm.joint_lower - 1e-9) or np.any(q > arm.joint_upper + 1e-9):
                self._violation(f"{r} outside its joint limits")

    def _mrcp_cycle(self, run: _Run, tick: _Tick, dt: float) -> None:
        """An MRCP cycle: the operator's hand follows the subtask's target, the kernel
        moves the robots; its safety stops and invariant breaks are violations."""
        sub, k, t = tick.sub, tick.k, tick.t
        if run.kernel is None:
            run.kernel = MRCPKernel(self.arms, self.world, self.task_points, run.rsel,
                                    run.cutp, self.needle[0], self.needle[1],
                                    config=self.config, t0=t - dt)
            run.last = run.achieved = (self.needle[0].copy(), self.needle[1].copy())
        kernel = run.kernel
        target = self._mrcp_target(sub, k, t, t - run.sub_t0, run.sub_start, tick.off)
        pos_cmd, rot_cmd = run.hand.command(target, run.achieved, run.last, dt)
        assert rot_cmd is not None
        rec = kernel.step(t, pos_cmd, rot_cmd)
        if rec.state is KernelState.FAULT:
            # the safety stop: a violation; the operator acknowledges it and goes on
            self._violation(f"stitch {k + 1}: {sub}: RSel safety stop "
                            f"({', '.join(rec.events)})")
            kernel.reset_fault()
        run.last = (pos_cmd, rot_cmd)
        assert rec.task_rotation is not None
        run.achieved = (rec.task_position.copy(), rec.task_rotation.copy())
        self.needle = run.achieved
        tick.rec = rec
        tick.events = list(rec.events)
        run.sub_events += tick.events
        run.rsel, run.cutp, tick.holders, tick.state = (rec.rsel, rec.cutp, rec.holders,
                                                        rec.state.value)
        view = cast(Setup, _SetupView(self.arms, self.world))
        for v in check_invariants(kernel, view, rec):
            self.violations.append(v)
        tick.ended = self._mrcp_done(run, tick, target)

    def _after_cycle(self, run: _Run, tick: _Tick) -> None:
        """The needle's angle, the stitch's entry/exit, the thread, and the jaws that held
        the needle lately; an overstretched thread or a needle inside a robot is a
        violation."""
        t, off = tick.t, tick.off
        self._beta = self.beta(self.needle[1])
        self._track_stitch(tick.sub, tick.k, t, run.stitches, off)
        state_thread = run.thread.update(self.tail() - off)
        if state_thread.attach_gap > ATTACH_TOL:
            self._violation(f"thread overstretched: its end is "
                            f"{state_thread.attach_gap * 1e3:.1f} mm off the needle")
        for r in self.arms:
            if r in tick.holders or (tick.rec is not None and r == tick.rec.rcnt):
                self._jaws[r] = t
        inside = self.needle_in_robot(tuple(r for r, t_ in self._jaws.items()
                                            if t - t_ <= RELEASE_S + 1e-9))
        if inside:
            self._violation(f"needle inside {', '.join(inside)}")

    def _close_subtask(self, run: _Run, tick: _Tick) -> None:
        """Ends the subtask when it is done (and the kernel is quiet before a mode switch)
        or timed out; the graph moves on."""
        sub, k, t = tick.sub, tick.k, tick.t
        kernel, graph = run.kernel, run.graph
        ended = tick.ended
        if ended:
            if sub == "extraction":
                st = run.stitches[k]
                if st.entry is None or st.exit is None:
                    self._violation(f"stitch {k + 1}: no entry or exit point")
                else:
                    run.thread.pin(st.entry, st.exit, self.tail() - tick.off)
            if sub == "needle_transfer" and not any(e.startswith("transfer_done")
                                                    for e in run.sub_events):
                self._violation(f"stitch {k + 1}: needle_transfer ended without a transfer")
            kstate = kernel.state if kernel is not None else KernelState.TOP
            if graph.index + 1 < len(graph.sequence) and kstate is not KernelState.TOP \
                    and SUTURE_SUBTASK_MODE[graph.sequence[graph.index + 1]] is not graph.mode:
                ended = False          # the switch waits for a quiet kernel
        timed_out = (not ended and t - run.sub_t0 > TIMEOUT
                     and (kernel is None or kernel.state is KernelState.TOP))
        if not (ended or timed_out):
            return
        if timed_out:
            self._violation(f"{sub} (stitch {k + 1}) timed out")
        run.subtasks.append({"name": sub, "mode": graph.mode.value.lower(),
                             "stitch": k + 1 if sub in STITCH_SUBTASKS else None,
                             "t_start": round(run.sub_t0, 4), "t_end": round(t, 4)})
        graph.advance(kernel.state if kernel is not None else KernelState.TOP)
        if ended:
            tick.events.append(f"subtask_done {sub}")
        run.sub_t0, run.sub_start, run.sub_events = t, (self.needle[0].copy(),
                                                        self.needle[1].copy()), []
        run.stdt_stage, run.stage_t0, self._sub_off = 0, t, tick.off

    def _sample(self, run: _Run, tick: _Tick) -> Sample:
        """The cycle's sample, with the thread in the scene."""
        ts = run.thread.state()
        off, rec = tick.off, tick.rec
        scene = {"thread": (ts.nodes + off).tolist(), "pinned": (ts.pinned + off).tolist(),
                 "slack": ts.slack, "reserve": ts.reserve, "free_length": ts.free_length,
                 "attach_gap": ts.attach_gap, "stitch": tick.k + 1}
        return Sample(tick.t, tick.state, run.rsel, run.cutp, tick.holders,
                      rec.rcnt if rec else None,
                      rec.continuity.ntt if rec is not None and rec.continuity is not None
                      else math.nan,
                      _robot_samples(rec, list(self.arms)) if rec is not None else {},
                      tuple(tick.events),
                      {r: self.world.configuration(r).copy() for r in self.arms},
                      self.needle[0].copy(), self.needle[1].copy(),
                      tuple(r for r in self.arms if self.world.in_collision(r)),
                      subtask=tick.sub,
                      mode=run.graph.mode.value if not run.graph.done else "StdT",
                      scene=scene)

    def _result(self, name: str, run: _Run) -> RunResult:
        """The run's result: samples, violations, subtasks, stitches and the thread."""
        ts = run.thread.state()
        graph = run.graph

        def rounded(p: FloatArray | None) -> list[float] | None:
            return None if p is None else [round(float(v), 5) for v in p]

        extra = {"subtasks": run.subtasks,
                 "stitches": [{"stitch": n + 1, "entry": rounded(s_.entry),
                               "exit": rounded(s_.exit), "t_entry": s_.t_entry,
                               "t_exit": s_.t_exit} for n, s_ in enumerate(run.stitches)],
                 "thread": {"length": THREAD_LENGTH, "total": round(ts.total_length, 9),
                            "slack": round(ts.slack, 6), "reserve": round(ts.reserve, 6)}}
        return RunResult(name, list(self.arms), run.samples, self.violations,
                         {"stitches": self.stitches, "breathing_amplitude_m": g.BREATH_AMPLITUDE,
                          "breathing_period_s": g.BREATH_PERIOD, "finished": graph.done,
                          "stopped_in": None if graph.done else graph.subtask}, extra=extra)

    # ------------------------------------------------------------------ the stitch
    def _track_stitch(self, sub: str, k: int, t: float, stitches: list[_Stitch],
                      off: FloatArray) -> None:
        """Records the entry (the tip goes below the surface) and exit (it comes out on the
        other lip) of stitch ``k``."""
        st = stitches[k]
        if sub not in ("insertion", "pass_through", "needle_transfer", "extraction"):
            return
        tip = self.tip()
        inside = g.below_surface(tip, t)
        if st.entry is None and inside:
            st.entry, st.t_entry = tip - off, round(t, 4)
        elif (st.entry is not None and st.exit is None and not inside
              and tip[0] > g.INCISION_GAP and tip[2] - off[2] > g.SURFACE_Z):
            st.exit, st.t_exit = tip - off, round(t, 4)

    def _mrcp_target(self, sub: str, k: int, t: float, since: float,
                     start: tuple[FloatArray, FloatArray], off: FloatArray
                     ) -> tuple[FloatArray, FloatArray]:
        """The operator's needle pose in an MRCP subtask (world frame)."""
        centre = g.stitch_centre(k) + off
        b0 = self.beta(start[1])
        if sub == "approximation":
            goal = (centre, g.needle_rotation(g.BETA_START))
            return _towards(start, goal, since, TRAVEL_SPEED)
        if sub in ("insertion", "pass_through", "extraction"):
            b = b0 + TURN_RATE * since
            if sub == "extraction":
                b = min(b, g.EXIT_ANGLE + math.pi + 0.35 + 2 * math.pi * round(
                    (b0 - g.EXIT_ANGLE - math.pi) / (2 * math.pi)))
            return centre, g.needle_rotation(b)
        if sub == "needle_transfer":
            return start
        if sub == "tighten_thread":
            pull = np.array([0.5, -0.3, 0.8])
            pull /= np.linalg.norm(pull)
            # the pull starts where the needle was, riding on the breathing tissue
            return start[0] + off - self._sub_off + pull * PULL_SPEED * since, start[1]
        if sub == "needle_return":
            nxt = g.stitch_centre(min(k + 1, self.stitches - 1)) + off
            goal = (nxt + np.array([RETURN_X, 0.0, 0.012]), g.needle_rotation(g.BETA_START))
            return _towards(start, goal, since, TRAVEL_SPEED)
        raise ValueError(f"not an MRCP subtask: {sub!r}")

    def _mrcp_done(self, run: _Run, tick: _Tick,
                   target: tuple[FloatArray, FloatArray]) -> bool:
        """Whether the MRCP subtask of ``tick`` is done (``target``: the operator's pose)."""
        sub, k, t = tick.sub, tick.k, tick.t
        kernel, stitches, thread = run.kernel, run.stitches, run.thread
        events, rsel = run.sub_events, run.rsel
        assert kernel is not None
        quiet = kernel.state is KernelState.TOP
        near = bool(np.linalg.norm(self.needle[0] - target[0]) < 1e-3
                    and np.linalg.norm(self.needle[1] - target[1]) < 0.03)
        if sub == "approximation":
            return quiet and near and _angle_gap(self._beta, g.BETA_START) < 0.05
        if sub == "insertion":
            return stitches[k].entry is not None and self._beta - 2 * math.pi * round(
                (self._beta - g.ENTRY_ANGLE) / (2 * math.pi)) > g.ENTRY_ANGLE + 0.15
        if sub == "pass_through":
            return any(e.startswith("transfer_start") for e in events)
        if sub == "needle_transfer":
            return any(e.startswith("transfer_done") for e in events) and quiet
        if sub == "extraction":
            tail = self.tail()
            return (quiet and near and stitches[k].exit is not None
                    and not g.below_surface(tail, t) and tail[0] > 0.0)
        if sub == "tighten_thread":
            return thread.slack <= 0.0 and thread.taut() and quiet
        if sub == "needle_return":
            return quiet and rsel == "R0" and near
        raise ValueError(f"not an MRCP subtask: {sub!r}")

    # ------------------------------------------------------------------ StdT scripts
    @staticmethod
    def _stdt_stages(sub: str) -> int:
        return 1 if sub == "pre_suture" else 5

    def _stdt_targets(self, sub: str, stage: int, since: float, rsel: str,
                      stitches: list[_Stitch]) -> tuple[dict[str, FloatArray], bool]:
        """Each master's tool-tip target in a StdT subtask, and whether its stage's script
        is over (the stage ends when the tips are also there)."""
        off = g.tissue_offset(self._t)
        other = "R1" if rsel == "R0" else "R0"
        if sub == "pre_suture":
            # R0 brings the needle over the first stitch, R1 goes to wait near its tip point
            centre = g.stitch_centre(0) + off + np.array([0.0, 0.0, 0.004])
            rot = g.needle_rotation(g.BETA_START)
            goal0 = centre + rot @ self.task_points[0].position
            wait1 = g.entry_exit(0)[1] + off + np.array([0.006, 0.0, 0.012])
            return {"R0": goal0, "R1": wait1}, True
        # knot tying: the free end's robot (``other``, R1) withdraws along its shaft, then
        # takes the thread above the last exit; the needle's robot wraps the thread round
        # R1's jaws on the trocars' side; both pull
        last = stitches[-1].exit if stitches[-1].exit is not None else g.entry_exit(
            self.stitches - 1)[1]
        site = last + off + KNOT_SITE
        if stage not in self._knot:
            self._knot[stage] = {r: self.tcp(r) - off for r in (rsel, other)}
        held = {r: p + off for r, p in self._knot[stage].items()}
        if stage == 0:
            shaft = self.arms[other].tcp_pose(self.world.configuration(other))[1][:, 2]
            return {other: held[other] - KNOT_WITHDRAW * shaft, rsel: held[rsel]}, True
        if stage == 1:
            return {other: site, rsel: held[rsel]}, True
        ring = site + np.array([0.0, 0.0, KNOT_RING[1]])
        if stage == 2:
            return {rsel: ring + KNOT_RING[0] * np.array([-1.0, 0.0, 0.0]), other: site}, True
        if stage == 3:
            turn = min(1.0, since / KNOT_TURN_S)
            psi = math.pi + KNOT_TURN * turn
            loop = ring + KNOT_RING[0] * np.array([math.cos(psi), math.sin(psi), 0.0])
            return {rsel: loop, other: site}, turn >= 1.0
        return {rsel: held[rsel] + KNOT_PULL[0], other: site + KNOT_PULL[1]}, True

    _extra_arms: dict[str, ArmKinematics] = field(default_factory=dict)
    _knot: dict[int, dict[str, FloatArray]] = field(default_factory=dict)
    _sub_off: FloatArray = field(default_factory=lambda: np.zeros(3))


def _angle_gap(a: float, b: float) -> float:
    """``|a - b|`` on the circle [rad].

    Example:
        >>> round(_angle_gap(0.01, 2 * math.pi - 0.01), 6)
        0.02
    """
    d = math.fmod(a - b, 2 * math.pi)
    return abs(min(d % (2 * math.pi), (-d) % (2 * math.pi)))


def _towards(start: tuple[FloatArray, FloatArray], goal: tuple[FloatArray, FloatArray],
             since: float, speed: float) -> tuple[FloatArray, FloatArray]:
    """A straight path from ``start`` to ``goal`` at ``speed`` (rotation by slerp)."""
    dist = float(np.linalg.norm(goal[0] - start[0]))
    frac = 1.0 if dist < 1e-9 else min(1.0, since * speed / dist)
    return (start[0] + frac * (goal[0] - start[0]),
            slerp_matrix(start[1], goal[1], frac))


@dataclass
class _SetupView:
    """What :func:`~vasim.mrcp.scenarios.runner.check_invariants` reads of a setup."""

    arms: dict[str, ArmKinematics]
    world: Any


def task_points() -> list[TaskPoint]:
    """The needle's grasp points: 0 near the tail (R0's), 1 near the tip (R1's), with
    their pre-grasp offsets (see :mod:`.suture_geometry`)."""
    return [TaskPoint(g.arc_point(phi), None, approach=g.approach_vector())
            for phi in g.GRASP_PHI]


class SutureCombined:
    name = "suture_combined"
    summary = ("the seed's experiment 4: a three-stitch continuous suture, pre-suture and "
               "knot tying in StdT, each stitch's seven subtasks in MRCP, a curved needle "
               "with a thread, a breathing tissue with an incision (seed sec. 5.5)")
    duration = 150.0

    def build(self, options: ScenarioOptions) -> Setup:
        from vasim.mrcp.backend import PybulletArm, PybulletWorld
        from vasim.mrcp.fulcrum import Fulcrum, LaparoscopicArm, LaparoscopicTool
        from vasim.mrcp.indices.cone import ConeSector, ToolCone
        from vasim.mrcp.scenarios.laparoscopic_rings import tool_model

        model = tool_model(g.TOOL_LENGTH, g.TOOL_RADIUS)
        world = PybulletWorld()
        up = np.array([0.0, 0.0, 1.0])
        tool = LaparoscopicTool(g.TOOL_LENGTH)
        arms: dict[str, ArmKinematics] = {
            r: LaparoscopicArm(PybulletArm(model, base_pose(*g.BASES[r]), name=r), tool,
                               Fulcrum(g.TROCARS[r], up)) for r in g.BASES}
        tps = task_points()
        centre = g.stitch_centre(0) + np.array([-0.03, -0.01, 0.02])
        rot = g.needle_rotation(g.BETA_START)
        starts = {"R0": centre + rot @ tps[0].position,
                  "R1": np.array([0.035, g.PATH_Y - 0.02, g.SURFACE_Z + 0.035])}
        for r in ("R0", "R1"):
            q = arms[r].ik(starts[r], None, model.home)
            if q is None:
                raise RuntimeError(f"suture_combined: {r} cannot reach its start")
            world.add_robot(r, model, base_pose(*g.BASES[r]), q)
        camera = LaparoscopicArm(PybulletArm(model, base_pose(*g.CAMERA_BASE), name="C"),
                                 tool, Fulcrum(g.CAMERA_TROCAR, up))
        qc = camera.ik(g.CAMERA_TIP, None, model.home)
        if qc is None:
            raise RuntimeError("suture_combined: the camera robot cannot reach its view")
        world.add_robot("C", model, base_pose(*g.CAMERA_BASE), qc)
        for body, (half, c) in g.tissue_boxes().items():
            world.add_box(body, half, c)
        cones = {r: ToolCone(g.TROCARS[r], -up, np.array([1.0, 0.0, 0.0]),
                             (ConeSector(0.0, 2 * np.pi + 1e-9, g.CONE_A, g.CONE_B),))
                 for r in g.BASES}
        indices = (IndexSpec("rj", {"b_max": 3.0}), IndexSpec("cr"),
                   IndexSpec("cone", {"cones": cones}))
        cfg = kernel_config(options.coarse, options.seed, indices)
        cfg = dataclasses.replace(cfg, planner=dataclasses.replace(
            cfg.planner, dr_max=0.1 * cfg.dt, safety_margin=0.0015, influence=0.01))
        runner = SutureRun(arms, world, tps, cfg, self.duration,
                           needle=(centre, rot))
        runner._extra_arms = {"C": camera}
        start = (centre.copy(), rot.copy())

        def operator(t: float) -> tuple[FloatArray, FloatArray]:
            return start

        return Setup(arms=arms, world=world, task_points=tps, rsel="R0", cutp=0,
                     operator=operator, config=cfg, duration=self.duration, close=world.close,
                     notes={"trocars": {r: v.tolist() for r, v in g.TROCARS.items()}},
                     custom_run=runner.run)
