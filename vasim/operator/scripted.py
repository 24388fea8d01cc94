r"""A scripted operator: a model of a person moving the master so the tool tip follows a task.

The operator drives tests, demos and simulated cohorts (spec/abdomen.md §3). It works in
*master* space (it returns the hand increment dX_M of each 1 kHz control step) and perceives
the *slave* tool tip on the screen, with a visual reaction delay. Everything random comes
from one ``numpy.random.Generator`` seeded by ``seed``: same profile, task, seed and inputs
give the same increments (``reset`` restarts the generator).

Notation: t [s] time, dt [s] control step, x [m] slave TCP (world frame), h [m] hand/master
position, g [m] current goal, p_j [m] the task's POIs, s = skill in [0, 1], P = practice (number
of earlier trials), alpha = learning rate. Vectors are per axis (x, y, z of the world frame,
which the master's axes are aligned with).

1. Learning and skill factors (dimensionless)::

       lambda_P = f + (1 - f) (1 + P) ** -alpha          power law of practice, with
                                                         asymptote f (profile.asymptote)
       kappa_T  = 1 + 1.5 (1 - s)                        movement-time factor of skill
       kappa_N  = 1 + 1.0 (1 - s)                        noise factor of skill
       kappa_K  = 0.5 + 0.5 s                            feedback-gain factor of skill

   Movement time and every *learnable* error source (motor noise, gain noise, perceptual
   noise) are multiplied by lambda_P (Newell & Rosenbloom 1981, "Mechanisms of skill
   acquisition and the law of practice": time per trial falls as a power of the number of
   trials). Physiological tremor and the reaction delay do not learn.

2. Planning: minimum-jerk submovements (Flash & Hogan 1985, "The coordination of arm
   movements"). A submovement toward target p (in task space) over duration T is the
   quintic q(t) minimising integral |d^3 q/dt^3|^2 with boundary conditions
   q(0) = q0, dq/dt(0) = v0, d^2q/dt^2(0) = a0, q(T) = p, dq/dt(T) = d^2q/dt^2(T) = 0::

       q(t) = sum_k c_k t^k,  c0 = q0, c1 = v0, c2 = a0/2,
       c3 = (20 D - 12 v0 T - 3 a0 T^2) / (2 T^3),
       c4 = (-30 D + 16 v0 T + 3 a0 T^2) / (2 T^4),
       c5 = (12 D - 6 v0 T - a0 T^2) / (2 T^5),   D = p - q0

   From rest (v0 = a0 = 0) this is the classic q0 + D (10 tau^3 - 15 tau^4 + 6 tau^5),
   tau = t/T, with the bell-shaped speed D/T (30 tau^2 - 60 tau^3 + 30 tau^4). A new
   submovement starts from the current planned position, velocity and acceleration (the
   plan stays C2-smooth; overlapping submovements as in Flash & Henis 1991).

   Duration from Fitts' law, Shannon formulation (Fitts 1954; MacKenzie 1992)::

       T = (a + b log2(1 + D / W)) * kappa_T * lambda_P,   W = 2 r_reach

   a = ``fitts_a`` [s], b = ``fitts_b`` [s/bit]. The target width W is the diameter of the
   reach sphere, seen on screen; D is the distance the *hand* expects to travel,
   D = |(p - q0) * msc| (per-axis product, msc the motion-scaling compensation of §4): a low
   master-to-slave gain means longer, hence slower, hand movements (cf. the control-display
   gain studies of Casiez, Vogel, Balakrishnan & Cockburn 2008). Defaults a = 0.4 s,
   b = 0.5 s/bit are a **calibration**, not a citation: with them a 30-POI trajectory trial
   lasts ~20 s for the expert preset, ~35-45 s for the intermediate and ~55-75 s for the
   novice (the VF study's trials last tens of seconds); classic Fitts tapping constants are
   smaller, laparoscopic and teleoperated pointing several times slower.

   Targets: the operator knows the path (the task) and aims at the perceived goal
   ``g_seen`` (index ``i_seen``); its plan target j is ``i_seen`` or ``i_seen + 1``. It
   *anticipates* the next POI -- starts the submovement toward p_(j+1) -- once the current
   submovement has run a fraction phi = ``anticipation`` of T and the predicted TCP x_hat
   (§3) is within r_reach of p_j. If the perceived goal has not advanced
   ``tau_d + T/2 + 0.1 s`` after that, the POI was missed: the operator re-plans back to it
   and, knowing its judgement was off, looks again (the perceptual misjudgement n_p of §3 is
   redrawn with correlation 0.5). Targets follow the perceived displacement of the goal
   from its nominal POI (m = g_seen - p_(i_seen): tissue motion), so the desired TCP is
   d(t) = q(t) + m(t) - m(t_plan); a perceived jump of m larger than r_reach triggers a
   re-plan. Every re-plan starts at the previous step's desired position (no jumps).

3. Visual feedback with reaction delay and a forward model (a Smith predictor, Miall, Weir,
   Wolpert & Stein 1993, "Is the cerebellum a Smith predictor?"). The person sees the TCP
   and the cues as they were tau_d = ``reaction_delay`` ago (visuomotor loop latency
   150-250 ms, Keele & Posner 1968) -- a ring buffer of round(tau_d/dt) observations -- and
   adds what it has commanded since (efference copy C, in task space)::

       x_seen(t) = x(t - tau_d) + sigma_p,eff * w * n_p(t)
       sigma_p,eff = sigma_p kappa_N lambda_P / (zoom sqrt(1 + beta_VG [VG] + beta_AG vol))
       x_hat(t)  = x_seen(t) + C(t) - C(t - tau_d)
       e_hat     = d(t) - x_hat(t)
       K         = K0 kappa_K (1 + beta_VG [VG]) (1 + beta_AG vol)
       v_cmd     = dq/dt(t) + K e_hat,          dC = v_cmd dt

   n_p is a unit-variance Gauss-Markov process per axis (a misjudgement of where the tip is
   relative to the goal) that decorrelates with time *and* with the tip's motion on screen:
   n_p <- rho n_p + sqrt(1 - rho^2) xi, rho = exp(-dt / tau_p - |dq/dt| dt / l_p), tau_p =
   ``perception_time`` [s] (3 s), l_p = ``perception_length`` [m] (1 cm), dq/dt the planned
   velocity (tremor and noise do not count as motion): a resting hand keeps its (biased)
   judgement, a moving one sees a changing scene; w = (1, 1, 2):
   **decision**, depth (z, along the endoscope's view axis) is judged twice as badly as the
   image-plane directions. sigma_p = ``perception_noise`` [m] at zoom 1.

   How the fixtures' sensory channels enter (cue values are the delayed ones; [VG] = 1 while
   the arrow is shown, vol = AG volume in [0, 1]):

   * Mag: zoom divides the visual misjudgement (a magnified image shows the same error over
     more pixels).
   * VG and AG are extra cues about the error, fused with vision by maximum-likelihood cue
     combination (Ernst & Banks 2002): precisions add, so the fused misjudgement is
     sigma / sqrt(1 + beta_VG [VG] + beta_AG vol) -- beta is a cue's precision relative to
     unaided vision (the audio cue's proportional to its volume). They also raise the
     correction gain K by (1 + beta): the person corrects faster when cued.

   K0 = ``feedback_gain`` [1/s]; K dt is capped at 0.2.

4. Execution: motor noise, tremor, compliance to force feedback, motion-scaling
   compensation. Per axis::

       msc   = 1 + c_MS (MS - 1)                    (partial compensation of motion scaling)
       dh    = msc v_cmd dt (1 + sigma_g kappa_N lambda_P n_g(t))      (signal-dependent)
               + sigma_m kappa_N lambda_P / sqrt(2 tau_m) n_m(t) dt      (additive)
               + (y_trem(t) - y_trem(t - dt))                           (tremor)
               + (F_f(t) - F_f(t - dt)) / k_arm                         (compliance)

   * Signal-dependent noise (Harris & Wolpert 1998): n_g is a unit OU process with
     correlation time tau_m = 0.1 s (muscle force is low-passed), sigma_g = ``gain_noise``
     (relative velocity error).
   * Additive motor noise: a velocity noise, n_m a unit OU process with the same tau_m,
     scaled so that its low-frequency intensity is sigma_m = ``noise`` [m/sqrt(s)]: an
     uncorrected hand drifts by sigma_m sqrt(t) for t >> tau_m (1 mm after 1 s for 1e-3),
     while above ~2 Hz its spectrum falls off and the tremor peak stands out.
   * Physiological tremor (8-12 Hz, RMS ~0.1 mm or less; Elble & Koller 1990 "Tremor";
     Riviere et al. report tens of micrometres to ~0.1 mm for surgeons' hands): an AR(2)
     resonator per axis, the exact discretisation of a damped oscillator (frequency
     f_t = ``tremor_hz``, damping ratio 0.1) driven by white noise,
     y_k = a1 y_(k-1) + a2 y_(k-2) + b xi_k with a1 = 2 r cos(2 pi f_d dt), a2 = -r^2,
     r = exp(-zeta 2 pi f_t dt), and b set so that std(y) = ``tremor_amplitude`` [m] RMS.
   * Force feedback (FF) pulls the compliant hand: the force rendered on the stylus F [N],
     low-passed with time constant ``force_time`` (arm and grip mechanics), displaces the
     hand by F_f / k_arm, k_arm = ``arm_stiffness`` [N/m] (a relaxed human arm's endpoint
     stiffness is a few hundred N/m, Mussa-Ivaldi, Hogan & Bizzi 1985). The person feels
     the pull and lets a fraction a_F = ``force_acceptance`` of it guide the hand: that part
     enters the plan and the forward model (d and C move by a_F dF_f / (k_arm MS)), so it
     is not corrected; the rest is a disturbance, seen and corrected after tau_d.
   * Motion scaling (MS) is applied by the runtime to dh (dx_slave = dh / MS). The person
     adapts partially to the visible gain change: c_MS = ``ms_compensation`` in [0, 1]
     (0: ignores it, 1: fully compensates). **decision**: the adaptation is instantaneous
     and reads ``obs.ms_factors`` (in a real person it comes from watching the tip move
     less than the hand); the forward model assumes the compensated gain, so the remaining
     slowdown (MS / msc) shows up as a delayed error the feedback loop corrects, and the
     longer hand distances lengthen the planned movements (§2).

Cost: ``step`` does scalar float arithmetic and draws its Gaussian numbers in blocks of 1024
steps (~9 us per step measured on one core of the development machine).

Example:
    >>> from vasim.tasks import point_task
    >>> task = point_task()
    >>> op = ScriptedOperator(OperatorProfile.expert(), task, seed=1)
    >>> op.reset(task.start)
    >>> obs = OperatorObservation(t=0.001, dt=0.001, tcp=task.start, goal=task.points[0],
    ...                           goal_index=0)
    >>> op.step(obs).shape
    (3,)
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from vasim.fixtures.types import Vec3
from vasim.haptics.observation import OperatorObservation
from vasim.operator.port import Percept
from vasim.operator.profile import OperatorProfile
from vasim.tasks.base import Task

# -- model constants (documented in the module docstring) ---------------------------------
SKILL_TIME = 1.5
"""kappa_T = 1 + SKILL_TIME (1 - skill): a novice's submovements are up to 2.5x longer."""
SKILL_NOISE = 1.0
"""kappa_N = 1 + SKILL_NOISE (1 - skill): a novice's learnable noise is up to 2x larger."""
SKILL_GAIN_MIN = 0.5
"""kappa_K = SKILL_GAIN_MIN + (1 - SKILL_GAIN_MIN) skill."""
TREMOR_DAMPING = 0.1
"""Damping ratio zeta of the tremor resonator (a ~2 Hz wide spectral peak at 10 Hz)."""
MOTOR_NOISE_TIME = 0.1
"""Correlation time of the motor noises n_g and n_m [s] (the low-pass of muscle force)."""
DEPTH_WEIGHT = (1.0, 1.0, 2.0)
"""Per-axis weight w of the perceptual noise (z is the depth axis of the endoscopic view)."""
MISS_MARGIN = 0.1
"""Extra wait [s] before the operator concludes a POI was missed."""
MISS_RECORRELATION = 0.5
"""Correlation of the perceptual misjudgement before and after noticing a missed POI."""
MAX_GAIN_DT = 0.2
"""Upper bound of K dt (keeps the discrete feedback loop well damped at any dt)."""
_BLOCK = 1024
_NRAND = 12


def power_law(practice: float, alpha: float, asymptote: float = 0.0) -> float:
    """Power law of practice factor lambda_P = f + (1 - f) (1 + P) ** -alpha (Newell &
    Rosenbloom 1981; f = ``asymptote``, the share practice never removes: experienced
    operators plateau, issue #25).

    >>> round(power_law(20, 0.3), 4), round(power_law(20, 0.3, 0.5), 4)
    (0.4012, 0.7006)
    """
    if practice < 0:
        raise ValueError(f"practice must be >= 0, got {practice!r}")
    return asymptote + (1.0 - asymptote) * (1.0 + practice) ** -alpha


def fitts_time(distance: float, width: float, a: float, b: float) -> float:
    """Fitts' law movement time, Shannon form: a + b log2(1 + D / W) [s].

    Args:
        distance: D [m], >= 0. width: W [m], > 0. a: intercept [s]. b: slope [s/bit].

    >>> fitts_time(0.01, 0.01, 0.4, 0.5)
    0.9
    """
    if width <= 0:
        raise ValueError(f"target width must be > 0 m, got {width!r}")
    return a + b * math.log2(1.0 + max(distance, 0.0) / width)


def min_jerk_position(tau: float | np.ndarray) -> float | np.ndarray:
    """Normalised min-jerk position s(tau) = 10 tau^3 - 15 tau^4 + 6 tau^5, tau in [0, 1]."""
    tau = np.clip(tau, 0.0, 1.0)
    return tau**3 * (10.0 - 15.0 * tau + 6.0 * tau**2)


def min_jerk_speed(tau: float | np.ndarray) -> float | np.ndarray:
    """Normalised min-jerk speed ds/dtau = 30 tau^2 - 60 tau^3 + 30 tau^4 (peak 1.875)."""
    tau = np.clip(tau, 0.0, 1.0)
    return 30.0 * tau**2 * (1.0 - tau) ** 2


def quintic_coefficients(q0: float, v0: float, a0: float, qf: float,
                         duration: float) -> tuple[float, float, float, float, float, float]:
    """Coefficients c0..c5 of the minimum-jerk quintic (one axis) from (q0, v0, a0) at t = 0
    to (qf, 0, 0) at t = ``duration`` [s] (Flash & Hogan 1985).

    >>> c = quintic_coefficients(0.0, 0.0, 0.0, 1.0, 1.0)
    >>> [round(x, 9) for x in c]
    [0.0, 0.0, 0.0, 10.0, -15.0, 6.0]
    """
    if not duration > 0:
        raise ValueError(f"duration must be > 0 s, got {duration!r}")
    T = duration
    D = qf - q0
    T2 = T * T
    return (
        q0, v0, 0.5 * a0,
        (20.0 * D - 12.0 * v0 * T - 3.0 * a0 * T2) / (2.0 * T2 * T),
        (-30.0 * D + 16.0 * v0 * T + 3.0 * a0 * T2) / (2.0 * T2 * T2),
        (12.0 * D - 6.0 * v0 * T - a0 * T2) / (2.0 * T2 * T2 * T),
    )


def tremor_ar2(hz: float, amplitude: float, dt: float,
               damping: float = TREMOR_DAMPING) -> tuple[float, float, float]:
    """AR(2) coefficients (a1, a2, b) of the tremor resonator (see the module docstring).

    The process y_k = a1 y_(k-1) + a2 y_(k-2) + b xi_k (xi ~ N(0, 1)) has a spectral peak
    near ``hz`` and stationary standard deviation ``amplitude`` [m].
    """
    w = 2.0 * math.pi * hz
    if not (0 < damping < 1):
        raise ValueError(f"tremor damping must be in (0, 1), got {damping!r}")
    if w * dt >= math.pi:
        raise ValueError(f"tremor at {hz!r} Hz is above the Nyquist rate of dt={dt!r} s")
    r = math.exp(-damping * w * dt)
    theta = w * math.sqrt(1.0 - damping * damping) * dt
    a1 = 2.0 * r * math.cos(theta)
    a2 = -r * r
    var_unit = (1.0 - a2) / ((1.0 + a2) * ((1.0 - a2) ** 2 - a1 * a1))
    return a1, a2, amplitude / math.sqrt(var_unit)


# ---------------------------------------------------------------------------------------
# The person


class ScriptedOperator:
    """A simulated person holding the master (see the module docstring for the model).

    Args:
        profile: the person.
        task: the task to perform (the operator knows the path, as a trainee sees it).
        seed: seed of the operator's random generator.
        practice: P >= 0, number of earlier trials of this person (power law of practice).

    Call :meth:`reset` with the tool's start position before the first :meth:`step`.
    """

    def __init__(self, profile: OperatorProfile, task: Task, *, seed: int,
                 practice: int = 0):
        if isinstance(practice, bool) or not isinstance(practice, int | np.integer) \
                or practice < 0:
            raise ValueError(f"practice must be an int >= 0, got {practice!r}")
        self.profile = profile
        self.task = task
        self.seed = seed
        self.practice = int(practice)
        p = profile
        lam = power_law(self.practice, p.learning_rate, p.asymptote)
        self.learning_factor = lam
        """lambda_P of this trial."""
        kn = 1.0 + SKILL_NOISE * (1.0 - p.skill)
        self._time_factor = (1.0 + SKILL_TIME * (1.0 - p.skill)) * lam
        self._k0 = p.feedback_gain * (SKILL_GAIN_MIN + (1.0 - SKILL_GAIN_MIN) * p.skill)
        self._sig_m = p.noise * kn * lam
        self._sig_g = p.gain_noise * kn * lam
        self._sig_p = p.perception_noise * kn * lam
        self._width = 2.0 * task.reach_radius
        self._r = task.reach_radius
        self._pts = [tuple(float(c) for c in row) for row in task.points]
        self._n = len(self._pts)
        self._sq_miss = math.sqrt(1.0 - MISS_RECORRELATION**2)
        self.misses = 0
        """Number of missed POIs noticed since :meth:`reset` (for diagnostics)."""
        self._ready = False

    # -- public API -----------------------------------------------------------------------
    def movement_time(self, distance: float) -> float:
        """Duration T [s] of a submovement of ``distance`` [m] for this person and practice."""
        p = self.profile
        return fitts_time(distance, self._width, p.fitts_a, p.fitts_b) * self._time_factor

    def reset(self, tcp: Vec3) -> None:
        """Starts a trial with the tool tip (and the hand, at rest) at ``tcp`` [m].

        Restarts the random generator from ``seed``: a reset operator repeats itself.
        """
        x0 = [float(c) for c in np.asarray(tcp, dtype=np.float64).reshape(3)]
        self._rng = np.random.default_rng(self.seed)
        self._x0 = x0
        self._t = 0.0
        self._k = 0
        self._dt: float | None = None
        self._buf: list[tuple] = []
        # plan: quintic coefficients per axis, start time, duration, target
        self._coef = [(c, 0.0, 0.0, 0.0, 0.0, 0.0) for c in x0]
        self._target = list(x0)
        self._t0 = 0.0
        self._T = 1e-9
        self._j = -1
        self._t_ant = -1.0
        self._m_plan = [0.0, 0.0, 0.0]
        self._d_last = list(x0)
        self._C = [0.0, 0.0, 0.0]
        self._np = [float(v) for v in self._rng.standard_normal(3)]
        self._ng = [float(v) for v in self._rng.standard_normal(3)]
        self._nm = [float(v) for v in self._rng.standard_normal(3)]
        self._y1 = [0.0, 0.0, 0.0]
        self._y2 = [0.0, 0.0, 0.0]
        self._ff = [0.0, 0.0, 0.0]
        self._acc = [0.0, 0.0, 0.0]
        self._ds_plan = 0.0
        self._msc = [1.0, 1.0, 1.0]
        self.misses = 0
        self._noise: list[list[float]] = []
        self._ni = _BLOCK
        self._ready = True

    @property
    def target_index(self) -> int:
        """Index of the POI the current submovement aims at (-1 before the goal is seen)."""
        return self._j

    def step(self, obs: OperatorObservation) -> Vec3:
        """One control step: perceive ``obs`` (delayed), plan, correct, move.

        Args:
            obs: what the person perceives now (it is acted on after the reaction delay).

        Returns:
            (3,) master increment dX_M [m] for this step, world-aligned master axes.

        Raises:
            RuntimeError: if called before :meth:`reset`.
            ValueError: if ``obs.dt`` is not a finite positive number.
        """
        return np.array(self.step_floats(
            obs.dt, obs.tcp.tolist(), obs.goal.tolist(), obs.goal_index, obs.guidance,
            obs.audio_volume, obs.zoom, obs.ms_factors.tolist(), obs.force.tolist()))

    def act(self, percept: Percept) -> list[float]:
        """The trial operator protocol (``vasim.operator.port.TrialOperator``): one
        :meth:`step_floats` on the percept's floats."""
        p = percept
        return self.step_floats(p.dt, p.tcp, p.goal, p.goal_index, p.guidance,
                                p.audio_volume, p.zoom, p.ms_factors, p.force)

    def step_floats(
        self, dt: float, tcp: Sequence[float], goal: Sequence[float], goal_index: int,
        guidance: bool, audio_volume: float, zoom: float, ms_factors: Sequence[float],
        force: Sequence[float],
    ) -> list[float]:
        """``step`` with the observation's fields as floats (the trial loop's fast path: no
        ``OperatorObservation`` and no arrays are built per step; same model, same numbers).

        ``tcp`` and ``goal`` (3 floats each) are kept for the reaction delay: pass values
        that are not modified afterwards (tuples). Returns dX_M as a list of 3 floats [m].

        **Decision** (issue #29 item 5): one function of about 170 lines, like the compiled
        kernels. It runs once per servo tick of every simulated trial, and the phases
        (perception, motion-scaling compensation, plan, desired motion, feedback,
        execution) hand each other about twenty floats. Four method calls passing them on
        cost 15 % of the step on their own (28.7 -> 33.0 us a step, 20,000 steps, median
        of 7, on the shared CI machine; a split also packs and unpacks tuples, which costs
        more). The phases are marked by the ``# ----`` comments below.
        """
        if not self._ready:
            raise RuntimeError("call ScriptedOperator.reset() before step()")
        if self._dt is None:
            self._setup(dt)
        elif dt != self._dt and not (dt > 0 and math.isfinite(dt)):
            raise ValueError(f"obs.dt must be a finite number > 0 s, got {dt!r}")
        p = self.profile
        # ---- perception: store now, act on what was stored tau_d ago ----------------------
        C = self._C
        nb = self._nbuf
        k = self._k
        self._buf[k % nb] = (tcp, goal, goal_index, guidance, audio_volume, zoom,
                             C[0], C[1], C[2])
        xs, gs, i_s, guid, vol, zoom, c0, c1, c2 = self._buf[(k + 1) % nb]
        self._k = k + 1
        t = self._t + dt
        self._t = t
        if self._ni >= _BLOCK:
            self._noise = self._rng.standard_normal((_BLOCK, _NRAND)).tolist()
            self._ni = 0
        rnd = self._noise[self._ni]
        self._ni += 1
        # perceptual misjudgement (OU), divided by zoom, reduced by VG
        # the misjudgement decorrelates with time and with the (planned) motion of the tip
        ds = self._ds_plan
        if ds > 0.0:
            rp = self._rho_p * math.exp(-ds / p.perception_length)
            sp = math.sqrt(1.0 - rp * rp)
        else:
            rp, sp = self._rho_p, self._sq_p
        npv = self._np
        prec = 1.0
        if guid:
            prec += p.guidance_gain
        if vol > 0.0:
            prec += p.audio_gain * (vol if vol < 1.0 else 1.0)
        sig_p = self._sig_p / ((zoom if zoom > 1e-6 else 1e-6) * math.sqrt(prec))
        npv[0] = rp * npv[0] + sp * rnd[0]
        npv[1] = rp * npv[1] + sp * rnd[1]
        npv[2] = rp * npv[2] + sp * rnd[2]
        xh0 = xs[0] + sig_p * DEPTH_WEIGHT[0] * npv[0] + C[0] - c0
        xh1 = xs[1] + sig_p * DEPTH_WEIGHT[1] * npv[1] + C[1] - c1
        xh2 = xs[2] + sig_p * DEPTH_WEIGHT[2] * npv[2] + C[2] - c2
        # ---- motion-scaling compensation (read before planning: it sets hand distances) --
        ms = ms_factors
        if ms[0] < 1e-6 or ms[1] < 1e-6 or ms[2] < 1e-6:
            ms = [m if m > 1e-6 else 1e-6 for m in ms]
        c_ms = p.ms_compensation
        msc = self._msc
        msc[0] = 1.0 + c_ms * (ms[0] - 1.0)
        msc[1] = 1.0 + c_ms * (ms[1] - 1.0)
        msc[2] = 1.0 + c_ms * (ms[2] - 1.0)
        # ---- plan ----------------------------------------------------------------------
        if gs is None or i_s < 0:
            m0 = m1 = m2 = 0.0
        else:
            if i_s < self._n:
                pn = self._pts[i_s]
                m0, m1, m2 = gs[0] - pn[0], gs[1] - pn[1], gs[2] - pn[2]
            else:
                m0 = m1 = m2 = 0.0
            j = self._j
            mp = self._m_plan
            if j < i_s or j > i_s + 1:
                self._replan(t, i_s, gs, m0, m1, m2)
            elif j == i_s:
                tg = self._target
                if (j + 1 < self._n and t - self._t0 >= p.anticipation * self._T
                        and (xh0 - tg[0]) ** 2 + (xh1 - tg[1]) ** 2 + (xh2 - tg[2]) ** 2
                        <= self._r * self._r):
                    self._replan(t, j + 1, gs, m0, m1, m2)
                    self._t_ant = t
                elif (m0 - mp[0]) ** 2 + (m1 - mp[1]) ** 2 + (m2 - mp[2]) ** 2 \
                        > self._r * self._r:
                    self._replan(t, j, gs, m0, m1, m2)
            elif t - self._t_ant > p.reaction_delay + 0.5 * self._T + MISS_MARGIN:
                # j == i_s + 1 and the perceived goal did not advance: the POI was missed.
                # The failure tells the person its judgement is off: it looks again.
                self._replan(t, i_s, gs, m0, m1, m2)
                self.misses += 1
                xi = self._rng.standard_normal(3).tolist()
                for ax in range(3):
                    npv[ax] = MISS_RECORRELATION * npv[ax] + self._sq_miss * xi[ax]
        # ---- desired position and velocity (quintic, Horner) ---------------------------
        mp = self._m_plan
        tau = t - self._t0
        if tau >= self._T:
            tg = self._target
            d0, d1, d2 = tg[0], tg[1], tg[2]
            v0 = v1 = v2 = 0.0
        else:
            cf = self._coef
            a = cf[0]
            d0 = a[0] + tau * (a[1] + tau * (a[2] + tau * (a[3] + tau * (a[4] + tau * a[5]))))
            v0 = a[1] + tau * (2 * a[2] + tau * (3 * a[3] + tau * (4 * a[4] + tau * 5 * a[5])))
            a = cf[1]
            d1 = a[0] + tau * (a[1] + tau * (a[2] + tau * (a[3] + tau * (a[4] + tau * a[5]))))
            v1 = a[1] + tau * (2 * a[2] + tau * (3 * a[3] + tau * (4 * a[4] + tau * 5 * a[5])))
            a = cf[2]
            d2 = a[0] + tau * (a[1] + tau * (a[2] + tau * (a[3] + tau * (a[4] + tau * a[5]))))
            v2 = a[1] + tau * (2 * a[2] + tau * (3 * a[3] + tau * (4 * a[4] + tau * 5 * a[5])))
        self._ds_plan = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2) * dt
        if i_s >= 0:
            d0 += m0 - mp[0]
            d1 += m1 - mp[1]
            d2 += m2 - mp[2]
        dl = self._d_last
        dl[0], dl[1], dl[2] = d0, d1, d2
        acc = self._acc  # accepted force-induced displacement (task space)
        d0 += acc[0]
        d1 += acc[1]
        d2 += acc[2]
        # ---- feedback (Smith predictor) -----------------------------------------------
        K = self._k0
        if guid:
            K *= 1.0 + p.guidance_gain
        if vol > 0.0:
            K *= 1.0 + p.audio_gain * (vol if vol < 1.0 else 1.0)
        kmax = MAX_GAIN_DT / dt
        if K > kmax:
            K = kmax
        u0 = v0 + K * (d0 - xh0)
        u1 = v1 + K * (d1 - xh1)
        u2 = v2 + K * (d2 - xh2)
        C[0] += u0 * dt
        C[1] += u1 * dt
        C[2] += u2 * dt
        # ---- execution -------------------------------------------------------------------
        ng = self._ng
        rg, sg = self._rho_g, self._sq_g
        ng[0] = rg * ng[0] + sg * rnd[3]
        ng[1] = rg * ng[1] + sg * rnd[4]
        ng[2] = rg * ng[2] + sg * rnd[5]
        sig_g = self._sig_g
        nm = self._nm
        sm = self._sig_m * self._sm_scale * dt  # OU velocity noise -> displacement
        a1, a2, b = self._ar
        y1, y2 = self._y1, self._y2
        ff = self._ff  # hand displacement by force F_f / k_arm [m]
        fa = self._f_alpha
        karm = p.arm_stiffness
        acc = self._acc
        acc_f = p.force_acceptance
        out = [0.0, 0.0, 0.0]
        for ax, u in ((0, u0), (1, u1), (2, u2)):
            y = a1 * y1[ax] + a2 * y2[ax] + b * rnd[6 + ax]
            dy = y - y1[ax]
            y2[ax] = y1[ax]
            y1[ax] = y
            df = fa * (force[ax] / karm - ff[ax])
            ff[ax] += df
            # the accepted part of the pull is expected (forward model) and wanted (plan)
            da = acc_f * df / ms[ax]
            acc[ax] += da
            C[ax] += da
            nm[ax] = rg * nm[ax] + sg * rnd[9 + ax]
            out[ax] = msc[ax] * u * dt * (1.0 + sig_g * ng[ax]) + sm * nm[ax] + dy + df
        return out

    # -- internals -----------------------------------------------------------------------
    def _setup(self, dt: float) -> None:
        if not (isinstance(dt, int | float) and math.isfinite(dt) and dt > 0):
            raise ValueError(f"obs.dt must be a finite number > 0 s, got {dt!r}")
        p = self.profile
        self._dt = float(dt)
        self._sm_scale = 1.0 / math.sqrt(2.0 * MOTOR_NOISE_TIME)
        n_delay = round(p.reaction_delay / dt)
        self._nbuf = n_delay + 1
        x0 = self._x0
        entry = (x0, None, -1, False, 0.0, 1.0, 0.0, 0.0, 0.0)
        self._buf = [entry] * self._nbuf
        self._rho_p = math.exp(-dt / p.perception_time)
        self._sq_p = math.sqrt(1.0 - self._rho_p**2)
        self._rho_g = math.exp(-dt / MOTOR_NOISE_TIME)
        self._sq_g = math.sqrt(1.0 - self._rho_g**2)
        self._ar = tremor_ar2(p.tremor_hz, p.tremor_amplitude, dt)
        self._f_alpha = 1.0 - math.exp(-dt / p.force_time)

    def _state_at(self, t: float) -> tuple[list[float], list[float], list[float]]:
        """Planned position, velocity, acceleration at time t (per axis)."""
        tau = t - self._t0
        if tau >= self._T:
            return list(self._target), [0.0] * 3, [0.0] * 3
        q, v, a = [], [], []
        for c in self._coef:
            q.append(c[0] + tau * (c[1] + tau * (c[2] + tau * (c[3] + tau * (c[4] + tau * c[5])))))
            v.append(c[1] + tau * (2 * c[2] + tau * (3 * c[3] + tau * (4 * c[4] + tau * 5 * c[5]))))
            a.append(2 * c[2] + tau * (6 * c[3] + tau * (12 * c[4] + tau * 20 * c[5])))
        return q, v, a

    def _replan(self, t: float, j: int, gs: list[float], m0: float, m1: float,
                m2: float) -> None:
        """Starts a min-jerk submovement toward POI j from the current planned state."""
        _, v, a = self._state_at(t)
        q = list(self._d_last)  # the desired position of the previous step: no jump
        if j < self._n:
            pj = self._pts[j]
            target = [pj[0] + m0, pj[1] + m1, pj[2] + m2]
        else:
            target = list(gs)
        msc = self._msc  # Fitts distance in hand space (motion scaling), width on screen
        dist = math.sqrt(sum(((target[ax] - q[ax]) * msc[ax]) ** 2 for ax in range(3)))
        T = self.movement_time(dist)
        self._coef = [quintic_coefficients(q[ax], v[ax], a[ax], target[ax], T)
                      for ax in range(3)]
        self._target = target
        self._t0 = t
        self._T = T
        self._j = j
        self._m_plan = [m0, m1, m2]


__all__ = [
    "OperatorObservation",
    "OperatorProfile",
    "ScriptedOperator",
    "fitts_time",
    "min_jerk_position",
    "min_jerk_speed",
    "power_law",
    "quintic_coefficients",
    "tremor_ar2",
]
