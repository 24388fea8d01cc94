r"""An emulated Phantom Omni / Geomagic Touch: a stylus mass held by a hand, pushed by forces.

The emulator stands in for the hardware in tests, demos and benchmarks: the servo loop
cannot tell it from a device, and it behaves like one where it matters for force rendering
(inertia, a compliant hand, force limits, position quantisation, a mechanical range). It is
deterministic: the same hand motion and the same forces give the same readings.

Model (per axis of the device frame, x the stylus tip [m], v its velocity [m/s]):

    m dv/dt = F_out + k_h (h - x) + b_h (dh/dt - v)

* m = ``stylus_mass_kg`` (45 g: the Omni's apparent mass at the tip is of that order);
* h(t) = the hand target [m] (a constant, or a function of time), k_h = ``hand_stiffness``,
  b_h = ``hand_damping``: the endpoint impedance of the hand holding the stylus (a relaxed
  arm's endpoint stiffness is a few hundred N/m, Mussa-Ivaldi, Hogan & Bizzi 1985). With
  no hand (``hand=None``) the stylus is free: k_h = 0, b_h = ``free_damping`` (bearing and
  cable friction, viscous);
* F_out = the force the motors render (below).

Integration: the equation is linear with a zero-order-hold input over each period ``dt``
(the force and the hand target are held), so it is discretised *exactly*,
[x, v](t + dt) = Phi [x, v](t) + Gamma u with u = F_out + k_h h + b_h dh/dt, Phi and Gamma
from the matrix exponential of the augmented system (Van Loan 1978). Time advances by one
``dt`` per ``read()`` (the first read returns the initial state at t = 0): the emulated
device runs on simulated time, at the pace the servo loop reads it.

Mechanical range: the stylus stops (inelastically: position clamped, outward velocity
zeroed) at the usable workspace box grown by ``end_stop_margin_m`` on each side.

Readings are quantised to the position resolution q: x_read = q round(x / q) (the Omni's
encoders: ~0.055 mm).

Force limits, as hardware enforces them (``write_force``):

1. peak: the commanded force is scaled down to norm ``max_force_n`` (direction kept);
2. continuous (thermal model, **decision**): the motors' heat is modelled by the
   exponentially weighted mean of the squared output, H_(k+1) = rho H_k + (1 - rho)
   |F_out,k|^2, rho = exp(-dt / tau), tau = ``continuous_window_s`` (the averaging window
   that defines "continuous"). The output is limited so that H never exceeds F_c^2
   (F_c = ``max_continuous_force_n``): |F_out,k| <= sqrt((F_c^2 - rho H_k) / (1 - rho)).
   From cold, the peak force is available for t* = -tau ln(1 - (F_c / F)^2) (0.74 s at
   3.3 N with tau = 10 s); a sustained demand above F_c then settles at exactly F_c, and
   anything below F_c is never limited. The direction is always kept.

Example:
    >>> import numpy as np
    >>> dev = EmulatorDevice(hand=np.zeros(3))
    >>> dev.start()
    >>> dev.read().position.tolist()
    [0.0, 0.0, 0.0]
    >>> dev.write_force(np.array([0.0, 0.0, 9.0]))      # above the 3.3 N peak
    >>> dev.applied_force.tolist()
    [0.0, 0.0, 3.3]
    >>> for _ in range(500):
    ...     s = dev.read(); dev.write_force(np.array([0.0, 0.0, 1.5]))
    >>> round(float(s.position[2]), 4)                  # 1.5 N against a 300 N/m hand
    0.005
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike
from scipy.linalg import expm

from vasim.core.config import check_number
from vasim.core.errors import DeviceError
from vasim.haptics.device import (
    OMNI_LIMITS,
    DeviceLimits,
    DeviceSample,
    FloatArray,
    as_force,
)

HandInput = ArrayLike | Callable[[float], ArrayLike] | None
"""A hand target: None (hand off), a fixed (3,) point [m], or a function t [s] -> (3,)."""


@dataclass(frozen=True)
class EmulatorParams:
    """Mechanics of the emulated stylus and hand (module docstring for the model).

    Attributes:
        stylus_mass_kg: m, apparent mass at the stylus tip [kg] (> 0).
        hand_stiffness: k_h, hand endpoint stiffness [N/m] (>= 0).
        hand_damping: b_h, hand endpoint damping [N s/m] (>= 0).
        free_damping: viscous friction of the free stylus (no hand) [N s/m] (>= 0).
        end_stop_margin_m: mechanical range beyond the usable workspace box [m] (>= 0).
        dt: the emulated period [s] (one per ``read``), > 0.
    """

    stylus_mass_kg: float = 0.045
    hand_stiffness: float = 300.0
    hand_damping: float = 5.0
    free_damping: float = 0.05
    end_stop_margin_m: float = 0.005
    dt: float = 1e-3

    def __post_init__(self) -> None:
        for name in ("stylus_mass_kg", "dt"):
            check_number(getattr(self, name), f"emulator.{name}", gt=0)
        for name in ("hand_stiffness", "hand_damping", "free_damping", "end_stop_margin_m"):
            check_number(getattr(self, name), f"emulator.{name}", ge=0)


def zoh_matrices(mass: float, stiffness: float, damping: float,
                 dt: float) -> tuple[FloatArray, FloatArray]:
    """Exact zero-order-hold discretisation of m x'' = u - k x - b x'.

    Returns:
        (Phi (2, 2), Gamma (2,)) with [x, v](t + dt) = Phi [x, v](t) + Gamma u.

    >>> phi, gam = zoh_matrices(1.0, 0.0, 0.0, 0.1)        # a free unit mass
    >>> phi.round(12).tolist(), gam.round(12).tolist()
    ([[1.0, 0.1], [0.0, 1.0]], [0.005, 0.1])
    """
    a = np.zeros((3, 3))
    a[0, 1] = 1.0
    a[1, 0] = -stiffness / mass
    a[1, 1] = -damping / mass
    a[1, 2] = 1.0 / mass
    e = expm(a * dt)
    return e[:2, :2].copy(), e[:2, 2].copy()


def thermal_limit(heat: float, rho: float, continuous_n: float) -> float:
    """Largest |F_out| [N] allowed now by the thermal model (module docstring, step 2).

    Args:
        heat: H, the weighted mean of |F_out|^2 so far [N^2].
        rho: exp(-dt / tau), in (0, 1).
        continuous_n: F_c [N].

    >>> round(thermal_limit(0.88 ** 2, math.exp(-1e-4), 0.88), 12)   # hot: exactly F_c
    0.88
    >>> round(thermal_limit(0.0, math.exp(-1e-4), 0.88), 1)          # cold: 100 F_c
    88.0
    """
    room = continuous_n * continuous_n - rho * heat
    return math.sqrt(room / (1.0 - rho)) if room > 0.0 else 0.0


class EmulatorDevice:
    """An emulated Omni (see the module docstring for the model and its limits).

    Args:
        limits: device limits (default: the Omni's).
        params: stylus and hand mechanics.
        hand: hand target: None (hand off), a fixed (3,) point [m] or a function t -> (3,).
        buttons: a bitmask, or a function t [s] -> bitmask.
        start_position: (3,) initial stylus position [m]; default: the hand target at t = 0,
            or the workspace centre without a hand.
        name: device name.
    """

    def __init__(self, limits: DeviceLimits = OMNI_LIMITS, params: EmulatorParams | None = None,
                 *, hand: HandInput = None, buttons: int | Callable[[float], int] = 0,
                 start_position: ArrayLike | None = None, name: str = "emulator"):
        self.name = name
        self._limits = limits
        self.params = params if params is not None else EmulatorParams()
        p = self.params
        self._rho = math.exp(-p.dt / limits.continuous_window_s)
        self._stop_lo = tuple(v - p.end_stop_margin_m for v in limits.workspace_min)
        self._stop_hi = tuple(v + p.end_stop_margin_m for v in limits.workspace_max)
        self._buttons = buttons
        self.set_hand(hand)
        if start_position is not None:
            x0 = np.array(start_position, dtype=np.float64).reshape(3)
        elif self._hand is not None:
            x0 = np.array(self._hand_at(0.0))
        else:
            x0 = 0.5 * (np.asarray(limits.workspace_min) + np.asarray(limits.workspace_max))
            x0 = np.where(np.isfinite(x0), x0, 0.0)
        self._x0 = x0
        self._started = False
        self.reset()

    # -- configuration -------------------------------------------------------------------
    @property
    def limits(self) -> DeviceLimits:
        return self._limits

    def set_hand(self, hand: HandInput) -> None:
        """Changes the hand target (None lets go of the stylus)."""
        p = self.params
        self._h_const: tuple[float, ...] | None = None
        if hand is None:
            self._hand: Callable[[float], ArrayLike] | None = None
            k, b = 0.0, p.free_damping
        else:
            if callable(hand):
                self._hand = hand
            else:
                target = np.array(hand, dtype=np.float64).reshape(3)
                self._h_const = tuple(target.tolist())
                self._hand = lambda t: target
            k, b = p.hand_stiffness, p.hand_damping
        self._k, self._b = k, b
        phi, gam = zoh_matrices(p.stylus_mass_kg, k, b, p.dt)
        self._phi = tuple(phi.reshape(4).tolist())
        self._gam = tuple(gam.tolist())

    def set_buttons(self, buttons: int | Callable[[float], int]) -> None:
        """Changes the pressed buttons (a bitmask or a function of time)."""
        self._buttons = buttons

    def set_state(self, position: ArrayLike, velocity: ArrayLike = (0.0, 0.0, 0.0)) -> None:
        """Puts the stylus at ``position`` [m] with ``velocity`` [m/s] (tests, demos)."""
        self._x = np.asarray(position, dtype=np.float64).reshape(3).tolist()
        self._v = np.asarray(velocity, dtype=np.float64).reshape(3).tolist()

    def reset(self) -> None:
        """Back to t = 0: stylus at rest at the start position, motors cold."""
        self._t = 0.0
        self._k_read = 0
        self.set_state(self._x0)
        self._f_out: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._f_cmd: tuple[float, float, float] = (0.0, 0.0, 0.0)
        self._heat = 0.0

    # -- Device protocol -----------------------------------------------------------------
    def start(self) -> None:
        self._started = True

    def stop(self) -> None:
        self._f_out = (0.0, 0.0, 0.0)
        self._started = False

    def read(self) -> DeviceSample:
        """Advances one period (except on the first read) and returns the reading."""
        if not self._started:
            raise DeviceError(f"{self.name}: read() before start()")
        if self._k_read > 0:
            self._advance()
        self._k_read += 1
        q = self._limits.position_resolution_m
        x = self._x
        if q > 0:
            pos = np.array((round(x[0] / q) * q, round(x[1] / q) * q, round(x[2] / q) * q))
        else:
            pos = np.array(x)
        b = self._buttons
        buttons = int(b(self._t)) if callable(b) else int(b)
        return DeviceSample(t=self._t, position=pos, buttons=buttons)

    def write_force(self, force: FloatArray) -> None:
        """Renders ``force`` (3,) [N] from now on, after the peak and thermal limits."""
        f0, f1, f2 = as_force(force).tolist()
        if not (math.isfinite(f0) and math.isfinite(f1) and math.isfinite(f2)):
            raise DeviceError(f"{self.name}: non-finite force {[f0, f1, f2]!r}")
        self._f_cmd = (f0, f1, f2)
        lim = self._limits
        n = math.sqrt(f0 * f0 + f1 * f1 + f2 * f2)
        cap = min(lim.max_force_n,
                  thermal_limit(self._heat, self._rho, lim.max_continuous_force_n))
        if n > cap:
            s = cap / n
            f0, f1, f2 = f0 * s, f1 * s, f2 * s
        self._f_out = (f0, f1, f2)

    # -- state, for tests and energy bookkeeping ------------------------------------------
    @property
    def t(self) -> float:
        """Emulated time of the last reading [s]."""
        return self._t

    @property
    def position(self) -> FloatArray:
        """(3,) true (unquantised) stylus position [m]."""
        return np.array(self._x)

    @property
    def velocity(self) -> FloatArray:
        """(3,) stylus velocity [m/s]."""
        return np.array(self._v)

    @property
    def applied_force(self) -> FloatArray:
        """(3,) force the motors render now [N] (after the limits)."""
        return np.array(self._f_out)

    @property
    def commanded_force(self) -> FloatArray:
        """(3,) force last written [N] (before the limits)."""
        return np.array(self._f_cmd)

    @property
    def heat(self) -> float:
        """H, the thermal model's weighted mean of |F_out|^2 [N^2] (<= F_c^2)."""
        return self._heat

    def hand_target(self) -> FloatArray | None:
        """(3,) hand target now [m], None when the hand is off."""
        return None if self._hand is None else np.array(self._hand_at(self._t))

    def mechanical_energy(self) -> float:
        """Kinetic energy of the stylus + elastic energy of the hand spring [J]."""
        x, v = self._x, self._v
        e = 0.5 * self.params.stylus_mass_kg * (v[0] * v[0] + v[1] * v[1] + v[2] * v[2])
        if self._hand is not None:
            h = self._hand_at(self._t)
            d0, d1, d2 = x[0] - h[0], x[1] - h[1], x[2] - h[2]
            e += 0.5 * self._k * (d0 * d0 + d1 * d1 + d2 * d2)
        return e

    # -- internals -----------------------------------------------------------------------
    def _hand_at(self, t: float) -> tuple[float, ...]:
        if self._h_const is not None:
            return self._h_const
        assert self._hand is not None
        return tuple(np.asarray(self._hand(t), dtype=np.float64).reshape(3).tolist())

    def _advance(self) -> None:
        """[x, v] <- Phi [x, v] + Gamma u per axis (exact ZOH), end stops, heat."""
        dt = self.params.dt
        u0, u1, u2 = self._f_out
        if self._hand is not None:
            k, b = self._k, self._b
            h0 = self._hand_at(self._t)
            if self._h_const is not None:
                u0, u1, u2 = u0 + k * h0[0], u1 + k * h0[1], u2 + k * h0[2]
            else:
                h1 = self._hand_at(self._t + dt)
                u0 += k * h0[0] + b * (h1[0] - h0[0]) / dt
                u1 += k * h0[1] + b * (h1[1] - h0[1]) / dt
                u2 += k * h0[2] + b * (h1[2] - h0[2]) / dt
        p00, p01, p10, p11 = self._phi
        g0, g1 = self._gam
        x, v = self._x, self._v
        lo, hi = self._stop_lo, self._stop_hi
        for a, u in ((0, u0), (1, u1), (2, u2)):
            xa, va = x[a], v[a]
            xn = p00 * xa + p01 * va + g0 * u
            vn = p10 * xa + p11 * va + g1 * u
            if xn < lo[a]:
                xn = lo[a]
                vn = vn if vn > 0.0 else 0.0
            elif xn > hi[a]:
                xn = hi[a]
                vn = vn if vn < 0.0 else 0.0
            x[a], v[a] = xn, vn
        f = self._f_out
        rho = self._rho
        self._heat = rho * self._heat + (1.0 - rho) * (f[0] * f[0] + f[1] * f[1] + f[2] * f[2])
        self._t = self._k_read * dt


__all__ = ["EmulatorDevice", "EmulatorParams", "HandInput", "thermal_limit", "zoh_matrices"]
