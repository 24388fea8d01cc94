"""RJ — the joint-limit index (spec/mrcp.md §4, seed eq. 3.12-3.20, Fig. 3.3).

Pure functions plus the :class:`JointLimitIndex` plug-in ("rj")::

    dist_i  = min(|θ_i - θmax_i|, |θ_i - θmin_i|) / (|θmax_i - θmin_i| / 2)   in [0, 1]
    Jeval_i = (1 - cos(π · dist_i^(1/b_i))) / 2,   b_i >= 1
    RJ      = min_i Jeval_i

``Jeval = 1/2`` exactly where ``dist = 0.5^b``: a larger ``b`` keeps the index high until
closer to the limit (a later alarm).

**Decision** (spec §4, velocity-modulated ``b``): the seed's text says ``b`` varies inversely
with the approach speed while its printed eq. 3.14 increases with it; the text is followed.
With ``v_i`` the speed toward the nearest limit (0 when moving away)
``b_i = bmax - (bmax - bmin) · min(1, v_i / θ̇max_i)`` — the faster the approach, the
earlier the alarm.

**Decision** (spec §4, predicted ranges): along the predicted trajectory the range of joint
``i`` at predicted point ``k`` is shrunk on *both* sides by the observed prediction error
``|e_k|``, ``e_k = θ_{i,0} - θ_{i-k,k}`` (what the prediction made ``k`` steps ago said for
now), ``[θmin + |e_k|, θmax - |e_k|]`` — conservative whatever the error's sign (the seed's
eq. 3.17 shifts it by the signed error). ``J̄eval_i = Σ_k w_k Jeval_{i,k} / Σ_k w_k`` with
``w_k = 1/(k+1)``; an unreachable predicted point contributes ``Jeval = 0``;
``RJ = min_i J̄eval_i``.

**Decision** (issue #17 §3, eq. 3.19's denominator): the seed prints
``Σ_k w_k Jeval_k / Σ_k Jeval_k``; vasim divides by ``Σ_k w_k`` because the printed ratio is
homogeneous of degree 0 in the Jeval values: a trajectory held at Jeval = 0.0002 (next to a
limit) and one at Jeval = 1 (mid-range) both score ``Σw/(K+1)`` (0.52 for K = 3), and at the
limit itself it is 0/0 — RJ would stop measuring the distance to a limit, contrary to the
text ("the weights balance the contribution of each Jeval_k") and to eq. 3.20 taking the
minimum over joints. With ``Σ w_k`` the value is a weighted mean of the points' Jeval in
[0, 1] and a still trajectory scores its single-pose RJ (eq. 3.15).
``tests/mrcp/test_kernel_rj_eq319.py`` shows both.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

from vasim.core.kernel_args import readonly_c, writable_c
from vasim.mrcp.indices._index_kernels import rj_along
from vasim.mrcp.indices.base import INDICES, EvalContext, prediction_weights

FloatArray = NDArray[np.float64]


def joint_distance(theta: FloatArray, lower: FloatArray, upper: FloatArray) -> FloatArray:
    """Normalised distance to the nearest limit: 1 at mid-range, 0 at (or beyond) a limit.

    An empty range (``upper <= lower``, e.g. after shrinking) gives 0.
    """
    th = np.asarray(theta, dtype=np.float64)
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    half = (hi - lo) / 2.0
    inside = (th > lo) & (th < hi) & (half > 0.0)
    d = np.minimum(np.abs(th - hi), np.abs(th - lo)) / np.where(half > 0.0, half, 1.0)
    return np.where(inside, np.clip(d, 0.0, 1.0), 0.0)


def jeval(dist: FloatArray, b: FloatArray | float) -> FloatArray:
    """``(1 - cos(π dist^(1/b))) / 2`` (seed eq. 3.12), ``b >= 1``.

    Example:
        >>> round(float(jeval(0.25, 2.0)), 12)
        0.5
    """
    bb = np.asarray(b, dtype=np.float64)
    if np.any(bb < 1.0):
        raise ValueError(f"jeval: modulation b must be >= 1, got {b!r}")
    d = np.clip(np.asarray(dist, dtype=np.float64), 0.0, 1.0)
    return (1.0 - np.cos(np.pi * d ** (1.0 / bb))) / 2.0


def modulation_b(theta: FloatArray, velocity: FloatArray, lower: FloatArray, upper: FloatArray,
                 max_velocity: FloatArray, b_min: float = 1.0, b_max: float = 6.0) -> FloatArray:
    """Velocity-modulated ``b`` per joint: ``bmax`` at rest or moving away, ``bmin`` when
    approaching the nearest limit at (or above) the joint's maximum speed."""
    th = np.asarray(theta, dtype=np.float64)
    v = np.asarray(velocity, dtype=np.float64)
    lo = np.asarray(lower, dtype=np.float64)
    hi = np.asarray(upper, dtype=np.float64)
    toward_upper = np.abs(th - hi) <= np.abs(th - lo)
    approach = np.clip(np.where(toward_upper, v, -v), 0.0, None)
    ratio = np.minimum(1.0, approach / np.asarray(max_velocity, dtype=np.float64))
    return b_max - (b_max - b_min) * ratio


def rj(theta: FloatArray, lower: FloatArray, upper: FloatArray,
       b: FloatArray | float = 1.0) -> float:
    """RJ at one configuration: ``min_i Jeval_i`` (seed eq. 3.15)."""
    return float(np.min(jeval(joint_distance(theta, lower, upper), b)))


def rj_trajectory(configs: FloatArray, reachable: NDArray[np.bool_], lower: FloatArray,
                  upper: FloatArray, b: FloatArray, errors: FloatArray) -> float:
    """RJ along a predicted trajectory (seed eq. 3.16-3.20 with the spec's decisions).

    Args:
        configs: ``(K+1, n)`` joint values at the trajectory points (``[0]`` = now).
        reachable: ``(K+1,)`` False where IK failed (those points give Jeval = 0).
        lower, upper: ``(n,)`` joint limits.
        b: ``(K+1, n)`` modulation per point and joint.
        errors: ``(K+1, n)`` observed prediction errors ``e_k`` (row 0 is zero).
    """
    e = np.abs(np.asarray(errors, dtype=np.float64))
    lo = np.asarray(lower)[None, :] + e
    hi = np.asarray(upper)[None, :] - e
    th = np.where(reachable[:, None], configs, 0.0)
    values = jeval(joint_distance(th, lo, hi), b)
    values = np.where(reachable[:, None], values, 0.0)
    w = prediction_weights(values.shape[0])
    per_joint = (w[:, None] * values).sum(axis=0) / w.sum()
    return float(per_joint.min())


def prediction_errors(configs: FloatArray, past_configs: list[FloatArray] | tuple[FloatArray, ...]
                      ) -> FloatArray:
    """``e_k = θ_now - θ_{i-k,k}`` for ``k = 0..K`` (zero where no earlier prediction exists).

    ``past_configs[j]`` is the ``(K+1, n)`` prediction made ``j + 1`` steps ago; its row
    ``j + 1`` was its prediction for now.
    """
    out = np.zeros_like(configs)
    now = configs[0]
    for k in range(1, min(configs.shape[0], len(past_configs) + 1)):
        err = now - past_configs[k - 1][k]
        if np.isfinite(err).all():
            out[k] = err
    return out


@INDICES.add("rj")
class JointLimitIndex:
    """RJ along the predicted trajectory, ``b`` modulated by the joint velocities.

    Args:
        b_min: ``b`` when approaching a limit at full speed (>= 1).
        b_max: ``b`` at rest (>= ``b_min``).
    """

    name = "rj"

    def __init__(self, b_min: float = 1.0, b_max: float = 6.0) -> None:
        if not 1.0 <= b_min <= b_max:
            raise ValueError(f"rj: need 1 <= b_min <= b_max, got b_min={b_min!r}, "
                             f"b_max={b_max!r}")
        self.b_min = float(b_min)
        self.b_max = float(b_max)

    def evaluate(self, ctx: EvalContext) -> float:
        """:func:`rj_trajectory` with :func:`modulation_b` and :func:`prediction_errors`
        (compiled in one call; the tests hold it to the numpy functions)."""
        if not ctx.reachable[0]:
            return 0.0
        arm = ctx.arm
        reach = writable_c(ctx.reachable, np.bool_)
        configs = np.ascontiguousarray(
            np.where(reach[:, None], ctx.configs, ctx.configs[0][None, :]), dtype=np.float64)
        errors = prediction_errors(configs, list(ctx.past_configs))
        return float(rj_along(configs, reach, writable_c(ctx.joint_velocity),
                              readonly_c(arm.joint_lower), readonly_c(arm.joint_upper),
                              readonly_c(arm.max_velocity), self.b_min, self.b_max, errors))
