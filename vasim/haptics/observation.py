"""What the simulated or real person perceives at one control step (the hand's side of the
servo loop): the observation a device or operator model reads before each tick.

It lives in the haptics layer because devices and the servo loop hand it on; the scripted
operator (``vasim.operator.scripted``) is one of its readers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from vasim.fixtures.types import Vec3

_ONES3 = np.ones(3)
_ONES3.setflags(write=False)
_ZEROS3 = np.zeros(3)
_ZEROS3.setflags(write=False)


@dataclass(frozen=True, eq=False)
class OperatorObservation:
    """What the person perceives (and feels) at one control step.

    Attributes:
        t: time since trial start [s].
        dt: control step [s] (1e-3 at the haptic rate).
        tcp: (3,) slave tool tip as seen on screen [m], world frame.
        goal: (3,) current goal point [m], world frame.
        goal_index: index of the current goal in the task's POIs.
        force: (3,) force rendered on the hand [N] (FF, virtual walls); zeros if none.
        ms_factors: (3,) motion-scaling factors MS per axis (ones if none).
        guidance: True while the VG arrow is shown.
        audio_volume: AG cue volume in [0, 1] (0 = silent).
        audio_pitch_hz: AG pitch [Hz] (not used by the model; kept for logging).
        zoom: Mag zoom (1 = widest view / no Mag).
    """

    t: float
    dt: float
    tcp: Vec3
    goal: Vec3
    goal_index: int
    force: Vec3 = field(default_factory=lambda: _ZEROS3)
    ms_factors: Vec3 = field(default_factory=lambda: _ONES3)
    guidance: bool = False
    audio_volume: float = 0.0
    audio_pitch_hz: float = 0.0
    zoom: float = 1.0
