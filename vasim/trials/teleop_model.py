"""The teleoperation trial's data: the frozen model (what the trial is) apart from its
state (what a control cycle changes), as in the VF engine (``vasim.trials.vf_model``).

* :class:`TeleopTrialModel` -- frozen: the config, the mode, the needle task, the cycle, the
  time limit, the person's profile, the mode penalties and the hands' adjustment.
* :class:`TeleopTrialState` -- the needle, its holder, the ring and route progress, the
  counters, the master's and needle's paths, the physics snapshot, the samples and events.
* :class:`MrcpLoop`, :class:`StdtLoop` -- what each mode's operator carries from cycle to
  cycle (its hand, the kernel or the StdT phase), read and changed by the mode's phases.

The station, the camera hand, the abdomen and the deformation accumulator are the trial's
world objects (``vasim.trials.teleop.TeleopTrial``): built once, stepped by the phases.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from vasim.operator.needle import RING_RADIUS, RING_SITES, NeedleTask, Side, needle_task
from vasim.operator.profile import OperatorProfile
from vasim.operator.teleop_profile import (
    NEUTRAL,
    TeleopAdjustment,
    TeleopEffects,
    teleop_adjustment,
)
from vasim.records.samples import SampleBuffer
from vasim.trials.config_fields import preset_profile
from vasim.trials.teleop_config import TeleopTrialConfig

if TYPE_CHECKING:
    from vasim.abdomen.snapshot import AbdomenSnapshot
    from vasim.mrcp.kernel import MRCPKernel
    from vasim.operator.port import MasterHand

CYCLE_DT = 0.018
"""Control cycle of the station [s] (the seed's robot controllers: 55.6 Hz)."""

EM_PARTS = ("to_ring", "to_via", "transfer")
"""What moved the needle, for the split of EM (``em_<part>`` trial metrics, [m]): carrying
it to a ring, carrying it to a via point, and changing hands (MRCP: the kernel's transfer,
the master decoupled; StdT: approach, grasp and release, where only a misaligned grasp
moves it)."""

COUNTS = ("transfers", "regrasps", "misaligned_transfers", "transfer_aborts", "tool_holds",
          "rsel_holds", "safety_stops")
"""The trial's event counters (``TeleopTrialState.counts``; summary columns)."""


@dataclass(frozen=True, eq=False)
class TeleopTrialModel:
    """What a teleoperation trial is (never changes while it runs).

    Attributes:
        config: the trial's configuration. mode: its mode. task: the needle task.
        dt: the control cycle [s]. profile: the person (the config's, else the skill's
        preset). effects: the person's mode penalties. adjustment: the hands' profiles of
        this mode and mode practice (``vasim.operator.teleop_profile``).
    """

    config: TeleopTrialConfig
    mode: str
    task: NeedleTask
    dt: float
    profile: OperatorProfile
    effects: TeleopEffects
    adjustment: TeleopAdjustment

    @classmethod
    def build(cls, config: TeleopTrialConfig, n_rings: int | None = None,
              effects: TeleopEffects | None = None) -> TeleopTrialModel:
        """The model of ``config`` (``TeleopTrial``'s arguments: ``n_rings``, default all
        of ``RING_SITES``, pass radius ``config.reach_radius`` else ``RING_RADIUS``;
        ``effects``, default ``config.mode_effects`` else ``NEUTRAL``)."""
        radius = config.reach_radius if config.reach_radius is not None else RING_RADIUS
        task = needle_task(len(RING_SITES) if n_rings is None else n_rings,
                           ring_radius=radius)
        profile = preset_profile(config.profile, config.skill)
        if effects is None:
            effects = config.mode_effects if config.mode_effects is not None else NEUTRAL
        adjustment = teleop_adjustment(
            config.mode, config.practice if config.mode_practice is None
            else config.mode_practice, profile, effects)
        return cls(config=config, mode=config.mode, task=task, dt=CYCLE_DT, profile=profile,
                   effects=effects, adjustment=adjustment)


@dataclass(slots=True, eq=False)
class TeleopTrialState:
    """What a control cycle changes.

    Attributes:
        rings: (n, 3) the rings where they are now [m]. needle: (3,) the needle centre [m].
        holder: the instrument holding it. i: rings passed. k: cycle index (-1 before the
        first). t: time [s]. reach_times: when each ring was passed [s]. counts: the event
        counters (``COUNTS``). master_path: the masters' path [m]. tt_time: time in
        transfer [s]. done: the trial has ended. clutch: 1 while the master is decoupled.
        via: the next waypoint is the via point before ring i. route_j: waypoints reached.
        em_parts: the needle's path by what moved it (``EM_PARTS``) [m]. em_from: the
        needle where the last cycle left it. transferring: the needle changes hands this
        cycle. route_log: (ring or -1 for a via point, time, waypoint, needle) per
        waypoint reached. snap: the latest physics snapshot. samples, events: the record.
    """

    rings: np.ndarray
    needle: np.ndarray
    samples: SampleBuffer
    snap: AbdomenSnapshot | None = None
    holder: Side = "right"
    i: int = 0
    k: int = -1
    t: float = 0.0
    reach_times: list[float] = field(default_factory=list)
    counts: dict[str, int] = field(default_factory=lambda: dict.fromkeys(COUNTS, 0))
    master_path: float = 0.0
    tt_time: float = 0.0
    done: bool = False
    clutch: int = 0
    via: bool = False
    route_j: int = 0
    em_parts: dict[str, float] = field(default_factory=lambda: dict.fromkeys(EM_PARTS, 0.0))
    em_from: np.ndarray = field(default_factory=lambda: np.zeros(3))
    transferring: bool = False
    route_log: list[tuple[int, float, np.ndarray, np.ndarray]] = field(default_factory=list)
    events: list[tuple[float, str, str]] = field(default_factory=list)

    @classmethod
    def initial(cls, model: TeleopTrialModel,
                snap: AbdomenSnapshot | None) -> TeleopTrialState:
        """The state before the first cycle (``snap``: the abdomen's, None without one)."""
        task = model.task
        needle = task.start.copy()
        return cls(rings=task.rings.copy() if snap is None else np.array(snap.targets),
                   needle=needle, snap=snap, em_from=needle.copy(),
                   samples=SampleBuffer(capacity=int(model.config.max_time / model.dt) + 2,
                                        active_fixtures=""))


@dataclass(slots=True, eq=False)
class MrcpLoop:
    """What the ``mrcp`` modes' operator carries from cycle to cycle.

    Attributes:
        kernel: the MRCP kernel moving the robots. master: the master's position [m].
        hand: the current path's hand. key: the path's number (its seed's key).
        ack: time left until the operator acknowledges a safety stop [s].
        holding: the kernel held RSel last cycle (one event per run of held cycles).
    """

    kernel: MRCPKernel
    master: np.ndarray
    hand: MasterHand
    key: int = 0
    ack: float = 0.0
    holding: bool = False


@dataclass(slots=True, eq=False)
class StdtLoop:
    """What the ``stdt`` operator carries from cycle to cycle.

    Attributes:
        hand: the current path's hand. offset: needle centre - holder tip [m].
        sigma: the jaw placement error's standard deviation [m]. delay: a gripper action's
        duration [s]. key: the path's number (its seed's key). phase: ``"carry"``,
        ``"handover"``, ``"approach"``, ``"close"`` or ``"release"``. other: the free
        instrument. wait: time left of the gripper action [s]. attempts: grasps tried.
    """

    hand: MasterHand
    offset: np.ndarray
    sigma: float
    delay: float
    key: int = 0
    phase: str = "carry"
    other: Side = "left"
    wait: float = 0.0
    attempts: int = 0


__all__ = ["COUNTS", "CYCLE_DT", "EM_PARTS", "MrcpLoop", "StdtLoop", "TeleopTrialModel",
           "TeleopTrialState"]
