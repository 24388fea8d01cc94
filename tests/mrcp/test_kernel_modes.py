"""TOp/TT state machine, teleoperation modes, pairing and the suture subtasks."""

from __future__ import annotations

import pytest

from vasim.core.errors import TransitionError
from vasim.mrcp.modes import (
    KERNEL_TRANSITIONS,
    SUTURE_SUBTASK_MODE,
    TASK,
    KernelEvent,
    KernelState,
    TeleopMode,
    next_state,
    pairing,
    switch_mode,
)


def test_transfer_cycle_returns_to_top() -> None:
    s = KernelState.TOP
    for e in (KernelEvent.START_TRANSFER, KernelEvent.AT_PREGRASP, KernelEvent.GRASPED,
              KernelEvent.RELEASED):
        s = next_state(s, e)
    assert s is KernelState.TOP
    assert next_state(KernelState.TT_GRASP, KernelEvent.ABORT) is KernelState.TOP


def test_release_only_after_grasp() -> None:
    """The table itself guarantees the task is never left ungrasped: RELEASED is accepted
    only in TT_HANDOVER, which only GRASPED enters."""
    releasing = [s for (s, e) in KERNEL_TRANSITIONS if e is KernelEvent.RELEASED]
    assert releasing == [KernelState.TT_HANDOVER]
    entering = [(s, e) for (s, e), t in KERNEL_TRANSITIONS.items()
                if t is KernelState.TT_HANDOVER]
    assert entering == [(KernelState.TT_GRASP, KernelEvent.GRASPED)]
    with pytest.raises(TransitionError, match=r"'TOp'.*'released'"):
        next_state(KernelState.TOP, KernelEvent.RELEASED)
    with pytest.raises(TransitionError):
        next_state(KernelState.TT_HANDOVER, KernelEvent.ABORT)


def test_fault_from_every_active_state() -> None:
    for s in KernelState:
        if s is KernelState.FAULT:
            continue
        assert next_state(s, KernelEvent.RSEL_COLLISION) is KernelState.FAULT
    assert next_state(KernelState.FAULT, KernelEvent.RESET) is KernelState.TOP
    assert KernelState.TT_GRASP.mode == "TT" and KernelState.TOP.mode == "TOp"
    assert KernelState.TOP.operator_input_applied
    assert not KernelState.TT_APPROACH.operator_input_applied


def test_mode_switching() -> None:
    assert switch_mode(TeleopMode.STDT, TeleopMode.MRCP, KernelState.TOP) is TeleopMode.MRCP
    with pytest.raises(TransitionError, match=r"TT\.grasp"):
        switch_mode(TeleopMode.MRCP, TeleopMode.STDT, KernelState.TT_GRASP)
    assert switch_mode(TeleopMode.MRCP, TeleopMode.MRCP, KernelState.TT_GRASP) is \
        TeleopMode.MRCP


def test_pairing() -> None:
    assert pairing(TeleopMode.STDT, ["l", "r"], ["r1", "r2"]) == {"l": "r1", "r": "r2"}
    assert pairing(TeleopMode.MRCP, ["l", "r"], ["r1", "r2"]) == {"l": TASK}
    with pytest.raises(ValueError, match="camera"):
        pairing(TeleopMode.MRCP_CAM, ["l", "r"], ["r1", "r2"])
    with pytest.raises(ValueError, match="StdT needs"):
        pairing(TeleopMode.STDT, ["l"], ["r1", "r2"])


def test_suture_subtasks() -> None:
    stitching = ["approximation", "insertion", "pass_through", "needle_transfer",
                 "extraction", "tighten_thread", "needle_return"]
    assert all(SUTURE_SUBTASK_MODE[s] is TeleopMode.MRCP for s in stitching)
    assert SUTURE_SUBTASK_MODE["pre_suture"] is TeleopMode.STDT
    assert SUTURE_SUBTASK_MODE["knot_tying"] is TeleopMode.STDT
