"""From indices to time (spec/mrcp.md §§5-6, seed section 4.4.1-4.4.2, Algorithm 1).

Indices live in different spaces; MRCP compares them as time.

* ``texec``: a least-squares polynomial fitted to the last values of an index against time;
  its first future zero is when the robot stops being able to continue. No zero within the
  confidence window ``T_max`` -> ``T_max``. **Decision**: an index whose last observed value is
  ``<= 0`` gives 0; otherwise the earliest ``t`` in ``[0, T_max]`` where the fitted
  polynomial is ``<= 0`` (0 when the fit is already non-positive now, else its smallest
  real root in ``(0, T_max]``). ``texec_q = min`` over the indices.
* ``ttransf``: straight-line TCP motion to the task point at half the maximum TCP speed,
  inflated by the transfer complexity ``TTC = (1/n) Σ_j (1/K) Σ_k |θ̈_{j,k}| / θ̈max_j``
  (clipped to [0, 1]): ``ttransf* = ttransf (1 + TTC)``. **Decision**: the joint
  accelerations are second differences of the joint values at ``K`` evenly spaced samples of
  the line (the current configuration, IK solutions between, the grasp configuration),
  timed at that speed; a sample IK cannot reach makes ``TTC = 1``.
* ``tus = texec - ttransf*`` (``ttransf* = 0`` for RSel at CuTP).
* RCnt (Algorithm 1): the (robot, point) with the largest ``tus``, RSel at CuTP included.
* ``NTT = 1 - (tus_RSel - ttransf*_RCnt) / tus_RSel = ttransf*_RCnt / tus_RSel``; the
  transfer starts when ``NTT >= threshold`` (**decision**: default 0.9; ``tus_RSel <= 0``
  gives ``NTT = inf``: transfer now).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray

from vasim.core.geometry import vector_norm
from vasim.mrcp.interfaces import ArmKinematics

FloatArray = NDArray[np.float64]
Key = tuple[str, int]


def _first_nonpositive(coef: FloatArray, t_max: float) -> float:
    """Earliest ``t`` in ``[0, t_max]`` with ``P(t) <= 0`` (``coef`` increasing powers)."""
    c = np.trim_zeros(np.asarray(coef, dtype=np.float64), "b")
    if c.size == 0 or c[0] <= 0.0:
        return 0.0
    if c.size == 1:
        return float(t_max)
    roots = np.roots(c[::-1])
    real = roots[np.abs(roots.imag) <= 1e-9 * np.maximum(1.0, np.abs(roots.real))].real
    fut = real[(real > 0.0) & (real <= t_max)]
    return float(fut.min()) if fut.size else float(t_max)


def texec(times: FloatArray, values: FloatArray, t_max: float, degree: int = 2) -> float:
    """Time until the fitted index reaches 0 [s], in ``[0, t_max]``.

    Args:
        times: ``(n,)`` sample times [s]; the last one is *now*.
        values: ``(n,)`` index values.
        t_max: the confidence window [s].
        degree: polynomial degree (lowered to ``n - 1`` with few samples).

    Example:
        >>> import numpy as np
        >>> t = np.arange(5) * 0.1
        >>> round(texec(t, 1.0 - t, t_max=5.0, degree=1), 9)   # 0.6 left at slope -1
        0.6
    """
    t = np.asarray(times, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    if t.shape != y.shape or t.size == 0:
        raise ValueError(f"texec: times {t.shape} and values {y.shape} must be equal, non-empty")
    if t_max <= 0.0:
        raise ValueError(f"texec: t_max must be > 0, got {t_max!r}")
    if y[-1] <= 0.0:
        return 0.0
    if t.size == 1:
        return float(t_max)
    deg = min(degree, t.size - 1)
    coef = np.polynomial.polynomial.polyfit(t - t[-1], y, deg)
    return _first_nonpositive(coef, t_max)


def texec_many(times: FloatArray, values: FloatArray, t_max: float, degree: int = 2) -> FloatArray:
    """:func:`texec` for many series sharing the sample times.

    Args:
        times: ``(n,)`` sample times [s].
        values: ``(n, s)`` one column per series (no NaN).

    Returns:
        ``(s,)`` execution times [s].
    """
    t = np.asarray(times, dtype=np.float64)
    y = np.asarray(values, dtype=np.float64)
    out = np.full(y.shape[1], float(t_max))
    out[y[-1] <= 0.0] = 0.0
    if t.size == 1:
        return out
    deg = min(degree, t.size - 1)
    coefs = np.polynomial.polynomial.polyfit(t - t[-1], y, deg)         # (deg+1, s)
    live = y[-1] > 0.0
    if deg == 1:
        out[live] = _first_nonpositive_linear(coefs[:, live], t_max)
        return out
    for j in np.flatnonzero(live):
        out[j] = _first_nonpositive(coefs[:, j], t_max)
    return out


def _first_nonpositive_linear(coefs: FloatArray, t_max: float) -> FloatArray:
    """Vectorised :func:`_first_nonpositive` for straight lines ``(2, s)``."""
    c0, c1 = coefs
    out = np.full(c0.shape, float(t_max))
    out[c0 <= 0.0] = 0.0
    falling = (c0 > 0.0) & (c1 < 0.0)
    root = -c0[falling] / c1[falling]
    out[falling] = np.minimum(root, t_max)
    return out


def transfer_time(tcp: FloatArray, goal: FloatArray, max_tcp_speed: float) -> float:
    """Straight-line time at half the maximum TCP speed [s] (the seed's experiments)."""
    if max_tcp_speed <= 0.0:
        raise ValueError(f"transfer_time: max_tcp_speed must be > 0, got {max_tcp_speed!r}")
    return vector_norm(np.asarray(goal) - np.asarray(tcp)) / (0.5 * max_tcp_speed)


def transfer_complexity(joint_path: FloatArray | None, duration: float,
                        max_acceleration: FloatArray) -> float:
    """TTC ∈ [0, 1] from joint samples of the transfer (seed eq. 4.3).

    Args:
        joint_path: ``(K, n)`` joint values at evenly timed samples over ``duration``
            (None: a sample was unreachable -> 1).
        duration: the transfer time [s].
        max_acceleration: ``(n,)`` joint acceleration limits [rad/s²].
    """
    if joint_path is None:
        return 1.0
    path = np.asarray(joint_path, dtype=np.float64)
    if path.shape[0] < 3 or duration <= 0.0:
        return 0.0
    dt = duration / (path.shape[0] - 1)
    acc = np.abs(np.diff(path, n=2, axis=0)) / (dt * dt)
    ratio = acc / np.asarray(max_acceleration, dtype=np.float64)[None, :]
    return float(np.clip(ratio.mean(), 0.0, 1.0))


def transfer_path(arm: ArmKinematics, q: FloatArray, goal: FloatArray,
                  goal_rotation: FloatArray | None, samples: int,
                  q_goal: FloatArray | None = None) -> FloatArray | None:
    """Joint values at ``samples`` evenly spaced points of the straight TCP line from the
    current TCP to ``goal`` (``(samples, n)``), or None if one is unreachable.

    The first sample is ``q`` itself and the last ``q_goal`` when given (the kernel already
    solved it); the points between are IK solutions seeded along the line.
    """
    tcp, _ = arm.tcp_pose(q)
    out = np.empty((samples, q.shape[0]))
    out[0] = q
    seed = q
    for i, s in enumerate(np.linspace(0.0, 1.0, samples)[1:], start=1):
        last = i == samples - 1
        if last and q_goal is not None:
            out[i] = q_goal
            break
        p = tcp + s * (np.asarray(goal) - tcp)
        sol = arm.ik(p, goal_rotation if last else None, seed)
        if sol is None:
            return None
        out[i] = sol
        seed = sol
    return out


@dataclass(frozen=True)
class TransferEstimate:
    """``ttransf`` [s], ``TTC`` and ``ttransf* = ttransf (1 + TTC)`` of one (robot, point)."""

    ttransf: float
    ttc: float

    @property
    def total(self) -> float:
        return self.ttransf * (1.0 + self.ttc)


def estimate_transfer(arm: ArmKinematics, q: FloatArray, goal: FloatArray,
                      goal_rotation: FloatArray | None, max_tcp_speed: float,
                      samples: int = 4, q_goal: FloatArray | None = None) -> TransferEstimate:
    """ttransf and TTC of moving ``arm`` from ``q`` to the task point at ``goal``
    (``q_goal``: the configuration at the goal, if already known)."""
    tcp, _ = arm.tcp_pose(q)
    tt = transfer_time(tcp, goal, max_tcp_speed)
    path = transfer_path(arm, q, goal, goal_rotation, max(samples, 2), q_goal)
    return TransferEstimate(tt, transfer_complexity(path, tt, arm.max_acceleration))


@dataclass(frozen=True)
class Continuity:
    """Result of Algorithm 1 and the NTT decision of one cycle.

    Attributes:
        robot, point: RCnt and its task point (RSel and CuTP when nobody beats RSel).
        tus: the best useful time [s].
        ntt: Need of Task Transfer (0 when RCnt is RSel).
        transfer: True when a task transfer must start now (NTT >= threshold).
    """

    robot: str
    point: int
    tus: float
    ntt: float
    transfer: bool


def need_of_transfer(tus_rsel: float, ttransf_rcnt: float) -> float:
    """``NTT = 1 - (tus_RSel - ttransf*_RCnt) / tus_RSel`` (seed eq. 4.6); ``inf`` when
    RSel has no useful time left.

    Example:
        >>> need_of_transfer(2.0, 1.0)
        0.5
    """
    if tus_rsel <= 0.0:
        return float("inf")
    return 1.0 - (tus_rsel - ttransf_rcnt) / tus_rsel


def continuity_robot(tus: Mapping[Key, float], ttransf: Mapping[Key, float], rsel: str,
                     cutp: int, threshold: float = 0.9) -> Continuity:
    """Algorithm 1 + NTT: pick RCnt among RSel at CuTP and every candidate at its points.

    Args:
        tus: ``(robot, point) -> tus`` [s], containing ``(rsel, cutp)``; candidate entries
            with ``robot == rsel`` or ``point == cutp`` are ignored.
        ttransf: ``(robot, point) -> ttransf*`` [s] of the candidates.
        rsel, cutp: the robot holding the task and its point.
        threshold: start the transfer when ``NTT >= threshold``.

    Raises:
        KeyError: when ``(rsel, cutp)`` is missing from ``tus``.
    """
    own = float(tus[(rsel, cutp)])
    best_key, best = (rsel, cutp), own
    for key in sorted(tus):
        r, q = key
        if r == rsel or q == cutp:
            continue
        if tus[key] > best:
            best_key, best = key, float(tus[key])
    if best_key == (rsel, cutp):
        return Continuity(rsel, cutp, own, 0.0, False)
    ntt = need_of_transfer(own, float(ttransf[best_key]))
    return Continuity(best_key[0], best_key[1], best, ntt, ntt >= threshold)
