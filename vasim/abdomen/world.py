"""The virtual abdomen as one object: organs, tool contact, targets on tissue, snapshots.

:class:`Abdomen` is the stateful shell a trial (or the viewer's physics thread) steps at the
scene's physics rate. Each :meth:`Abdomen.step` takes the tool pose, advances every organ by
``dt`` and returns an immutable :class:`AbdomenSnapshot`: the tool's contact force, torque,
force derivative and contact patch (for the 1 kHz haptic side), the targets bound to the
tissue, and each organ's surface. Readers (the servo loop, the viewer, the recorder) only
ever see whole snapshots, never a half-updated mesh: a snapshot's arrays are copies, made
read-only.

Sleeping organs (**decision**, the standard "sleeping bodies" of physics engines, so that a
trial headless runs many times faster than real time while staying exact where it matters).
An organ the tool does not touch is, up to its small inertial lag, its gravity-settled shape
carried by the physiological motion field: ``x = x_settled + u(x_settled, t)`` (breathing,
heartbeat). Such an organ *sleeps*: its nodes are not integrated, its surface is computed
from that expression when someone reads it. It wakes the moment the tool's bounding box
comes within reach of its (motion-inflated) bounding box and a contact is found, starting
from the sleeping shape with the frame's velocity; it falls asleep again after
``sleep_after`` seconds without contact once it is within ``sleep_tolerance`` of the
sleeping shape and moving with the frame (the snap is at most that tolerance). The settled
shape is computed once per scene and process by integrating the organ at rest with fixed
anchors until it is still (:func:`settled_positions`). ``always_awake=True`` integrates
every organ at every step (the benchmark of the full cost, and a cross-check in the tests).

Contact: the tool capsule against every non-wall organ (:mod:`vasim.abdomen.contact`); the
reaction forces go to the organ's solver as external forces for the next step; a contact
with a delicate organ (the vessel) counts as damage. The wall is kinematic: the trocars stay
where the wall puts them and the shaft passes through it without contact. Any other
kinematic organ (**decision**, the simplest consistent rule) is a rigid body for contact: it
is detected, counted (touching, delicate damage, quality) and pushes the tool with the same
penalty force, but its nodes (all anchored) take no force and it is never stepped.

Several instruments (**decision**, issue #7 §4: in the MRCP study both tools and the
endoscope are in the abdomen). :meth:`Abdomen.step` takes one :class:`ToolPose`, a sequence
of them or a mapping name -> pose. Each instrument is detected against the tissue on its own
(same capsule, :attr:`Abdomen.tool`); the reaction forces of every instrument act on the
tissue, summed per node (the instruments' contacts concatenated in instrument order, one
scatter). The snapshot reports each instrument's result in :attr:`AbdomenSnapshot.tools`;
its top-level ``force`` / ``torque`` / ``patch`` / ``touching`` / ``delicate_contact`` are
the *first* instrument's (the haptic one, as with a single tool), while
:attr:`AbdomenSnapshot.any_contact`, ``touching_any`` and ``delicate_any`` cover them all.
The quality accumulator counts contact time while any instrument touches, the force and
torque as the sum over instruments of their magnitudes (``Σ_i |F_i|``, ``Σ_i |τ_i|``: two
tools pressing opposite ways load the tissue twice, they do not cancel; each torque is about
its own trocar, so only magnitudes add meaningfully) and delicate contacts by any
instrument. A single pose (or a 1-tuple) is the single-tool path, bit for bit.

Example:
    >>> import numpy as np
    >>> from vasim.abdomen.contact import ToolPose
    >>> world = Abdomen("default")
    >>> snap = world.step(None)
    >>> round(snap.t, 3), snap.in_contact
    (0.004, False)
    >>> sorted(world.names)[:2]
    ['abdominal_wall', 'intestine_0']
"""

from __future__ import annotations

import hashlib
import math
import threading
from collections import deque
from collections.abc import Callable, Mapping, Sequence
from functools import partial
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vasim.abdomen._contact_kernels import box_apart, cells_near, scatter_forces
from vasim.abdomen._kernels import frame_velocity
from vasim.abdomen.attach import SurfaceBinding, bind_points
from vasim.abdomen.contact import (
    ContactPatch,
    ContactResult,
    ToolPose,
    ToolShape,
    detect_contacts,
)
from vasim.abdomen.integrate import OrganSolver, StepReport
from vasim.abdomen.model import OrganModel, OrganState
from vasim.abdomen.motion import PhysioMotion, PointMotion, _sin_cos
from vasim.abdomen.quality import TissueQuality
from vasim.abdomen.scene import Scene, dumps_scene, load_scene
from vasim.abdomen.snapshot import AbdomenSnapshot, OrganView, ToolContact, readonly
from vasim.core.errors import ConfigError
from vasim.core.kernel_args import writable_c

FloatArray = NDArray[np.float64]

SLEEP_AFTER = 0.5
"""Seconds without contact before an awake organ may sleep again [s]."""
SLEEP_TOLERANCE = 5e-4
"""Largest node distance from the sleeping shape at which an organ may sleep [m]."""
SLEEP_VELOCITY = 0.01
"""Largest node speed relative to the moving frame at which an organ may sleep [m/s]."""
BROAD_CELL = 0.02
"""Edge of the cubes the broad phase bins each organ's nodes into [m]."""
SETTLE_TIME = 3.0
"""Longest simulated time spent settling an organ under gravity [s]."""
SETTLE_SPEED = 1e-4
"""An organ counts as settled when no node moves faster than this [m/s]."""
MAX_SETTLE_RESETS = 3
"""Solver resets tolerated while settling an organ before it is refused (ConfigError)."""
MAX_EVENTS = 10_000
"""Events kept in :attr:`Abdomen.events` (the newest; :attr:`Abdomen.n_events` counts all)."""
POSE_LIMIT = 1e3
"""A tool point farther than this from the origin on an axis [m] is out of the abdomen (no
contact): larger finite values overflow the kernel's squared lengths."""


# ---------------------------------------------------------------------------------------
# Settled (gravity-equilibrium) shapes, cached per scene text and process

_SETTLED: dict[tuple[str, str], FloatArray] = {}
_MODELS: dict[str, tuple[OrganModel, ...]] = {}
_BINDINGS: dict[tuple[object, ...], SurfaceBinding] = {}
"""Bindings of task points to the sleeping shapes, per scene, organs, time and points (a
trial binds the same POIs to the same shapes as the previous trial on that variant)."""
_SETTLED_LOCK = threading.Lock()


def _scene_key(scene: Scene) -> str:
    return hashlib.sha256(dumps_scene(scene).encode()).hexdigest()


def scene_models(scene: Scene) -> tuple[OrganModel, ...]:
    """The scene's organ models, built once per scene text and process (they are immutable)."""
    key = _scene_key(scene)
    with _SETTLED_LOCK:
        cached = _MODELS.get(key)
    if cached is None:
        cached = tuple(scene.build())
        with _SETTLED_LOCK:
            _MODELS[key] = cached
    return cached


def motion_phases(motion: PhysioMotion, t: float) -> tuple[float, float]:
    """(breathing, heartbeat) sine factors at ``t``: ``u(X, t) = s_b A_b + s_h w(X) A_h``.

    The same expression as :func:`vasim.abdomen.motion.point_offsets`, factored so that the
    per-node heartbeat weights ``w(X)`` of a rest shape are computed once.
    """
    b, h = motion.breathing, motion.heartbeat
    return (math.sin(2.0 * math.pi * b.frequency_hz * t + b.phase),
            math.sin(2.0 * math.pi * h.frequency_hz * t + h.phase))


def settled_positions(scene: Scene, model: OrganModel,
                      solver: OrganSolver | Callable[[], OrganSolver]) -> FloatArray:
    """(n, 3) positions of ``model`` at rest under gravity with its anchors at rest [m].

    Integrates from the rest shape with fixed anchors until every node is slower than
    ``SETTLE_SPEED`` (at most ``SETTLE_TIME`` of simulated time), then caches the result for
    this scene text and organ (a process computes it once). ``solver`` may be a factory,
    called only when the shape is not cached yet.
    """
    key = (_scene_key(scene), model.name)
    with _SETTLED_LOCK:
        cached = _SETTLED.get(key)
    if cached is not None:
        return cached
    if not isinstance(solver, OrganSolver):
        solver = solver()
    state = solver.initial_state()
    targets = np.array(model.rest[model.anchors])
    if len(model.anchors) < model.n_nodes:
        # a reset puts the organ back at rest with v = 0, which is not settled;
        # only a step without reset may end the settling, and an organ that keeps resetting
        # (e.g. absurd parameters) is refused rather than cached as its rest shape.
        resets = 0
        last_reset = False
        for _ in range(math.ceil(SETTLE_TIME / solver.dt)):
            report = solver.step(state, targets)
            last_reset = bool(report.reset)
            if last_reset:
                resets += 1
                if resets > MAX_SETTLE_RESETS:
                    break
                continue
            if float(np.abs(state.v).max()) < SETTLE_SPEED:
                break
        if last_reset:
            raise ConfigError(
                f"organ {model.name!r} does not settle under gravity: the solver reset it "
                f"{resets} times while settling (last: {report.reason}); check its stiffness, "
                "mass, anchors and the scene's gravity", file=scene.source,
                field=f"organs.{model.name}")
    out = readonly(state.x)
    with _SETTLED_LOCK:
        _SETTLED[key] = out
    return out


# ---------------------------------------------------------------------------------------
# The world


class _Body:
    """One organ's model, solver, state and sleep bookkeeping (private)."""

    def __init__(self, model: OrganModel, make_solver: Callable[[], OrganSolver],
                 motion: PhysioMotion, settled: FloatArray) -> None:
        self.model = model
        self._make_solver = make_solver
        self._solver: OrganSolver | None = None
        self.motion = motion
        self.settled = settled
        self.kinematic = model.kind == "wall" or len(model.anchors) == model.n_nodes
        self.state = OrganState(np.array(settled), np.zeros_like(settled), 0.0)
        self.awake = False
        self.quiet_time = 0.0
        self.anchor_rest = np.array(settled[model.anchors])
        self.anchor_motion = PointMotion(motion, self.anchor_rest)
        self.node_motion = PointMotion(motion, settled)
        self.amp_b = np.asarray(motion.breathing.amplitude_m, dtype=np.float64)
        self.amp_h = np.asarray(motion.heartbeat.amplitude_m, dtype=np.float64)
        self.weight_h = motion.heartbeat.weight(settled)
        # the frame velocity of every node, per step, into one buffer (frame_velocity)
        self.w_h = self.weight_h[:, None] * self.amp_h[None, :]
        self.heart = bool(any(motion.heartbeat.amplitude_m))
        self.v_frame = np.zeros_like(settled)
        self.max_edge = _max_edge(settled, model.faces)
        # Bounding sphere of the settled shape, inflated by the largest motion and the
        # longest edge: the broad phase of the tool test (floats: a few µs per organ).
        centre = 0.5 * (settled.min(axis=0) + settled.max(axis=0))
        reach = float(np.linalg.norm(self.amp_b) + np.linalg.norm(self.amp_h))
        self.centre = tuple(float(c) for c in centre)
        self.radius = (float(np.linalg.norm(settled - centre, axis=1).max()) + reach
                       + self.max_edge)
        self.f_ext = np.zeros((model.n_nodes, 3))
        # Finer broad phase: the nodes binned in cubes of BROAD_CELL, one sphere per cube
        # (centroid, farthest node + motion reach + longest edge).
        cell = np.floor(settled / BROAD_CELL).astype(np.int64)
        _, inverse = np.unique(cell, axis=0, return_inverse=True)
        inverse = inverse.ravel()
        n_cells = int(inverse.max()) + 1
        counts = np.bincount(inverse, minlength=n_cells)[:, None]
        cc = np.stack([np.bincount(inverse, settled[:, a], n_cells) for a in range(3)],
                      axis=1) / counts
        dist = np.linalg.norm(settled - cc[inverse], axis=1)
        rr = np.zeros(n_cells)
        np.maximum.at(rr, inverse, dist)
        self.cell_centres = cc
        self.cell_radii = rr + reach + self.max_edge

    @property
    def solver(self) -> OrganSolver:
        """The organ's solver, built on first use: an organ the tool never touches (most of
        them, in most trials) never pays for its set-up (e.g. a factorisation)."""
        if self._solver is None:
            self._solver = self._make_solver()
        return self._solver

    def sleeping_x(self, t: float) -> FloatArray:
        sb, sh = motion_phases(self.motion, t)
        return self.settled + sb * self.amp_b + (sh * self.weight_h)[:, None] * self.amp_h

    def wake(self, t: float) -> None:
        self.state.x[...] = self.sleeping_x(t)
        self.state.v[...] = self.node_motion.velocities(t)
        self.state.t = t
        self.awake = True
        self.quiet_time = 0.0

    def positions(self, t: float) -> FloatArray:
        return self.state.x if self.awake else self.sleeping_x(t)

    def frame_velocities(self, t: float) -> FloatArray:
        """(n, 3) frame velocity of every node at ``t`` [m/s], in a buffer the next call
        overwrites: ``node_motion.velocities(t)``, bit for bit, without temporaries."""
        b, h = self.motion.breathing, self.motion.heartbeat
        _, cb = _sin_cos(b.frequency_hz, b.phase, t)
        _, ch = _sin_cos(h.frequency_hz, h.phase, t)
        frame_velocity(cb, self.amp_b, ch, self.w_h, self.heart, self.v_frame)
        return self.v_frame


def _max_edge(x: FloatArray, faces: NDArray[np.int64]) -> float:
    if len(faces) == 0:
        return 0.0
    e = x[faces[:, [1, 2, 0]]] - x[faces]
    return float(np.sqrt((e * e).sum(-1).max()))


class Abdomen:
    """The deformable abdomen of one scene, stepped by its owner at ``dt`` (see module doc).

    Args:
        scene: a :class:`~vasim.abdomen.scene.Scene`, a scene name or a TOML path.
        tool: the tool's shape and contact stiffness.
        always_awake: integrate every organ every step (no sleeping).
    """

    def __init__(self, scene: Scene | str | Path = "default", *,
                 tool: ToolShape | None = None, always_awake: bool = False) -> None:
        self.scene = scene if isinstance(scene, Scene) else load_scene(scene)
        self.tool = tool or ToolShape()
        self.always_awake = always_awake
        self.dt = self.scene.physics.dt
        self._key = _scene_key(self.scene)
        options = self.scene.solver_options()
        self._bodies: list[_Body] = []
        for model in scene_models(self.scene):
            make = partial(OrganSolver, model, self.dt, **options)
            motion = self.scene.organ(model.name).motion(self.scene.motion)
            settled = settled_positions(self.scene, model, make)
            self._bodies.append(_Body(model, make, motion, settled))
        self.t = 0.0
        self.seq = 0
        self.quality = TissueQuality()
        # Bounded: an organ resetting every step of a long session grew this
        # list without end; the newest MAX_EVENTS are kept, n_events counts them all.
        self.events: deque[tuple[float, str, str]] = deque(maxlen=MAX_EVENTS)
        self.n_events = 0
        self._binding: SurfaceBinding | None = None
        self._bound: list[_Body] = []
        self._last_contacts: tuple[tuple[str, dict[int, ContactResult]], ...] = ()
        self._empty_patch = ContactPatch.empty(self.tool.radius)
        # per instrument slot (its position in the step's tools), the clearance of its last
        # broad phase (see _contacts)
        self._clears: dict[int, tuple[FloatArray, FloatArray, float] | None] = {}
        # Per-body tables for the vectorised broad phase and motion phases.
        # Every organ but the wall takes part in contact (a kinematic vessel was
        # never touched, so its damage never counted). A kinematic organ is rigid: the same
        # penalty pushes the tool and the contact counts, its anchored nodes take no force.
        deformable = [i for i, b in enumerate(self._bodies) if b.model.kind != "wall"]
        self._cell_body = np.concatenate(
            [np.full(len(self._bodies[i].cell_radii), i) for i in deformable]) \
            if deformable else np.zeros(0, dtype=np.int64)
        self._cell_centres = np.concatenate(
            [self._bodies[i].cell_centres for i in deformable]) if deformable \
            else np.zeros((0, 3))
        self._cell_r2 = (np.concatenate([self._bodies[i].cell_radii for i in deformable])
                         + self.tool.radius) ** 2 if deformable else np.zeros(0)
        for b in self._bodies:
            if always_awake and not b.kinematic:
                b.wake(0.0)
        self._warm_up()
        self._latest = self._snapshot(())

    def _warm_up(self) -> None:
        """Loads the compiled detection kernel now (from numba's disk cache; compiles it on
        the very first run) with the argument types of the stepping, so that the first
        contact costs no loading inside the physics loop (the 1 kHz kernel is loaded with the
        first ``ContactPatch``, ``vasim.abdomen.contact.load_kernels``)."""
        far = ToolPose(np.array([0.0, 0.0, 1e3]), np.array([0.0, 0.0, 1e3 - 0.01]))
        for b in self._bodies:
            if not b.kinematic:
                detect_contacts(b.state.x, b.model.faces, b.model.mass, far, self.tool,
                                dt=self.dt, max_edge=b.max_edge)
                break

    # -- queries --------------------------------------------------------------------------

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(b.model.name for b in self._bodies)

    @property
    def models(self) -> tuple[OrganModel, ...]:
        return tuple(b.model for b in self._bodies)

    @property
    def n_nodes(self) -> int:
        return sum(b.model.n_nodes for b in self._bodies)

    @property
    def latest(self) -> AbdomenSnapshot:
        """The snapshot of the last step (or of the initial state)."""
        return self._latest

    def awake(self) -> dict[str, bool]:
        return {b.model.name: b.awake for b in self._bodies}

    def faces(self, name: str) -> NDArray[np.int64]:
        """(f, 3) surface triangles of organ ``name``."""
        for b in self._bodies:
            if b.model.name == name:
                return b.model.faces
        raise KeyError(f"no organ {name!r}")

    # -- targets --------------------------------------------------------------------------

    def bind_targets(self, points: FloatArray, *, organs: Sequence[str] | None = None) -> None:
        """Binds task points to the nearest tissue (the wall excluded) at the current time.

        Args:
            points: (p, 3) target positions [m] at the current time.
            organs: restrict the binding to these organs (default: every non-wall organ).
        """
        bodies = [b for b in self._bodies if not b.kinematic
                  and (organs is None or b.model.name in organs)]
        if not bodies:
            raise ValueError("no deformable organ to bind the targets to")
        self._bound = bodies
        pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
        key = (self._key, tuple(b.model.name for b in bodies), self.t, pts.tobytes())
        with _SETTLED_LOCK:
            binding = _BINDINGS.get(key)
        if binding is None or any(b.awake for b in bodies):
            surfaces = [(b.positions(self.t), b.model.faces) for b in bodies]
            binding = bind_points(pts, surfaces)
            with _SETTLED_LOCK:
                if len(_BINDINGS) > 256:
                    _BINDINGS.clear()
                _BINDINGS[key] = binding
        self._binding = binding
        # Sleeping fast path: with the organ asleep, p = p_settled + s_b A_b + s_h c A_h,
        # c = Σ w_i w_h(X_i) (the motion field is linear in its two phase factors).
        settled = [b.settled for b in bodies]
        self._t_settled = binding.positions(settled)
        self._t_normals_settled = binding.normals(settled)
        self._t_amp_b = np.array([bodies[k].amp_b for k in binding.organ])
        self._t_amp_h = np.array([bodies[k].amp_h for k in binding.organ])
        self._t_weight_h = np.array([
            float(binding.weights[j] @ bodies[k].weight_h[binding.nodes[j]])
            for j, k in enumerate(binding.organ)])
        # Group the targets by motion phase (organs of a scene usually share one breathing
        # and one heartbeat): free(t) = P0 + Σ_groups s_b(t) B_g + s_h(t) H_g.
        groups: dict[tuple[float, float, float, float], list[int]] = {}
        for j, k in enumerate(binding.organ):
            m = bodies[k].motion
            groups.setdefault((2.0 * math.pi * m.breathing.frequency_hz, m.breathing.phase,
                               2.0 * math.pi * m.heartbeat.frequency_hz, m.heartbeat.phase),
                              []).append(j)
        self._t_groups = []
        for (wb, pb, wh, ph), rows in groups.items():
            mask = np.zeros((binding.size, 1))
            mask[rows] = 1.0
            self._t_groups.append((wb, pb, wh, ph, mask * self._t_amp_b,
                                   mask * self._t_weight_h[:, None] * self._t_amp_h))
        self._latest = self._snapshot(())

    def _targets(self) -> tuple[FloatArray, FloatArray, FloatArray]:
        binding = self._binding
        if binding is None:
            z = np.zeros((0, 3))
            return z, z.copy(), np.zeros(0)
        t = self.t
        free = self._t_settled
        for wb, pb, wh, ph, amp_b, amp_h in self._t_groups:
            free = free + math.sin(wb * t + pb) * amp_b + math.sin(wh * t + ph) * amp_h
        if not any(b.awake for b in self._bound):
            return free, self._t_normals_settled, np.zeros(binding.size)
        pos = [b.positions(self.t) for b in self._bound]
        p = binding.positions(pos)
        n = binding.normals(pos)
        return p, n, np.linalg.norm(p - free, axis=1)

    # -- stepping -------------------------------------------------------------------------

    def _contacts(self, pose: ToolPose, slot: int = 0) -> dict[int, ContactResult]:
        """Contacts of the tool at ``pose`` (instrument ``slot``) with every deformable organ
        near its axis.

        Broad phase, one compiled pass over every organ's cell spheres (see ``_Body``;
        ``vasim.abdomen._contact_kernels.cells_near``): the tool axis (fulcrum → tip) passes
        within one of them, or the organ is awake (it deforms, so its cells do not bound it;
        then its current bounding box decides).
        """
        ful = np.asarray(pose.fulcrum, dtype=np.float64)
        tip = np.asarray(pose.tip, dtype=np.float64)
        # Clearance: the cells are inflated by the organs' whole motion, so while the fulcrum
        # stays and the tip has moved less than the last clearance (no point of the shaft
        # moves more than the tip), no sleeping organ can be reached: skip the broad phase.
        last = self._clears.get(slot)
        awake = any(b.awake for b in self._bodies)
        if (last is not None and not awake and np.array_equal(last[0], ful)
                and float(np.sum((tip - last[1]) ** 2)) < last[2] ** 2):
            return {}
        near, gap = cells_near(self._cell_centres, self._cell_r2, self._cell_body,
                               len(self._bodies), writable_c(ful), writable_c(tip))
        self._clears[slot] = None if near.any() else (ful.copy(), tip.copy(), float(gap))
        out: dict[int, ContactResult] = {}
        lo = np.minimum(ful, tip) - self.tool.radius
        hi = np.maximum(ful, tip) + self.tool.radius
        for i, b in enumerate(self._bodies):
            if not (near[i] or b.awake):  # (the wall has no cells: never near)
                continue
            if b.awake and not near[i] and box_apart(b.state.x, lo, hi, b.max_edge):
                continue  # deformed, but its current bounding box is out of reach
            c = detect_contacts(b.positions(self.t), b.model.faces, b.model.mass, pose,
                                self.tool, dt=self.dt, max_edge=b.max_edge)
            if c.in_contact:
                out[i] = c
        return out

    def step(self, tool: ToolPose | Sequence[ToolPose] | Mapping[str, ToolPose] | None,
             ) -> AbdomenSnapshot:
        """Advances the abdomen by ``dt`` with the instruments at ``tool``.

        The contact forces found at the start of the step act on the tissue during it; with
        several instruments their reaction forces are summed per node (module docstring).
        A pose with a non-finite point, or one beyond :data:`POSE_LIMIT` on an axis, is an
        instrument out of the abdomen (no contact).

        Args:
            tool: one pose; a sequence of poses (instruments ``"0"``, ``"1"``, ...); a
                mapping instrument name -> pose; ``None`` or ``()``: no tool. The first
                instrument is the haptic one (the snapshot's top-level contact fields).

        Returns:
            The new snapshot (also :attr:`latest`).

        Raises:
            TypeError: an instrument's pose is not a :class:`ToolPose`.
        """
        per_tool: list[tuple[str, dict[int, ContactResult]]] = []
        for slot, (name, pose) in enumerate(_tool_poses(tool)):
            contacts: dict[int, ContactResult] = {}
            # Non-finite, or so far out that the kernel's squared lengths overflow (review
            # fix: a huge finite pose raised ValueError): out of the abdomen, no contact.
            if _in_reach(pose.tip) and _in_reach(pose.fulcrum):
                contacts = self._contacts(pose, slot)
            per_tool.append((name, contacts))
        t1 = self.t + self.dt
        step_events: list[tuple[str, str]] = []
        for i, b in enumerate(self._bodies):
            if b.kinematic:
                continue
            cs = [contacts[i] for _, contacts in per_tool if i in contacts]
            if cs and not b.awake:
                b.wake(self.t)
            if not b.awake:
                continue
            f = None
            if len(cs) == 1:
                scatter_forces(b.f_ext, cs[0].node_index, cs[0].node_force)
                f = b.f_ext
            elif cs:  # several instruments on this organ: their forces summed per node
                scatter_forces(b.f_ext, np.concatenate([c.node_index for c in cs]),
                               np.concatenate([c.node_force for c in cs]))
                f = b.f_ext
            targets = b.anchor_rest + b.anchor_motion.offsets(t1)
            report: StepReport = b.solver.step(
                b.state, targets, f, v_frame=b.frame_velocities(t1))
            b.state.t = t1
            if report.reset:  # the reason already names the organ (not twice)
                detail = report.reason or f"{b.model.name}: reset to rest"
                step_events.append(("organ_reset", detail))
                self.events.append((t1, "organ_reset", detail))
                self.n_events += 1
            self._maybe_sleep(b, bool(cs), t1)
        self.t = t1
        self.seq += 1
        self._last_contacts = tuple(per_tool)
        snap = self._snapshot(tuple(step_events))
        if len(snap.tools) <= 1:  # the single-tool path, as it always was
            self.quality.add(self.dt, force=snap.force, torque=snap.torque,
                             in_contact=snap.in_contact, delicate_contact=snap.delicate_contact,
                             target_displacement=float(snap.target_displacement.max(initial=0.0)))
        else:
            self.quality.add_instruments(
                self.dt, forces=[tc.force for tc in snap.tools],
                torques=[tc.torque for tc in snap.tools], in_contact=snap.any_contact,
                delicate_contact=snap.delicate_any,
                target_displacement=float(snap.target_displacement.max(initial=0.0)))
        self._latest = snap
        return snap

    def _maybe_sleep(self, b: _Body, touched: bool, t: float) -> None:
        if self.always_awake:
            return
        if touched:
            b.quiet_time = 0.0
            return
        b.quiet_time += self.dt
        if b.quiet_time < SLEEP_AFTER:
            return
        if float(np.abs(b.state.x - b.sleeping_x(t)).max()) > SLEEP_TOLERANCE:
            return
        v_ref = b.node_motion.velocities(t)
        if float(np.abs(b.state.v - v_ref).max()) > SLEEP_VELOCITY:
            return
        b.awake = False

    def _snapshot(self, events: tuple[tuple[str, str], ...]) -> AbdomenSnapshot:
        views = tuple((b.model.name, readonly(b.state.x[: b.model.n_surface])
                       if b.awake else None, b) for b in self._bodies)
        tools = tuple(self._tool_contact(name, contacts)
                      for name, contacts in self._last_contacts)
        first = tools[0] if tools else self._tool_contact("", {})
        p, n, disp = self._targets()
        return AbdomenSnapshot(
            t=self.t, seq=self.seq, organ_sources=views, targets=readonly(p),
            target_normals=readonly(n), target_displacement=readonly(disp),
            force=first.force, force_tip=first.force_tip, torque=first.torque,
            stiffness_tip=first.stiffness_tip, patch=first.patch, touching=first.touching,
            delicate_contact=first.delicate_contact, events=events, tools=tools)

    def _tool_contact(self, name: str, contacts: dict[int, ContactResult]) -> ToolContact:
        """One instrument's contacts with every organ, summed into its snapshot entry."""
        if len(contacts) == 1:  # one organ touched (the usual case): no sums to form
            (c,) = contacts.values()
            force, force_tip = readonly(c.force), readonly(c.force_tip)
            torque, stiff = readonly(c.torque), readonly(c.stiffness_tip)
            patch = c.patch
        elif contacts:
            cs = list(contacts.values())
            force = readonly(np.sum([c.force for c in cs], axis=0))
            force_tip = readonly(np.sum([c.force_tip for c in cs], axis=0))
            torque = readonly(np.sum([c.torque for c in cs], axis=0))
            stiff = readonly(np.sum([c.stiffness_tip for c in cs], axis=0))
            patch = ContactPatch.merge([c.patch for c in cs], self.tool.radius)
        else:
            force = force_tip = torque = _ZERO3
            stiff = _ZERO33
            patch = self._empty_patch
        touching = tuple(self._bodies[i].model.name for i in sorted(contacts))
        delicate = any(self._bodies[i].model.delicate for i in contacts)
        return ToolContact(name, force, force_tip, torque, stiff, patch, touching, delicate)


def _tool_poses(tool: ToolPose | Sequence[ToolPose] | Mapping[str, ToolPose] | None,
                ) -> tuple[tuple[str, ToolPose], ...]:
    """(name, pose) of every instrument given to :meth:`Abdomen.step`, in order."""
    if tool is None:
        return ()
    if isinstance(tool, ToolPose):
        return (("0", tool),)
    items = (tuple((str(k), v) for k, v in tool.items()) if isinstance(tool, Mapping)
             else tuple((str(i), v) for i, v in enumerate(tool)))
    for name, pose in items:
        if not isinstance(pose, ToolPose):
            raise TypeError(f"instrument {name!r}: expected a ToolPose, got "
                            f"{type(pose).__name__} {pose!r}")
    return items


def _in_reach(p: FloatArray) -> bool:
    """Every coordinate within ±POSE_LIMIT (False for NaN and infinities)."""
    return bool((np.abs(p) < POSE_LIMIT).all())


_ZERO3 = readonly(np.zeros(3))
_ZERO33 = readonly(np.zeros((3, 3)))


__all__ = [
    "MAX_EVENTS",
    "MAX_SETTLE_RESETS",
    "POSE_LIMIT",
    "SETTLE_SPEED",
    "SETTLE_TIME",
    "SLEEP_AFTER",
    "SLEEP_TOLERANCE",
    "SLEEP_VELOCITY",
    "Abdomen",
    "AbdomenSnapshot",
    "OrganView",
    "ToolContact",
    "motion_phases",
    "scene_models",
    "settled_positions",
]
