"""The port an instrument enters the abdomen through (the tool's fulcrum), per task.

Moved out of ``vasim.trials.vf`` (which re-exports it) to keep that module under the size
limit; the trial runner, the viewer and the real-time trial use it.
"""

from __future__ import annotations

import numpy as np

from vasim.abdomen.anatomy import trocar_points


def tool_trocar(task: str, start: np.ndarray) -> np.ndarray:
    """(3,) the port the instrument enters through: the tool's fulcrum [m].

    Trajectory following: the working port on the side the trajectory starts (the
    patient's right port for x < 0). Point targeting: the instrument port whose shaft
    points least toward the camera (Mag's view direction), so the shaft does not hide the
    POI in the magnified view.
    """
    from vasim.abdomen.anatomy import TROCAR_NAMES
    from vasim.fixtures.mag import MagParams

    ports = trocar_points()
    if task == "trajectory":
        side = "working_right" if float(start[0]) < 0 else "working_left"
        return ports[TROCAR_NAMES.index(side)]
    w = np.asarray(MagParams().view_dir, dtype=np.float64)
    best, score = ports[TROCAR_NAMES.index("working_right")], np.inf
    for name, port in zip(TROCAR_NAMES, ports, strict=True):
        if name == "camera":
            continue
        d = port - np.asarray(start, dtype=np.float64)
        s = float(d @ w) / float(np.linalg.norm(d) * np.linalg.norm(w))
        if s < score:
            best, score = port, s
    return best


__all__ = ["tool_trocar"]
