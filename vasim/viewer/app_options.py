"""What a :class:`vasim.viewer.app.ViewerApp` runs, grouped (issue #29: a parameter list
of 22 became three frozen groups plus the host, port, scene, store and trial factory).

* :class:`TrialOptions`: the first demo trial and what every trial shares (limits, pause,
  start cue, optics).
* :class:`ViewerPace`: how fast the trials run and the threads and pages update.
* :class:`PageAccess`: the two pages' tokens and the experimenter page's port.

The defaults are those the flat parameter list had; the values are checked by
``ViewerApp`` (and ``TrainingController``) with ``core.config``'s helpers, before a socket
is opened.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

from vasim.viewer.flow import SCENE_HZ

TaskName = Literal["trajectory", "point"]
SkillName = Literal["novice", "intermediate", "expert"]


@dataclass(frozen=True)
class TrialOptions:
    """The viewer's trials.

    Attributes:
        schema: fixture schema of the demo trials (a name in ``protocols/schemas``).
        seed: operator seed of the first trial (incremented per trial).
        task: ``"trajectory"`` or ``"point"``.
        skill: scripted operator preset.
        variant: trajectory variant of the first trial.
        max_time: simulated time limit per demo/free trial [s].
        pause_s: wall time a finished trial is shown before the next one starts [s].
        countdown_s: the start cue before a person-driven trial [s] (0: none).
        optics: the trainee's endoscope optics [deg], 0 or 30 (a scene option; stored with
            every person-driven trial).
    """

    schema: str = "trajectory_following"
    seed: int = 0
    task: TaskName = "trajectory"
    skill: SkillName = "intermediate"
    variant: int = 0
    max_time: float = 180.0
    pause_s: float = 1.5
    countdown_s: float = 3.0
    optics: float = 0.0


@dataclass(frozen=True)
class ViewerPace:
    """How fast the viewer's trials run and its threads and pages update.

    Attributes:
        speed: simulated seconds per wall second (1 = real time).
        control_hz, view_hz: rates of the controller and view threads [Hz].
        audio_hz: rate of the AG parameter stream [Hz].
        scene_hz: rate of what the trainee does not steer (organs, the task's points) on a
            page that keeps up [Hz]; slower pages get it less often (``flow.ScenePacer``).
            None: with every frame (as before issue #26.2; ``bench/viewer.py`` compares).
    """

    speed: float = 1.0
    control_hz: float = 50.0
    view_hz: float = 40.0
    audio_hz: float = 20.0
    scene_hz: float | None = SCENE_HZ


@dataclass(frozen=True)
class PageAccess:
    """Who may open the viewer's two pages, and where the experimenter's is served.

    Attributes:
        token: the trainee page's access token (required beyond loopback; ``--expose``).
        experimenter_token: the experimenter page's token; must differ from ``token``;
            None with a ``token``: a fresh one is drawn (read ``experimenter_url``).
        experimenter_port: the experimenter page's TCP port; None: the trainee's port + 1
            (0 when the trainee's is 0).
    """

    token: str | None = None
    experimenter_token: str | None = None
    experimenter_port: int | None = None
