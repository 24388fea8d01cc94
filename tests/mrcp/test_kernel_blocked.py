"""RSel's step blocked by a robot that does not hold the task (issue #26 §4): a hold, not a
safety stop; after ``hold_transfer_s`` the hold rule hands the task over. (An obstacle in
the way stays a safety stop: ``test_kernel_loop.test_rsel_collision_is_a_safety_stop``.)"""

from __future__ import annotations

import numpy as np
import pytest

import vasim.mrcp.kernel as kernel_mod
from tests.mrcp.planar import PlanarArm, PlanarWorld
from tests.mrcp.test_kernel_loop import BAR
from vasim.mrcp.kernel import IndexSpec, KernelConfig, MRCPKernel
from vasim.mrcp.modes import KernelState


def test_a_candidate_in_rsels_way_is_a_hold_then_a_transfer(
        monkeypatch: pytest.MonkeyPatch) -> None:
    # the candidates stand still (the worst case: B never leaves A's way by itself)
    monkeypatch.setattr(kernel_mod, "move_candidate", lambda *a, **k: None)
    a = PlanarArm("A", base=np.array([0.0, 0.0, 0.0]), radius=0.015)
    b = PlanarArm("B", base=np.array([0.6, 0.4, 0.0]), yaw=np.pi, radius=0.015)
    obj0 = np.array([0.3, 0.15, 0.0])
    qa = a.ik(obj0 + BAR[0].position, None, np.array([0.5, 1.0, 0.0]))
    qb = b.ik(np.array([0.25, 0.36, 0.0]), None, np.array([0.0, 1.0, 0.0]))  # on A's path
    assert qa is not None and qb is not None
    world = PlanarWorld({"A": a, "B": b}, {"A": qa, "B": qb}, None)
    cfg = KernelConfig(indices=(IndexSpec("rj"),))
    k = MRCPKernel({"A": a, "B": b}, world, BAR, "A", 0, obj0, config=cfg)
    held: list[float] = []
    start = None
    for i in range(150):
        t = (i + 1) * cfg.dt
        rec = k.step(t, obj0 + np.array([0.0, 0.15 * t, 0.0]))
        assert rec.state is not KernelState.FAULT, rec.events
        assert not world.in_collision(rec.rsel)
        held += [t for e in rec.events if e.startswith("rsel_hold A: blocked by B (")]
        if any(e.startswith("transfer_start") for e in rec.events):
            start = (t, next(e for e in rec.events if e.startswith("transfer_start")))
            break
    assert held, "A was never blocked: the set-up no longer puts B in its way"
    assert start is not None and start[1].startswith("transfer_start B@")
    assert "cause=hold" in start[1]
    # the hold rule: a transfer once A has been held for hold_transfer_s
    assert start[0] - held[0] == pytest.approx(cfg.hold_transfer_s, abs=2 * cfg.dt)
