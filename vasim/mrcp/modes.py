"""Operational modes of the slave station (spec/mrcp.md §8, seed Fig. 4.15, Table 4.2,
Fig. 5.34; suture subtasks in spec/study.md §5).

Two layers, each an explicit transition table; an illegal transition raises
:class:`~vasim.core.errors.TransitionError` naming the state and the event.

1. :class:`KernelState` — the MRCP control loop. ``TOP`` (task-oriented teleoperation:
   evaluate -> NTT -> actions, master input applied) and the task-transfer phases
   ``TT_APPROACH`` (RCnt to its pre-grasp pose), ``TT_GRASP`` (straight final approach),
   ``TT_HANDOVER`` (both hold: RCnt grasps, then RSel releases). In every TT phase the
   operator's input is held. ``FAULT`` is the safety stop of Algorithm 2 ("RSel collision").
   **Decision** (the seed's Table 4.2 did not survive extraction): the TT mode is split into
   these three phases so that "the task is never left ungrasped" is a property of the table
   — RSel releases only on ``RELEASED`` after ``GRASPED``.
2. :class:`TeleopMode` — how masters pair with slaves: ``STDT`` (bimanual standard
   teleoperation, each master drives one robot), ``MRCP`` (one master drives the task) and
   ``MRCP_CAM`` (one master drives the task, the other the camera robot). Switching is
   allowed only while the kernel is in ``TOP`` (never during a transfer).

:data:`SUTURE_SUBTASK_MODE` maps the seed's suture subtasks to the mode that suits them:
pre-suture and knot tying in StdT, the seven stitching subtasks in MRCP.
"""

from __future__ import annotations

from collections.abc import Sequence
from enum import Enum

from vasim.core.errors import TransitionError


class KernelState(Enum):
    TOP = "TOp"
    TT_APPROACH = "TT.approach"
    TT_GRASP = "TT.grasp"
    TT_HANDOVER = "TT.handover"
    FAULT = "fault"

    @property
    def mode(self) -> str:
        """The seed's operational mode: ``"TOp"``, ``"TT"`` or ``"fault"``."""
        return self.value.split(".")[0]

    @property
    def operator_input_applied(self) -> bool:
        return self is KernelState.TOP


class KernelEvent(Enum):
    START_TRANSFER = "start_transfer"      # NTT >= threshold, RCnt != RSel
    AT_PREGRASP = "at_pregrasp"
    GRASPED = "grasped"                    # RCnt closed on its point: two holders
    RELEASED = "released"                  # RSel opened: roles swapped
    ABORT = "abort"                        # RCnt cannot reach its point in time
    RSEL_COLLISION = "rsel_collision"
    RESET = "reset"


_S, _E = KernelState, KernelEvent
KERNEL_TRANSITIONS: dict[tuple[KernelState, KernelEvent], KernelState] = {
    (_S.TOP, _E.START_TRANSFER): _S.TT_APPROACH,
    (_S.TT_APPROACH, _E.AT_PREGRASP): _S.TT_GRASP,
    (_S.TT_GRASP, _E.GRASPED): _S.TT_HANDOVER,
    (_S.TT_HANDOVER, _E.RELEASED): _S.TOP,
    (_S.TT_APPROACH, _E.ABORT): _S.TOP,
    (_S.TT_GRASP, _E.ABORT): _S.TOP,
    (_S.TOP, _E.RSEL_COLLISION): _S.FAULT,
    (_S.TT_APPROACH, _E.RSEL_COLLISION): _S.FAULT,
    (_S.TT_GRASP, _E.RSEL_COLLISION): _S.FAULT,
    (_S.TT_HANDOVER, _E.RSEL_COLLISION): _S.FAULT,
    (_S.FAULT, _E.RESET): _S.TOP,
}


def next_state(state: KernelState, event: KernelEvent) -> KernelState:
    """The state after ``event`` (``KERNEL_TRANSITIONS``).

    Raises:
        TransitionError: when the table has no such transition.

    Example:
        >>> next_state(KernelState.TOP, KernelEvent.START_TRANSFER).value
        'TT.approach'
    """
    try:
        return KERNEL_TRANSITIONS[(state, event)]
    except KeyError:
        raise TransitionError(f"no transition from {state.value!r} on {event.value!r}") from None


class TeleopMode(Enum):
    STDT = "StdT"          # 2M:2S, each master drives one robot
    MRCP = "MRCP"          # 1M:nS, the master drives the task
    MRCP_CAM = "MRCP+Cam"  # 1M:nS for the task + 1M:1S for the camera robot


MODE_SWITCHES: frozenset[tuple[TeleopMode, TeleopMode]] = frozenset(
    (a, b) for a in TeleopMode for b in TeleopMode if a is not b)


def switch_mode(current: TeleopMode, target: TeleopMode, kernel: KernelState) -> TeleopMode:
    """Switch the pairing mode (Fig. 5.34); only from a quiet kernel.

    Raises:
        TransitionError: during a task transfer or a fault, or for an unknown switch.
    """
    if current is target:
        return current
    if kernel is not KernelState.TOP:
        raise TransitionError(f"cannot switch {current.value!r} -> {target.value!r} while the "
                              f"kernel is in {kernel.value!r}")
    if (current, target) not in MODE_SWITCHES:
        raise TransitionError(f"no mode switch {current.value!r} -> {target.value!r}")
    return target


TASK = "task"


def pairing(mode: TeleopMode, masters: Sequence[str], tool_robots: Sequence[str],
            camera_robot: str | None = None) -> dict[str, str]:
    """Master -> what it drives: a robot name, or :data:`TASK` (the MRCP kernel).

    Raises:
        ValueError: when the set-up lacks the masters or robots the mode needs.

    Example:
        >>> pairing(TeleopMode.MRCP_CAM, ["left", "right"], ["r1", "r2"], "cam")
        {'left': 'task', 'right': 'cam'}
    """
    if mode is TeleopMode.STDT:
        if len(masters) < 2 or len(tool_robots) < 2:
            raise ValueError(f"StdT needs 2 masters and 2 tool robots, got {list(masters)!r}, "
                             f"{list(tool_robots)!r}")
        return {masters[0]: tool_robots[0], masters[1]: tool_robots[1]}
    if not masters:
        raise ValueError("MRCP needs at least one master")
    out = {masters[0]: TASK}
    if mode is TeleopMode.MRCP_CAM:
        if len(masters) < 2 or camera_robot is None:
            raise ValueError(f"MRCP+Cam needs 2 masters and a camera robot, got "
                             f"{list(masters)!r}, camera {camera_robot!r}")
        out[masters[1]] = camera_robot
    return out


SUTURE_SUBTASK_MODE: dict[str, TeleopMode] = {
    "pre_suture": TeleopMode.STDT,
    "approximation": TeleopMode.MRCP,
    "insertion": TeleopMode.MRCP,
    "pass_through": TeleopMode.MRCP,
    "needle_transfer": TeleopMode.MRCP,
    "extraction": TeleopMode.MRCP,
    "tighten_thread": TeleopMode.MRCP,
    "needle_return": TeleopMode.MRCP,
    "knot_tying": TeleopMode.STDT,
}
