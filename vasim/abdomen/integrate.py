"""The implicit integrator of the mass-spring organs: backward Euler, solved by Newton–PCG.

**decision** (spec §1, "a stable implicit integrator"; chosen by measurement, numbers below):
each step is a backward-Euler step written as a minimisation (the variational form of
Liu et al. 2013 / Gast et al. 2015),

    x_{n+1} = argmin_x  g(x) = sum_i m_i/(2 dt²)|x_i - y_i|² + c/(2 dt)|x_i - z_i|² + E(x),
    y = x_n + dt v_n + dt² (gravity + f_ext / m),   z = x_n + dt v_frame,
    v_{n+1} = (x_{n+1} - x_n) / dt,

over the free nodes (anchors are eliminated: they sit at their targets, so moving anchors only
change the right-hand side). ``E`` is the spring energy, ``c`` the node damping toward the
moving frame (its implicit treatment can only dissipate). The minimiser is found by Newton's
method from the inertial prediction ``y``: each Newton system ``H d = -grad g`` (``H`` with
compressed springs' negative transverse stiffness clamped to 0, so it is SPD) is solved by a
matrix-free preconditioned conjugate gradient (numba, ``nogil``), and a backtracking line
search on ``g`` accepts the step, so every accepted iterate lowers ``g``: a step cut short by
the iteration budget is still an improvement on the prediction (stability does not depend on
convergence). Every stopping test is relative to the step itself (``tol``, ``cg_tol``), so a
truncated solve delays the approach to equilibrium but leaves no permanent offset (see
``vasim.abdomen._kernels.implicit_step``).

The preconditioner (``"auto"``, the default) is

* the constant diagonal ``m/dt² + c/dt + sum_s k_s`` (the diagonal of the stiffness bound
  ``M/dt² + L_k`` that Liu's method prefactors) when the step is near diagonal dominance
  (:func:`stiffness_ratio` <= :data:`AUTO_FACTOR_RATIO`) or the body is a membrane; else
* for a solid organ (volume springs), Liu's prefactored matrix ``M/dt² + c/dt + L_k``
  (LDLᵀ by SuperLU with a minimum-degree ordering, once per solver; bending springs left out of
  it, which cuts the fill from 71 to 29 entries per row on the 1,962-node ellipsoid at the
  same iteration count), applied by two gathering triangular solves per CG iteration.

Measured (``python -m bench abdomen``; 2-core shared host, medians; the guide's closed
ellipsoids, 5 anchors): on the 1,962-node membrane at k = 100 N/m, dt = 1 ms the diagonal
needs 3.2 CG iterations per step and the factor 3.3 at 2.8x the cost; at k = 1,000 N/m,
dt = 4 ms 97 vs 81 iterations, the factor 3.4x slower (a wrinkling membrane's hard modes are
transverse, which neither preconditioner captures). For the solid organs of the default
abdomen (stiffness ratio 60–1,700 at dt = 4 ms) the factor wins: under the same real-time
budget its positions stay within 0.2–0.3 mm of a converged solve where the diagonal's drift
by 2.8 mm (the whole-organ sag modes, which the diagonal resolves only over many iterations),
at the same cost per step. Liu's local/global iterations with that factor converge like
preconditioned gradient descent; CG on the Newton system needs fewer of the same solves
(prototype on 492 / 1,962 nodes: error after 10 solves 2–10x lower), so Liu + Chebyshev was
not pursued. A 3x3 block-Jacobi preconditioner of ``H`` was slower than the constant diagonal
(prototype: 2.7x the time on 1,962 nodes at k = 1,000 N/m, dt = 4 ms).

Accuracy: backward Euler damps an oscillator of frequency ω by ``(1 + ω²dt²)^(-1/2)`` per step
and stretches its period by ``ω dt / atan(ω dt)`` (1 % at ω dt = 0.17); the tests check the
period of a spring-mass at ω dt = 0.01 (error 3e-5 from the scheme) and the exact static
deflection of a hanging chain (the equilibrium of the step is the static equilibrium, at any
dt). At large ``dt`` with stiff springs a real-time iteration budget truncates the solve:
stable, but the stiff modes respond late (as in every published real-time solver; the
massspring guide).

Example:
    >>> import numpy as np, trimesh
    >>> from vasim.abdomen.model import AnchorRule, OrganParams, build_organ
    >>> mesh = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    >>> params = OrganParams(stiffness=200.0, mass=0.2, volume=False,
    ...                      anchors=(AnchorRule(to="point", point=(0, 0, 0.03), within=0.01),))
    >>> model = build_organ(mesh, params, name="ball")
    >>> solver = OrganSolver(model, dt=0.004)
    >>> state = solver.initial_state()
    >>> targets = model.rest[model.anchors]
    >>> reports = [solver.step(state, targets) for _ in range(250)]
    >>> all(r.ok for r in reports), round(state.t, 3)
    (True, 1.0)
    >>> bool(np.all(np.isfinite(state.x))) and bool(state.x[:, 2].min() < -0.03)  # it sags
    True
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from vasim.abdomen import _kernels
from vasim.abdomen.model import (
    SPRING_BENDING,
    SPRING_VOLUME,
    FloatArray,
    OrganModel,
    OrganState,
)
from vasim.core.kernel_args import writable_c

Preconditioner = Literal["auto", "diagonal", "factor"]
_PRECONDITIONERS = ("auto", "diagonal", "factor")
AUTO_FACTOR_RATIO = 16.0
"""``"auto"`` factors a solid organ (one with volume springs) when some node's spring stiffness
exceeds this many times its inertia term ``m/dt² + c/dt`` (the diagonal preconditioner's CG
then needs many iterations and leaves the smooth, whole-organ modes unresolved) ..."""
AUTO_FACTOR_MAX_NODES = 10_000
"""... and the organ has at most this many free nodes (the factor's fill, hence its solve
time, grows faster than the node count)."""


@dataclass(frozen=True)
class SolverOptions:
    """Options of :class:`OrganSolver`.

    Attributes:
        tol: relative tolerance of the step (update / predicted displacement), in (0, 1).
        atol: absolute floor of the step's tolerance [m], >= 0 (round-off level; the
            criteria are relative, see ``vasim.abdomen._kernels.implicit_step``).
        cg_tol: relative residual of each conjugate-gradient solve, in (0, 1).
        max_newton: Newton iterations per step at most, >= 1.
        max_iterations: conjugate-gradient iterations (Hessian products) per step at most,
            >= 1: the time budget of a step.
        preconditioner: ``"diagonal"``, ``"factor"`` or ``"auto"`` (module docstring,
            :func:`stiffness_ratio`).
        max_displacement: a node farther than this from its rest position [m] means the
            state blew up (reset, as for a non-finite state).
        max_speed: a node faster than this [m/s] (any coordinate) means the same.
    """

    tol: float = 1e-2
    atol: float = 1e-9
    cg_tol: float = 1e-2
    max_newton: int = 4
    max_iterations: int = 100
    preconditioner: Preconditioner = "auto"
    max_displacement: float = 1.0
    max_speed: float = 50.0

    def __post_init__(self) -> None:
        for name in ("tol", "cg_tol"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and 0.0 < v < 1.0):
                raise ValueError(f"{name} must be in (0, 1), got {v!r}")
        for name in ("max_newton", "max_iterations"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {v!r}")
        if not (isinstance(self.atol, int | float) and self.atol >= 0.0):
            raise ValueError(f"atol must be >= 0 [m], got {self.atol!r}")
        if self.preconditioner not in _PRECONDITIONERS:
            raise ValueError(f"preconditioner must be one of {_PRECONDITIONERS}, got "
                             f"{self.preconditioner!r}")
        for name in ("max_displacement", "max_speed"):
            v = getattr(self, name)
            if not (isinstance(v, int | float) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")


@dataclass(frozen=True)
class StepReport:
    """What one :meth:`OrganSolver.step` did.

    Attributes:
        ok: the step ran and its result is finite and bounded.
        reset: the organ was reset to rest (moved with its anchors) because the state was not
            finite or blew up; ``reason`` says why (the caller logs the event).
        reason: ``None`` when ok.
        newton_iterations: Newton iterations used.
        iterations: conjugate-gradient iterations used (Hessian products).
        converged: the step met its tolerance within the budget.
        t: simulated time after the step [s].
    """

    ok: bool
    reset: bool
    reason: str | None
    newton_iterations: int
    iterations: int
    converged: bool
    t: float


def spring_forces(model: OrganModel, x: FloatArray) -> FloatArray:
    """Spring forces on every node at positions ``x``.

    Args:
        model: the organ.
        x: (n, 3) positions [m].

    Returns:
        (n, 3) forces [N]; they sum to zero (action = reaction).
    """
    out = np.zeros((model.n_nodes, 3))
    _kernels.spring_forces(np.array(x, dtype=np.float64), np.array(model.springs[:, 0]),
                           np.array(model.springs[:, 1]), np.array(model.stiffness),
                           np.array(model.rest_length), out)
    return out


@dataclass(frozen=True)
class Energy:
    """Mechanical energy of an organ state [J] (gravity's zero at ``z = 0`` of the frame)."""

    kinetic: float
    elastic: float
    gravity: float

    @property
    def total(self) -> float:
        return self.kinetic + self.elastic + self.gravity


def energy(model: OrganModel, state: OrganState) -> Energy:
    """Kinetic, spring and gravitational energy of ``state``.

    Args:
        model: the organ.
        state: positions [m] and velocities [m/s].
    """
    x = np.array(state.x, dtype=np.float64)
    kin = 0.5 * float(np.sum(model.mass[:, None] * state.v**2))
    ela = float(_kernels.spring_energy(x, np.array(model.springs[:, 0]),
                                       np.array(model.springs[:, 1]), np.array(model.stiffness),
                                       np.array(model.rest_length)))
    grav = -float(np.sum(model.mass * (x @ model.gravity)))
    return Energy(kin, ela, grav)


def stiffness_ratio(model: OrganModel, dt: float) -> float:
    """Largest ratio, over the free nodes, of the summed spring stiffness to the inertia and
    damping term ``m/dt² + c/dt``: how far the step is from diagonally dominant.

    Args:
        model: the organ.
        dt: time step [s].
    """
    n = model.n_nodes
    ksum = (np.bincount(model.springs[:, 0], model.stiffness, n)
            + np.bincount(model.springs[:, 1], model.stiffness, n))
    inertia = model.mass / dt**2 + model.damping / dt
    free = model.free
    return float(np.max(ksum[free] / inertia[free])) if free.any() else 0.0


def reset_positions(model: OrganModel, anchor_targets: FloatArray) -> FloatArray:
    """Rest shape moved with the anchors: anchors at their targets, every other node displaced
    by the inverse-square-distance weighted mean of the anchors' displacements.

    Args:
        model: the organ.
        anchor_targets: (a, 3) anchor positions [m].

    Returns:
        (n, 3) positions [m].
    """
    x = np.array(model.rest, dtype=np.float64)
    if len(model.anchors) == 0:
        return x
    targets = np.asarray(anchor_targets, dtype=np.float64).reshape(-1, 3)
    disp = targets - model.rest[model.anchors]
    d2 = np.sum((model.rest[:, None, :] - model.rest[None, model.anchors, :]) ** 2, axis=2)
    w = 1.0 / (d2 + 1e-8)
    x += (w @ disp) / w.sum(axis=1, keepdims=True)
    x[model.anchors] = targets
    return x


class OrganSolver:
    """Steps one organ with a fixed ``dt`` (stateful shell around the kernel and its buffers).

    One solver per organ; :meth:`step` is not re-entrant (it owns scratch buffers), but two
    solvers can step in two threads at once: the kernel releases the interpreter lock.

    Args:
        model: the organ.
        dt: time step [s], > 0.
        **solver_options: fields of :class:`SolverOptions`.
    """

    def __init__(self, model: OrganModel, dt: float, **solver_options: object) -> None:
        if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0.0):
            raise ValueError(f"dt must be a finite number > 0 [s], got {dt!r}")
        self.model = model
        self.dt = float(dt)
        self.options = SolverOptions(**solver_options)  # type: ignore[arg-type]  # SolverOptions checks the keys
        n = model.n_nodes
        # Writable contiguous copies: one compiled signature of the kernel for every model
        # (the model's own arrays are read-only, a different numba type).
        self._si = np.array(model.springs[:, 0], dtype=np.int64)
        self._sj = np.array(model.springs[:, 1], dtype=np.int64)
        self._k = np.array(model.stiffness, dtype=np.float64)
        self._r = np.array(model.rest_length, dtype=np.float64)
        self._mass = np.array(model.mass, dtype=np.float64)
        self._gravity = np.array(model.gravity, dtype=np.float64)
        self._anchors = np.array(model.anchors, dtype=np.int64)
        self._rest = np.array(model.rest, dtype=np.float64)
        self._free = model.free.astype(np.uint8)
        # diagonal of the stiffness bound M/dt^2 + c/dt + L_k (the preconditioner)
        diag = self._mass / self.dt**2 + model.damping / self.dt
        diag = diag + np.bincount(self._si, self._k, n) + np.bincount(self._sj, self._k, n)
        self._pdiag = 1.0 / diag
        self._kind = 0
        empty_i = np.zeros(1, dtype=np.int64)
        self._lp, self._li, self._lx = empty_i, np.zeros(0, dtype=np.int64), np.zeros(0)
        self._up, self._ui, self._ux = empty_i, np.zeros(0, dtype=np.int64), np.zeros(0)
        self._dinv, self._perm = np.zeros(0), np.zeros(0, dtype=np.int64)
        pre = self.options.preconditioner
        if pre == "auto":
            solid = bool(np.any(model.spring_type == SPRING_VOLUME))
            pre = ("factor" if solid and stiffness_ratio(model, self.dt) > AUTO_FACTOR_RATIO
                   and 0 < int(self._free.sum()) <= AUTO_FACTOR_MAX_NODES else "diagonal")
        self.preconditioner: Preconditioner = pre
        """The preconditioner in use (``"auto"`` resolved)."""
        if pre == "factor" and self._free.any():
            self._kind = 1
            self._factor(diag)
        self._work = np.zeros((10, n, 3))
        self._scal = np.zeros((2, n))
        self._coef = np.zeros((len(self._k), 4))
        self._buf = np.zeros((max(1, len(self._perm)), 3))
        self._stats = np.zeros(7)
        self._zero = np.zeros((n, 3))
        self._target_shape = (len(model.anchors), 3)

    def _factor(self, diag: FloatArray) -> None:
        """LDLᵀ of ``M/dt² + c/dt + L_k`` on the free nodes (SuperLU, symmetric mode),
        ``L_k`` without the bending springs."""
        n = self.model.n_nodes
        free = np.flatnonzero(self._free)
        # Bending springs (second neighbours, 10 % of the stiffness) are left out of the
        # factored matrix: they double the graph's degree and the factor's fill (29 instead
        # of 71 entries per row on the 1,962-node ellipsoid) for the same CG iteration count.
        keep = self.model.spring_type != SPRING_BENDING
        kk, si, sj = self._k[keep], self._si[keep], self._sj[keep]
        dropped = self._k[~keep]
        diag = (diag - np.bincount(self._si[~keep], dropped, n)
                - np.bincount(self._sj[~keep], dropped, n))
        off = np.r_[-kk, -kk]
        rows = np.r_[si, sj]
        cols = np.r_[sj, si]
        a = sp.coo_matrix((off, (rows, cols)), shape=(n, n)).tocsr() + sp.diags(diag)
        a = a.tocsc()[free][:, free].tocsc()
        lu = spla.splu(a, permc_spec="MMD_AT_PLUS_A", diag_pivot_thresh=0.0,
                       options={"SymmetricMode": True})
        if not np.array_equal(lu.perm_r, lu.perm_c):
            raise RuntimeError("SuperLU pivoted off the diagonal: the matrix is not SPD")
        low = lu.L.tocsc()
        low.setdiag(0.0)
        low.eliminate_zeros()
        low.sort_indices()
        self._lp = low.indptr.astype(np.int64)
        self._li = low.indices.astype(np.int64)
        self._lx = low.data.astype(np.float64)
        rows = low.tocsr()
        rows.sort_indices()
        self._up = rows.indptr.astype(np.int64)
        self._ui = rows.indices.astype(np.int64)
        self._ux = rows.data.astype(np.float64)
        self._dinv = 1.0 / lu.U.diagonal()
        # SuperLU: Pr A Pc = L U with A[perm_r[i], ...] -> row i; factor row q is free node
        # argsort(perm_c)[q].
        self._perm = free[np.argsort(lu.perm_c)].astype(np.int64)

    @property
    def last_spring_passes(self) -> int:
        """Passes over all springs in the last step (gradient and energy evaluations plus
        Hessian products): ``springs x passes / time`` is the kernel's throughput."""
        return int(self._stats[6])

    def initial_state(self) -> OrganState:
        """The rest shape at rest, at t = 0."""
        return OrganState(np.array(self.model.rest, dtype=np.float64),
                          np.zeros((self.model.n_nodes, 3)), 0.0)

    def reset(self, state: OrganState, anchor_targets: FloatArray) -> None:
        """Puts ``state`` back to the rest shape moved with its anchors, at rest (in place)."""
        state.x[...] = reset_positions(self.model, anchor_targets)
        state.v[...] = 0.0

    def step(
        self,
        state: OrganState,
        anchor_targets: FloatArray,
        f_ext: FloatArray | None = None,
        *,
        v_frame: FloatArray | None = None,
    ) -> StepReport:
        """Advances ``state`` by ``dt`` in place.

        Args:
            state: positions (n, 3) [m] and velocities [m/s] at t; they become those at t + dt.
            anchor_targets: (a, 3) positions of the anchors at t + dt [m] (moving anchors:
                breathing, heartbeat).
            f_ext: (n, 3) external forces [N] during the step (the tool contact), or None.
            v_frame: (n, 3) velocity [m/s] of the moving frame at each node (the damping pulls
                toward it; see ``vasim.abdomen.motion.point_velocities``), or None (at rest).

        Returns:
            The report. A non-finite or blown-up state (before or after the step) is reset to
            rest moved with the anchors (:meth:`reset`) and reported with the reason.
        """
        model = self.model
        n = model.n_nodes
        targets = writable_c(anchor_targets)   # one kernel type (vasim.core.kernel_args)
        if targets.shape != self._target_shape:
            raise ValueError(f"anchor_targets must have shape {self._target_shape}, got "
                             f"{np.shape(anchor_targets)}")
        f = self._zero if f_ext is None else np.ascontiguousarray(f_ext, dtype=np.float64)
        vf = self._zero if v_frame is None else np.ascontiguousarray(v_frame, dtype=np.float64)
        if f.shape != (n, 3) or vf.shape != (n, 3):
            raise ValueError(f"f_ext and v_frame must have shape ({n}, 3), got {f.shape} and "
                             f"{vf.shape}")
        t_new = state.t + self.dt
        if not (state.x.flags.c_contiguous and state.x.dtype == np.float64
                and state.v.flags.c_contiguous and state.v.dtype == np.float64):
            state.x = np.ascontiguousarray(state.x, dtype=np.float64)
            state.v = np.ascontiguousarray(state.v, dtype=np.float64)
        o = self.options
        status = _kernels.implicit_step(
            state.x, state.v, self._rest, self._anchors, targets, self._free, f, vf, self._mass,
            model.damping, self._gravity, self.dt, self._si, self._sj, self._k, self._r,
            self._kind, self._pdiag, self._lp, self._li, self._lx, self._up, self._ui, self._ux,
            self._dinv, self._perm,
            o.tol, o.atol, o.cg_tol, o.max_newton, o.max_iterations, self._work, self._scal,
            self._coef, self._buf, self._stats,
        )  # fmt: skip
        if status == _kernels.STATUS_BAD_TARGETS:
            raise ValueError("anchor_targets must be finite")
        state.t = t_new
        stats = self._stats
        newton, iters, conv = int(stats[0]), int(stats[1]), bool(stats[2])
        if status == _kernels.STATUS_BAD_INPUT:
            what = ("state" if not (np.all(np.isfinite(state.x)) and np.all(np.isfinite(state.v)))
                    else "external force or frame velocity")
            return self._reset_report(state, targets, t_new, f"non-finite {what} before the step")
        if status != _kernels.STATUS_OK:
            return self._reset_report(state, targets, t_new, "non-finite state after the step",
                                      newton, iters)
        if stats[4] > o.max_displacement:
            return self._reset_report(
                state, targets, t_new,
                f"blow-up: a node moved {stats[4]:.3g} m from rest (> {o.max_displacement:g} m)",
                newton, iters)
        if stats[5] > o.max_speed:
            return self._reset_report(
                state, targets, t_new,
                f"blow-up: a node moves at {stats[5]:.3g} m/s (> {o.max_speed:g} m/s)",
                newton, iters)
        return StepReport(True, False, None, newton, iters, conv, t_new)

    def _reset_report(self, state: OrganState, targets: FloatArray, t: float, reason: str,
                      newton: int = 0, iters: int = 0) -> StepReport:
        self.reset(state, targets)
        state.t = t
        return StepReport(False, True, f"{self.model.name}: {reason}; reset to rest", newton,
                          iters, False, t)


__all__ = [
    "AUTO_FACTOR_MAX_NODES",
    "AUTO_FACTOR_RATIO",
    "Energy",
    "OrganSolver",
    "Preconditioner",
    "SolverOptions",
    "StepReport",
    "energy",
    "reset_positions",
    "spring_forces",
    "stiffness_ratio",
]
