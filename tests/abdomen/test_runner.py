"""vasim.abdomen.runner's PhysicsThread against a fake world that steps in no time: every step
is counted after the statistics trim, events are drained losslessly, and a thread that did not
end on stop() stays registered."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass
from typing import Any

import pytest

from tests.polling import wait_until
from vasim.abdomen.runner import PhysicsThread


@dataclass(frozen=True)
class _Snap:
    t: float
    seq: int
    events: tuple[tuple[str, str], ...] = ()


class _FakeWorld:
    """Steps in no time; every step is a reset event; ``gate`` can hold a step."""

    dt = 0.001

    def __init__(self) -> None:
        self.calls = 0
        self.latest = _Snap(0.0, 0)
        self.gate = threading.Event()
        self.gate.set()
        self.blocked = threading.Event()  # set once a step waits at the cleared gate

    def step(self, tool: Any) -> _Snap:
        if not self.gate.wait(timeout=0):
            self.blocked.set()
            self.gate.wait()
        self.calls += 1
        self.latest = _Snap(self.calls * self.dt, self.calls,
                            (("organ_reset", f"liver: reset {self.calls}"),))
        return self.latest


def test_stats_count_every_step_after_the_trim_and_events_are_drained_losslessly() -> None:
    world = _FakeWorld()
    physics = PhysicsThread(world, rate_hz=1e9)  # type: ignore[arg-type]
    physics.start()
    drained: list[tuple[float, str, str]] = []
    deadline = time.monotonic() + 120.0
    while world.calls < 100_500:
        if time.monotonic() > deadline:
            physics.stop()
            pytest.fail(f"the physics thread made {world.calls} of 100500 steps in 120 s")
        drained += physics.drain_events()
        time.sleep(0.01)
    physics.stop()
    drained += physics.drain_events()
    assert physics.stats()["steps"] == world.calls > 100_000
    assert [d for _, _, d in drained] == [f"liver: reset {i}" for i in range(1, world.calls + 1)]


def test_stop_keeps_a_thread_that_did_not_end_registered() -> None:
    world = _FakeWorld()
    physics = PhysicsThread(world, rate_hz=1000.0)  # type: ignore[arg-type]
    physics.start()
    wait_until(lambda: world.calls >= 2, what="two physics steps", step=0.001)
    world.gate.clear()  # the next step hangs
    wait_until(world.blocked.is_set, what="a physics step held at the gate", step=0.001)
    physics.stop(timeout=0.05)
    assert physics.running
    with pytest.raises(RuntimeError, match="already running"):
        physics.start()
    world.gate.set()
    physics.stop()
    assert not physics.running




