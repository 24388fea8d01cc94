"""The timing of a real-time run: the servo loop's statistics and the physics thread's
(shared by the threaded trial and the servo process)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from vasim.haptics.timing import TimingStats


@dataclass(frozen=True)
class RealtimeTiming:
    """Timing of a real-time trial: the servo loop's statistics and the physics thread's.

    Attributes:
        servo: the loop's ``TimingStats``.
        physics: ``PhysicsThread.stats()`` (rate, period and cost percentiles [s]), or None
            without a physics thread.
        saturated_ticks: ticks whose force was scaled down to the device's peak.
        guard_events: device readings or plant forces the guard rejected.
        clutch_presses: clutch presses.
        physics_mode: how the physics ran.
        priority_granted: whether the servo thread ran under real-time scheduling (None:
            not asked for, or not run in real time).
    """

    servo: TimingStats
    physics: dict[str, Any] | None
    saturated_ticks: int
    guard_events: int
    clutch_presses: int
    physics_mode: str
    priority_granted: bool | None = None

    @property
    def achieved_hz(self) -> float:
        return self.servo.achieved_hz

    def to_dict(self) -> dict[str, Any]:
        """The servo statistics (``TimingStats.to_dict``) plus the rest, JSON-able (NaN ->
        None): what ``timing_json`` stores per trial."""
        d: dict[str, Any] = dict(self.servo.to_dict())
        phys = None
        if self.physics is not None:
            phys = {k: (None if isinstance(v, float) and not math.isfinite(v) else v)
                    for k, v in self.physics.items()}
        d.update(physics=phys, physics_mode=self.physics_mode,
                 saturated_ticks=self.saturated_ticks, guard_events=self.guard_events,
                 clutch_presses=self.clutch_presses, priority_granted=self.priority_granted)
        return d

    def summary(self) -> str:
        line = self.servo.summary()
        if self.physics is not None and self.physics.get("steps"):
            p = self.physics
            line += (f"; physics {p['steps']} steps, {p['rate_hz']:.1f} Hz, cost p50 "
                     f"{1e3 * p['cost_p50']:.2f} ms")
        return line


__all__ = ["RealtimeTiming"]
