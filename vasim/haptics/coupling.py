r"""Virtual coupling: a spring-damper between the device and the simulated tool (pure).

The device (master) position x_d does not drive the simulated tool directly. A *proxy* of
mass m (the tool tip as the simulation sees it) is tied to x_d by a spring-damper and
pushed by the tissue; the device renders the coupling force (as iMSTK and SOFA do). The
tissue solver is slow, so between its updates the tissue force at the proxy is:

* extrapolated from the last update, F(x) = F0 + K (x - x0), with K = dF/dx [N/m] the
  force derivative the physics sends along (OpenSurgSim's coupler does this): a
  :class:`LinearForce`; or
* re-evaluated against the frozen contact planes with
  :func:`vasim.abdomen.contact.patch_force` when a :class:`PatchForce` (a ``ContactPatch``
  and the trocar fulcrum) is given — the exact unilateral law between physics updates.

Equations (vectors in the device frame; x_p, v_p the proxy, x_d, v_d the device):

    F_dev = -ks (x_d - x_p) - kd (v_d - v_p)                   force on the device (hand)
    m dv_p/dt = -F_dev + F_tissue(x_p)                         proxy

kd defaults to critical damping of the proxy on the coupling spring, kd = 2 sqrt(m ks).
The proxy is integrated with *implicit* (backward) Euler, linearising the tissue force at
the current proxy position (the K above, negative semi-definite for a contact):

    (m/dt + kd + dt ks - dt K) v_p' = m/dt v_p + ks (x_d - x_p) + kd v_d + F(x_p)
    x_p' = x_p + dt v_p'

unconditionally stable for any ks, kd >= 0 and K <= 0 (the proxy can never be what makes
the loop oscillate). The rendered force is ``force_scale * F_dev`` (evaluated with the new
proxy state), saturated to the device's peak force with its direction kept
(:func:`saturate`).

The device velocity v_d is estimated from quantised positions: a backward difference,
low-passed (first order, cutoff ``velocity_cutoff_hz``, :func:`lowpass_velocity`). Raw
1 kHz differences of positions quantised at q turn one encoder count into q / dt (55 mm/s
for the Omni) and make the damping term buzz.

Example:
    >>> import numpy as np
    >>> p = CouplingParams(stiffness=500.0, proxy_mass=0.02)
    >>> round(p.kd, 6)                                     # 2 sqrt(0.02 * 500)
    6.324555
    >>> coupling_force(np.array([0.0, 0, 0.002]), np.zeros(3), np.zeros(3), np.zeros(3),
    ...                500.0, 0.0).tolist()
    [-0.0, -0.0, -1.0]
    >>> f, sat = saturate(np.array([3.0, 4.0, 0.0]), 2.5)  # direction kept
    >>> f.tolist(), sat
    ([1.5, 2.0, 0.0], True)
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike, NDArray

from vasim.abdomen.contact import ContactPatch, ToolPose, patch_force
from vasim.core.config import check_number

FloatArray = NDArray[np.float64]


def critical_damping(mass: float, stiffness: float) -> float:
    """kd = 2 sqrt(m ks) [N s/m]: critical damping of mass m [kg] on a spring ks [N/m].

    >>> critical_damping(0.05, 800.0)
    12.649110640673518
    """
    if not (mass > 0 and stiffness >= 0):
        raise ValueError(f"need mass > 0 and stiffness >= 0, got {mass!r}, {stiffness!r}")
    return 2.0 * math.sqrt(mass * stiffness)


@dataclass(frozen=True)
class CouplingParams:
    """Parameters of the virtual coupling (module docstring for the equations).

    Attributes:
        stiffness: ks [N/m] (> 0). The default 800 N/m is below the Omni's nominal maximum
            stiffness (~1 N/mm along z, the data sheet's weakest axis).
        proxy_mass: m [kg] (> 0).
        damping: kd [N s/m] (>= 0); None means critical, 2 sqrt(m ks).
        force_scale: factor from the coupling force to the rendered force (> 0).
        velocity_cutoff_hz: cutoff of the device-velocity low-pass [Hz] (> 0).

    Raises:
        ConfigError: for a value out of range (field and value in the message).
    """

    stiffness: float = 800.0
    proxy_mass: float = 0.01
    damping: float | None = None
    force_scale: float = 1.0
    velocity_cutoff_hz: float = 30.0

    def __post_init__(self) -> None:
        for name in ("stiffness", "proxy_mass", "force_scale", "velocity_cutoff_hz"):
            check_number(getattr(self, name), f"coupling.{name}", gt=0)
        if self.damping is not None:
            check_number(self.damping, "coupling.damping", ge=0)

    @property
    def kd(self) -> float:
        """The damping in use [N s/m] (critical when ``damping`` is None)."""
        if self.damping is None:
            return critical_damping(self.proxy_mass, self.stiffness)
        return float(self.damping)


def coupling_force(x_dev: FloatArray, v_dev: FloatArray, x_proxy: FloatArray,
                   v_proxy: FloatArray, ks: float, kd: float) -> FloatArray:
    """F_dev = -ks (x_d - x_p) - kd (v_d - v_p): the coupling force on the device [N].

    Args:
        x_dev, v_dev: (3,) device position [m] and velocity [m/s].
        x_proxy, v_proxy: (3,) proxy position [m] and velocity [m/s].
        ks: stiffness [N/m]. kd: damping [N s/m].
    """
    return -ks * (np.asarray(x_dev) - x_proxy) - kd * (np.asarray(v_dev) - v_proxy)


def saturate(force: ArrayLike, max_n: float) -> tuple[FloatArray, bool]:
    """Scales ``force`` (3,) [N] down to norm ``max_n`` if longer, keeping its direction.

    A non-finite force becomes zero (and counts as saturated).

    Returns:
        (the force, whether it was scaled).
    """
    f = np.asarray(force, dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        n = float(np.sqrt(f @ f))
    if not math.isfinite(n):
        n = float(math.hypot(*f.tolist()))
        if not math.isfinite(n):
            return np.zeros(3), True
    if n <= max_n:
        return f.copy(), False
    return f * (max_n / n), True


def extrapolate_force(f0: FloatArray, k: FloatArray, x0: FloatArray,
                      x: FloatArray) -> FloatArray:
    """F(x) = F0 + K (x - x0): the tissue force extrapolated from the last physics update.

    Args:
        f0: (3,) force at x0 [N]. k: (3, 3) dF/dx at x0 [N/m]. x0: (3,) position of the
            update [m]. x: (3,) current position [m].

    >>> extrapolate_force(np.array([0, 0, 1.0]), -200.0 * np.eye(3), np.zeros(3),
    ...                   np.array([0, 0, 0.001])).tolist()
    [0.0, 0.0, 0.8]
    """
    return np.asarray(f0, dtype=np.float64) + np.asarray(k) @ (np.asarray(x) - x0)


@dataclass(frozen=True, eq=False)
class LinearForce:
    """A tissue force linearised at the last physics update: F(x) = f0 + k (x - x0).

    Attributes:
        f0: (3,) force [N]. k: (3, 3) dF/dx [N/m]. x0: (3,) where it was evaluated [m].
    """

    f0: FloatArray
    k: FloatArray
    x0: FloatArray

    def __post_init__(self) -> None:
        # float copies for the 1 kHz path (``force_xyz``)
        object.__setattr__(self, "_f0", tuple(np.asarray(self.f0, dtype=np.float64)
                                              .reshape(3).tolist()))
        object.__setattr__(self, "_k", tuple(np.asarray(self.k, dtype=np.float64)
                                             .reshape(9).tolist()))
        object.__setattr__(self, "_x0", tuple(np.asarray(self.x0, dtype=np.float64)
                                              .reshape(3).tolist()))

    def force_xyz(self, x: Sequence[float]) -> tuple[float, float, float]:
        """F(x) on floats (same arithmetic as ``extrapolate_force``)."""
        f, k, x0 = self._f0, self._k, self._x0  # type: ignore[attr-defined]  # slots set in __post_init__
        d0, d1, d2 = x[0] - x0[0], x[1] - x0[1], x[2] - x0[2]
        return (f[0] + (k[0] * d0 + k[1] * d1 + k[2] * d2),
                f[1] + (k[3] * d0 + k[4] * d1 + k[5] * d2),
                f[2] + (k[6] * d0 + k[7] * d1 + k[8] * d2))


@dataclass(frozen=True, eq=False)
class PatchForce:
    """The frozen contact planes of the last physics update and the trocar fulcrum [m]."""

    patch: ContactPatch
    fulcrum: FloatArray = field(default_factory=lambda: np.array([0.0, 0.0, 0.1]))


TissueModel = LinearForce | PatchForce | None
"""What the physics publishes for the haptic loop (None: free space)."""


def tissue_force(model: TissueModel, x: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The tissue force on the tool tip at ``x`` (3,) [m] and its derivative.

    Returns:
        (F (3,) [N], dF/dx (3, 3) [N/m]): extrapolated for a ``LinearForce`` (its K is the
        derivative), re-evaluated with ``patch_force`` for a ``PatchForce``, zero for None.
    """
    if model is None:
        return np.zeros(3), np.zeros((3, 3))
    if isinstance(model, LinearForce):
        return extrapolate_force(model.f0, model.k, model.x0, x), np.asarray(model.k)
    return patch_force(model.patch, ToolPose(fulcrum=model.fulcrum, tip=np.asarray(x)))


@dataclass(frozen=True, eq=False)
class ProxyState:
    """The simulated tool tip tied to the device: position x [m], velocity v [m/s]."""

    x: FloatArray
    v: FloatArray = field(default_factory=lambda: np.zeros(3))


def proxy_step(state: ProxyState, x_dev: FloatArray, v_dev: FloatArray, tissue: TissueModel,
               params: CouplingParams, dt: float) -> tuple[ProxyState, FloatArray]:
    """One implicit-Euler step of the proxy and the force it sends to the device.

    Args:
        state: the proxy now.
        x_dev, v_dev: (3,) device position [m] and (filtered) velocity [m/s].
        tissue: the tissue force model (None: free space).
        params: coupling parameters.
        dt: step [s] (> 0).

    Returns:
        (new proxy state, ``force_scale * F_dev`` (3,) [N], not yet saturated).
    """
    x, v, f = proxy_step_xyz(state.x.tolist(), state.v.tolist(), np.asarray(x_dev).tolist(),
                             np.asarray(v_dev).tolist(), tissue, params, dt)
    return ProxyState(np.array(x), np.array(v)), np.array(f)


def _tissue_xyz(tissue: TissueModel, x: Sequence[float]
                ) -> tuple[tuple[float, float, float], Sequence[float] | None]:
    """(F (3 floats), K (9 floats, row-major) or None when zero) at x."""
    if tissue is None:
        return (0.0, 0.0, 0.0), None
    if isinstance(tissue, LinearForce):
        k = tissue._k  # type: ignore[attr-defined]  # slot set in __post_init__
        return tissue.force_xyz(x), (k if any(k) else None)
    f, k = patch_force(tissue.patch, ToolPose(fulcrum=tissue.fulcrum, tip=np.array(x)))
    kl = k.reshape(9).tolist()
    f0, f1, f2 = f.tolist()
    return (f0, f1, f2), (kl if any(kl) else None)


def proxy_step_xyz(x: Sequence[float], v: Sequence[float], xd: Sequence[float],
                   vd: Sequence[float], tissue: TissueModel, params: CouplingParams,
                   dt: float) -> tuple[tuple[float, float, float], tuple[float, float, float],
                                       tuple[float, float, float]]:
    """``proxy_step`` on floats (the servo loop's path; same equations).

    Args:
        x, v: proxy position [m] and velocity [m/s] (3 floats each).
        xd, vd: device position [m] and filtered velocity [m/s] (3 floats each).
        tissue, params, dt: as ``proxy_step``.

    Returns:
        (new x, new v, ``force_scale * F_dev``), 3 floats each. The 3 x 3 system
        (a I - dt K) v' = rhs is solved by the adjugate (A is symmetric positive definite
        for K <= 0: its determinant is > 0).
    """
    ks, kd, m = params.stiffness, params.kd, params.proxy_mass
    (f0, f1, f2), k = _tissue_xyz(tissue, x)
    md = m / dt
    r0 = md * v[0] + ks * (xd[0] - x[0]) + kd * vd[0] + f0
    r1 = md * v[1] + ks * (xd[1] - x[1]) + kd * vd[1] + f1
    r2 = md * v[2] + ks * (xd[2] - x[2]) + kd * vd[2] + f2
    a = md + kd + dt * ks
    if k is None:
        w0, w1, w2 = r0 / a, r1 / a, r2 / a
    else:
        a00, a01, a02 = a - dt * k[0], -dt * k[1], -dt * k[2]
        a10, a11, a12 = -dt * k[3], a - dt * k[4], -dt * k[5]
        a20, a21, a22 = -dt * k[6], -dt * k[7], a - dt * k[8]
        c00 = a11 * a22 - a12 * a21
        c01 = a12 * a20 - a10 * a22
        c02 = a10 * a21 - a11 * a20
        det = a00 * c00 + a01 * c01 + a02 * c02
        w0 = (c00 * r0 + (a02 * a21 - a01 * a22) * r1 + (a01 * a12 - a02 * a11) * r2) / det
        w1 = (c01 * r0 + (a00 * a22 - a02 * a20) * r1 + (a02 * a10 - a00 * a12) * r2) / det
        w2 = (c02 * r0 + (a01 * a20 - a00 * a21) * r1 + (a00 * a11 - a01 * a10) * r2) / det
    y0, y1, y2 = x[0] + dt * w0, x[1] + dt * w1, x[2] + dt * w2
    s = params.force_scale
    return ((y0, y1, y2), (w0, w1, w2),
            (s * (-ks * (xd[0] - y0) - kd * (vd[0] - w0)),
             s * (-ks * (xd[1] - y1) - kd * (vd[1] - w1)),
             s * (-ks * (xd[2] - y2) - kd * (vd[2] - w2))))


def velocity_alpha(cutoff_hz: float, dt: float) -> float:
    """Gain a = 1 - exp(-2 pi f_c dt) of the first-order velocity low-pass.

    >>> round(velocity_alpha(30.0, 1e-3), 6)
    0.171796
    """
    return 1.0 - math.exp(-2.0 * math.pi * cutoff_hz * dt)


def lowpass_velocity(v_prev: FloatArray, x: FloatArray, x_prev: FloatArray, dt: float,
                     alpha: float) -> FloatArray:
    """v <- v + a ((x - x_prev) / dt - v): the filtered backward difference [m/s]."""
    return v_prev + alpha * ((x - x_prev) / dt - v_prev)


def coupling_energy(x_dev: FloatArray, state: ProxyState, params: CouplingParams) -> float:
    """Energy stored in the coupling spring plus the proxy's kinetic energy [J]."""
    d = np.asarray(x_dev) - state.x
    return 0.5 * params.stiffness * float(d @ d) + 0.5 * params.proxy_mass * float(
        state.v @ state.v)


__all__ = [
    "CouplingParams",
    "LinearForce",
    "PatchForce",
    "ProxyState",
    "TissueModel",
    "coupling_energy",
    "coupling_force",
    "critical_damping",
    "extrapolate_force",
    "lowpass_velocity",
    "proxy_step",
    "proxy_step_xyz",
    "saturate",
    "tissue_force",
    "velocity_alpha",
]
