"""Force–torque index (spec/mrcp.md §4, seed eq. 3.30-3.31).

``FTeval = min((Fmax - |F|)/Fmax, (τmax - |τ|)/τmax)`` clamped to [0, 1], with the load the
sensor of the holding robot measures. A candidate is evaluated as if it held the task at
its own task point: the same load expressed at that point, ``τ_q = τ + (p_s - p_q) x F``
(**decision**: rigid object, static load; this is what makes the grasp point near the
centre of mass preferable, seed Fig. 3.17). No sensor reading -> 1.
"""

from __future__ import annotations

import numpy as np

from vasim.mrcp.indices.base import INDICES, EvalContext


def ft_eval(force: np.ndarray, torque: np.ndarray, f_max: float, tau_max: float) -> float:
    """``min((Fmax - |F|)/Fmax, (τmax - |τ|)/τmax)`` clamped to [0, 1].

    Example:
        >>> import numpy as np
        >>> ft_eval(np.array([5.0, 0, 0]), np.array([0, 1.0, 0]), 10.0, 4.0)
        0.5
    """
    f = float(np.linalg.norm(force))
    tau = float(np.linalg.norm(torque))
    return float(np.clip(min((f_max - f) / f_max, (tau_max - tau) / tau_max), 0.0, 1.0))


@INDICES.add("force_torque")
class ForceTorqueIndex:
    """Force-torque margin at the evaluated task point.

    Args:
        f_max: maximum admissible force [N].
        tau_max: maximum admissible torque [N m].
    """

    name = "force_torque"

    def __init__(self, f_max: float = 50.0, tau_max: float = 5.0) -> None:
        if f_max <= 0.0 or tau_max <= 0.0:
            raise ValueError(f"force_torque: f_max and tau_max must be > 0, got {f_max!r}, "
                             f"{tau_max!r}")
        self.f_max = float(f_max)
        self.tau_max = float(tau_max)

    def evaluate(self, ctx: EvalContext) -> float:
        if not ctx.reachable[0]:
            return 0.0
        if ctx.wrench is None:
            return 1.0
        w = ctx.wrench.moved_to(ctx.positions[0])
        return ft_eval(w.force, w.torque, self.f_max, self.tau_max)
