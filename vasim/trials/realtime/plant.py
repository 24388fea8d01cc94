"""The plant the servo loop drives: the trial runner coupled to the tool, and the physics
hand-off (feeds) beside it (the per-tick steps and the force blending: the package
docstring, ``vasim.trials.realtime``)."""

from __future__ import annotations

import math
import threading
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from vasim.abdomen.contact import ToolPose
from vasim.abdomen.runner import PhysicsThread
from vasim.core.config import check_number
from vasim.core.errors import DeviceError
from vasim.haptics.coupling import CouplingParams, LinearForce
from vasim.haptics.device import FloatArray
from vasim.haptics.observation import OperatorObservation
from vasim.haptics.servo import CoupledToolPlant
from vasim.trials.realtime.recording import PhysicsLog
from vasim.trials.vf import (
    MasterIncrement,
    TrialRunner,
)

PhysicsMode = Literal["thread", "inline", "off"]
"""``thread``: real-time physics thread; ``inline``: stepped inside the control step every
``abdomen.dt`` (deterministic; for tests and ``run_ticks``); ``off``: the abdomen stays as
it was built (no motion, no contact updates)."""

_ZERO = (0.0, 0.0, 0.0)
_ZERO9 = (0.0,) * 9

DEFAULT_BLEND_S = 0.02
"""Time constant of the blending of physics updates into the rendered force [s] (module
docstring): 5 physics periods of the default scene."""


class RecordingWorld:
    """An ``Abdomen`` as the physics thread sees it: every step's pose is logged; once
    frozen (the trial is over) steps do nothing, so the log and the tissue statistics end
    with the trial. The lock lets a reader wait for a step in flight."""

    def __init__(self, abdomen: Any, log: PhysicsLog):
        self.abdomen = abdomen
        self.dt = abdomen.dt
        self.log = log
        self.lock = threading.Lock()
        self.frozen = False

    @property
    def latest(self) -> Any:
        return self.abdomen.latest

    def step(self, tool: ToolPose | None) -> Any:
        with self.lock:
            if self.frozen:
                return self.abdomen.latest
            self.log.add_step(tool)
            return self.abdomen.step(tool)

    def freeze(self) -> None:
        with self.lock:
            self.frozen = True


class ThreadFeed:
    """Posts the tool pose to the physics thread and hands over its newest snapshot."""

    def __init__(self, physics: PhysicsThread, log: PhysicsLog):
        self.physics = physics
        self.log = log
        self._seq = physics.latest.seq
        self._pending: list[tuple[float, str, str]] = []

    def __call__(self, k: int, pose: ToolPose) -> Any:
        self.physics.set_tool(pose)
        snap = self.physics.latest
        if snap.seq != self._seq:
            self._seq = snap.seq
            self.log.applied.append((k, snap.seq))
            # the events of every step since the last hand-off (also of skipped
            # snapshots) ride on this one; those of steps newer than it wait for the next.
            self._pending += self.physics.drain_events()
            now = tuple((kind, d) for t, kind, d in self._pending if t <= snap.t)
            self._pending = [e for e in self._pending if e[0] > snap.t]
            if now != tuple(snap.events):
                snap = replace(snap, events=now)
            return snap
        return None


class InlineFeed:
    """Steps the abdomen inside the control step every ``every`` steps (as headless)."""

    def __init__(self, abdomen: Any, every: int, log: PhysicsLog):
        self.abdomen = abdomen
        self.every = every
        self.log = log

    def __call__(self, k: int, pose: ToolPose) -> Any:
        if k % self.every:
            return None
        self.log.add_step(pose)
        snap = self.abdomen.step(pose)
        self.log.applied.append((k, snap.seq))
        return snap


class ReplayFeed:
    """Re-steps a fresh abdomen with the recorded poses; hands each recorded snapshot over
    at the recorded control step; ``finish`` runs the steps left after the last one."""

    def __init__(self, abdomen: Any, log: PhysicsLog):
        self.abdomen = abdomen
        self.log = log
        self._next = 0

    def _step_to(self, seq: int) -> None:
        a = self.abdomen
        if seq > self.log.n_steps:
            raise DeviceError(f"the physics log has {self.log.n_steps} steps, the run asks "
                              f"for step {seq}")
        while a.seq < seq:
            a.step(self.log.pose(a.seq + 1))

    def __call__(self, k: int, pose: ToolPose) -> Any:
        del pose  # the recorded poses decide
        applied = self.log.applied
        i = self._next
        if i < len(applied) and applied[i][0] == k:
            self._next = i + 1
            self._step_to(applied[i][1])
            return self.abdomen.latest
        return None

    def finish(self) -> None:
        self._step_to(self.log.n_steps)


# ---------------------------------------------------------------------------------------
# The plant


class TrialPlant:
    """A ``TrialRunner`` as the servo loop's plant (module docstring, steps 2-4).

    Args:
        runner: the trial (its operator is replaced by a ``MasterIncrement``).
        coupling: virtual-coupling parameters.
        dt: the servo period [s] (the trial's control step).
        blend_s: time constant of the blending of a new physics snapshot into the rendered
            tissue force [s] (module docstring); 0 switches at once.

    Attributes:
        felt: the last force handed to the coupling, F_fixtures + F_tissue [N] (3 floats).
        force: the last coupling force returned to the loop [N] (before saturation).
    """

    def __init__(self, runner: TrialRunner, coupling: CouplingParams | None = None, *,
                 dt: float = 1e-3, blend_s: float = DEFAULT_BLEND_S):
        check_number(blend_s, "blend_s", ge=0)
        self.runner = runner
        self.blend_s = float(blend_s)
        self._decay = math.exp(-dt / blend_s) if blend_s > 0 else 0.0
        self._offset: tuple[float, ...] = _ZERO
        self._snap_id = id(runner.state.snap)
        self._fc_prev: tuple[float, ...] = _ZERO
        self._kt_prev: tuple[float, ...] | None = None
        self._x_prev: tuple[float, ...] = tuple(runner.state.x)
        self.input = MasterIncrement()
        runner.operator = self.input  # the increment source plays the operator
        self.coupled = CoupledToolPlant(coupling, dt=dt)
        self.on_done: list[Any] = []
        self._prev: tuple[float, float, float] | None = None
        self.felt: tuple[float, ...] = _ZERO
        self.force: tuple[float, ...] = _ZERO

    def on_start(self, t: float) -> None:
        self._prev = None
        self.coupled.on_start(t)

    def on_stop(self) -> None:
        pass

    def observation(self) -> OperatorObservation | None:
        """What a scripted operator perceives: the runner's cues, and the force the device
        is rendering (the coupling's) instead of the headless trial's felt force."""
        r = self.runner
        if r.done:
            return None
        return replace(r.observation(), force=np.array(self.force))

    def tick(self, t: float, master: FloatArray, buttons: int) -> tuple[float, ...]:
        r = self.runner
        if r.done:
            self.force = _ZERO
            return _ZERO
        m0, m1, m2 = master.tolist()
        p = self._prev
        self._prev = (m0, m1, m2)
        if p is not None:
            self.input.set((m0 - p[0], m1 - p[1], m2 - p[2]))
        r.step()
        if r.done:
            for fn in self.on_done:
                fn()
        st = r.state
        c, fc, kt, x = st.cues, st.fc, st.kt, st.x
        o = self._offset
        if self._decay:
            if id(st.snap) != self._snap_id:  # a new snapshot: blend its force step in
                self._snap_id = id(st.snap)
                q, kp = self._fc_prev, self._kt_prev
                if kp is not None:  # what the old planes give here, to first order
                    d0, d1, d2 = (x[0] - self._x_prev[0], x[1] - self._x_prev[1],
                                  x[2] - self._x_prev[2])
                    q = (q[0] + kp[0] * d0 + kp[1] * d1 + kp[2] * d2,
                         q[1] + kp[3] * d0 + kp[4] * d1 + kp[5] * d2,
                         q[2] + kp[6] * d0 + kp[7] * d1 + kp[8] * d2)
                o = (o[0] + q[0] - fc[0], o[1] + q[1] - fc[1], o[2] + q[2] - fc[2])
            a = self._decay
            o = self._offset = (a * o[0], a * o[1], a * o[2])
            self._fc_prev, self._kt_prev, self._x_prev = fc, kt, x
        felt = self.felt = (c[0] + fc[0] + o[0], c[1] + fc[1] + o[1], c[2] + fc[2] + o[2])
        if kt is None:
            k = _ZERO9
        else:  # dF/dmaster = dF/dx diag(1 / MS): the slave moves dX_M / MS per axis
            s0, s1, s2 = (1.0 / v if v else 0.0 for v in st.ms)
            k = (kt[0] * s0, kt[1] * s1, kt[2] * s2, kt[3] * s0, kt[4] * s1, kt[5] * s2,
                 kt[6] * s0, kt[7] * s1, kt[8] * s2)
        self.coupled.set_tissue(LinearForce(np.array(felt), np.array(k), master))
        f = self.force = self.coupled.tick(t, master, buttons)
        return f


__all__ = ["DEFAULT_BLEND_S", "PhysicsMode", "TrialPlant"]
