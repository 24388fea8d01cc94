"""Trials of the MRCP vs standard-teleoperation study (spec/study.md §4, spec/mrcp.md §8).

One trial carries the needle of :mod:`vasim.operator.needle` through its rings in the virtual
abdomen with the two tool robots of :mod:`vasim.mrcp.toolstation`, in one of three modes
(below). The trial is a frozen ``TeleopTrialModel`` and a ``TeleopTrialState``
(``vasim.trials.teleop_model``, as the VF engine's model and state); one 18 ms cycle runs the
named phases ``before_step`` (the clock), the mode's phases (``mrcp_operator_phase``: the
hand moves the master, ``mrcp_master_phase``: the kernel the robots,
``mrcp_events_phase``, ``mrcp_fault_phase``; StdT's one of ``stdt_carry_phase`` (carry,
hand-over), ``stdt_approach_phase``, ``stdt_close_phase``, ``stdt_release_phase``), then
``after_step``: ``path_phase`` (EM by what moved the needle), physics, ``route_phase``
(via point, ring), ``camera_phase``, the sample, and ``should_terminate``; the mode's
``mrcp_after_step`` / ``stdt_after_step`` start the next path. What a mode's operator
carries between cycles is its ``MrcpLoop`` / ``StdtLoop``. The trial's hands come from
its ``hand_factory`` (``vasim.operator.port.HandFactory``; default the scripted
person's). The modes:

* ``"stdt"`` — standard teleoperation, bimanual: each master drives one tool tip (2
  masters : 2 slaves). At every change of side the scripted operator transfers the needle
  itself: it carries the needle to the route's via point at the midline, the hand-over
  point (:func:`~vasim.operator.needle.handover_point`), brings the other tool to the pre-grasp and
  grasp points, closes that jaw, then opens the first one. Jaw placement errors, drawn
  from the operator's skill model (:mod:`vasim.operator.needle`), cause re-grasps and
  misaligned transfers.
* ``"mrcp"`` — task-oriented teleoperation (1 master : 2 slaves): the operator moves the
  needle only; the MRCP kernel (:class:`~vasim.mrcp.kernel.MRCPKernel` with the RJ, tool
  cone and CR indices) decides which robot holds it and transfers it automatically; while
  a transfer runs (TT) the master is decoupled (logged as ``clutch = 1``).
* ``"mrcp_cam"`` — MRCP plus a second master that drives the camera robot: the
  endoscope follows the needle (a narrower, closer view: ``CAMERA_ZOOM``), instead of the
  fixed wide-angle endoscope of the other modes.

The operator is the study pipeline's scripted person (:mod:`vasim.operator.scripted`, its
profile, seed and practice from the session): minimum-jerk submovements aimed at what it
sees, Fitts timing, motor and perceptual noise, tremor, learning. A hand runs
``OPERATOR_SUBSTEPS`` steps per control cycle; the station runs at the seed's 18 ms cycle
(``CYCLE_DT``); the abdomen physics at its own rate (4 ms), with both instruments and the
endoscope as its tools.

Logged (one sample per control cycle, ``vasim.records.samples`` columns): ``x`` the needle
centre (the task), ``g`` the ring it was compared with (its position that cycle: the rings
ride on the tissue), ``goal_index`` that ring's index, the tissue
contact flag (any instrument), the force and torque on the needle holder's instrument of
the latest physics step, ``clutch`` (master decoupled),
``zoom`` and ``in_view`` (needle inside the camera's view cone). The trial metrics are the
pipeline's (``vasim.records.trial_metrics``): ET = ``completion_time``, EM = ``path_l2`` (the
needle trajectory, spec/study.md §4 "length of the needle/tool trajectory"), Q =
``target_deformation`` [mm s] (the seed's Q: the rings' displacement by contacts,
integrated over time and summed over the rings, ``vasim.trials.teleop_quality``; with its
peak ``target_deformation_peak`` [mm]) and, for experiment 3, ``contact_time``,
``accumulated_force``, ``accumulated_torque`` and
``target_displacement_max``; with tissue, every Q metric is the abdomen's quality
accumulator (``TISSUE_METRICS``, decisions below). Added per trial:
``master_path_l2`` (the summed path of the operator's hands on the masters, camera hand
included), ``camera_path_l2``, ``transfers``, ``regrasps``, ``misaligned_transfers``,
``tt_time`` (time the master was decoupled), ``safety_stops``, and EM split by what
moved the needle (``EM_PARTS``): ``em_to_ring``, ``em_to_via``, ``em_transfer``.

**Decisions**:

* One needle route in every mode (issue #7 §4; :func:`~vasim.operator.needle.needle_route`):
  the operator aims at the same waypoints (the rings, and between rings on different
  sides the via point at the midline 1.5 cm above the higher ring), each reached within
  the ring radius, a ring counting only after its via point; the via point is computed
  from the rings where they are that cycle. StdT hands over at the via point; in MRCP the
  operator's one hand passes it while the kernel transfers the needle where its indices
  decide. The modes then differ only in how the needle changes hands. Before, MRCP went
  straight from ring to ring at ring height (8 mm above the loops) and StdT crossed at the
  hand-over height: in a 4-subject cohort MRCP's tool tips touched the loops in 6 of 8
  trials and StdT's in 1 of 8, which was the route's doing, not the mode's. Each reached
  waypoint is in ``route_log`` and, for via points, a ``"route"`` event with its position.
* One path of the scripted hand per waypoint, in every mode (issue #21 §1): when the
  needle reaches a waypoint, the hand starts a new path toward the next one. Before, MRCP's
  hand was one scripted path through the whole route, and the scripted operator's
  *anticipation* (it starts toward the next point once it believes the current one
  reached) sent the needle 30-50 mm on toward the next via point whenever its perceived
  position was within the ring radius but the needle was not; it came back after its miss
  detection. That alone made MRCP's needle path 22 % longer than StdT's in the issue's
  cohort, the opposite of the seed. Measured per part of the path (``em_to_ring``,
  ``em_to_via``, ``em_transfer``, seed 1, no tissue): MRCP to-ring legs were 206, 204, 192
  mm for 67, 70, 60 mm of straight distance (StdT: 87, 125, 117 mm), and the kernel's
  transfers moved the needle 0 mm (it is held in TT; its master increments are dropped,
  22 mm in 30 TT cycles, and the kernel followed the master's TOp increments to 3 mm in 1.37 m).
  With one path per waypoint MRCP's path is StdT's within ±7 % (seeds 1-3: 1.06 / 1.01,
  0.95 / 0.96, 1.02 / 0.95 m): the station and the kernel do not lengthen it, and the
  threading task is done as the seed's subjects did it, one target at a time. What
  remains of the seed's EM difference is not the station's (a person's penalty, if any,
  is a declared assumption: ``vasim.operator.teleop_profile``).
* The person in the modes (issue #21 §2): every hand's profile is the trial's
  ``vasim.operator.teleop_profile.teleop_adjustment`` of the mode and its practice
  (``config.mode_practice``, else ``config.practice``): carries to a ring use its
  ``carry`` profile (the threading time), every other movement its ``handover`` one, and
  StdT's jaw placement error follows the handover profile's perception. The penalties
  are a declared teleoperation scenario's (``config.mode_effects``, from the session's
  ``[teleop]`` scenario); without one they are ``NEUTRAL``: the scripted operator as it
  is, the mechanism alone (issue #25 item 6).
* Every instrument in the abdomen is in the contact model (issue #7 §4): each physics
  step gets the two tools (trocar to tool tip, ``"right"`` and ``"left"``) and the
  endoscope (camera trocar to lens, the same 2.5 mm capsule as the tools: the abdomen has
  one tool shape), in that fixed order. Q is the abdomen's quality accumulator, at the
  physics rate: contact time while any instrument touches tissue, force and torque as the
  per-step sums of the instruments' magnitudes, delicate contacts by any instrument
  (``vasim.abdomen.quality``). A sample row holds one force vector, so the samples cannot
  carry that sum: they log the contact flag of any instrument and the force and torque on
  the needle holder's instrument, and the trial metrics ``TISSUE_METRICS`` are replaced by
  the accumulator's (``excessive_force_*`` stay the samples', the holder's). Before, only
  the needle holder was in the contact model, and StdT's free instrument, which approaches
  the needle near the tissue at every hand-over, touched tissue uncounted.
* The StdT operator plans each phase (carry to a ring, carry to the hand-over point,
  approach and grasp) as a new path of the scripted operator starting at rest, as a person
  pauses between a gripper action and the next movement; gripper actions take the
  reaction delay plus ``GRIPPER_TIME``.
* An MRCP safety stop (the kernel's FAULT: RSel would collide) freezes the operator's
  hand; after the reaction delay plus ``FAULT_ACK_TIME`` the operator acknowledges it
  (``MRCPKernel.reset_fault``) and starts a new movement; more than ``MAX_SAFETY_STOPS``
  end the trial. Repeated kernel events ("rsel_hold" on consecutive cycles, "fault: no
  motion") are counted, not logged one by one.
* MRCP kernel settings for this station: guidance step ``ΔR_max`` = 2 mm per cycle
  (0.11 m/s at the tool tip, a laparoscopic pace; the default 1 cm per cycle makes the
  mount move faster than the joints allow and breaks the fulcrum constraint), transfer
  speed 0.1 m/s, repulsion influence ``REPULSION_INFLUENCE`` = 3 cm, and NTT threshold
  ``NTT_THRESHOLD`` = 2 (the spec's default is 0.9; it is configurable): a transfer starts
  once RSel's remaining
  useful time covers only half of the transfer. With the short prediction horizon the
  cone index of a fast-moving needle is extrapolated to zero early, and at 0.9 the kernel
  handed the needle over before the midline, to a robot outside its own cone, which handed
  it straight back; the crossed instruments then ended in safety stops. Measured on the
  16 MRCP trials of a 4-subject simulated cohort (rings on the breathing tissue): at 0.9,
  7.9 transfers per trial for 5 needed, 7 safety stops, one trial stalled; at 2.0, 6.1
  transfers, no safety stop, every trial completed. Only ``rj`` and ``cone`` are
  evaluated: ``cr``, normalised across the robots, fell for the holder whenever the idle
  instrument stayed near the needle after a hand-over and triggered transfers back.
  The influence was 5 cm until the shared route: the idle instrument, tracking its
  pre-grasp pose, stops at its cone's edge near the midline at about the via height, so
  the needle coming back to the next via point drives the holder's shaft at it; at 5 cm
  the repulsion pushed it sideways and round behind the holder, its transfer timed out
  and RSel ran into it (safety stops): 3 of 6 MRCP trials (intermediate operator, tissue,
  seeds 1-5 and one test seed) ended in repeated safety stops; at 3 cm 12 of 12
  completed (seeds 1-11 and that one), none stopped.
* Camera: in ``stdt`` and ``mrcp`` the endoscope stays aimed at the centroid of the rings
  with the 100 deg field of view of the study's fixed endoscope
  (``vasim.trials.endoscope.DEFAULT_ENDOSCOPE``, whose own aim, the trajectory workspace, lies
  above this task). The camera hand of ``mrcp_cam`` re-aims only when the needle leaves
  the central third of its 70 deg view (a dead zone), then follows it with a 0.4 s time
  constant; its path is the aim point's.

Example:
    >>> from vasim.trials.teleop_config import TeleopTrialConfig
    >>> res = TeleopTrial(TeleopTrialConfig(mode="mrcp", seed=1, max_time=0.5, scene="none"),
    ...                   n_rings=2).run()
    >>> res.summary["mode"], float(res.samples.view()["t"][0])
    ('mrcp', 0.018)
"""

from __future__ import annotations

import math
import time
from collections.abc import Iterator
from typing import TYPE_CHECKING

import numpy as np

from vasim.core.geometry import vector_norm
from vasim.mrcp.kernel import CycleRecord, IndexSpec, KernelConfig, MRCPKernel, TaskPoint
from vasim.mrcp.modes import KernelState
from vasim.mrcp.planner import PlannerParams
from vasim.mrcp.toolstation import CameraRobot, Station, build_station
from vasim.operator.needle import (
    NeedleTask,
    Side,
    classify_grasp,
    grasp_offset,
    grasp_sigma,
    handover_point,
    lateral_error,
    needs_via,
    pregrasp_offset,
)
from vasim.operator.port import HandFactory, HandRequest, MasterHand
from vasim.operator.profile import OperatorProfile
from vasim.operator.teleop_profile import TeleopAdjustment, TeleopEffects
from vasim.records.point_metrics import evaluate_trial
from vasim.records.trial_metrics import MetricParams, trial_metrics
from vasim.trials.endoscope import DEFAULT_ENDOSCOPE
from vasim.trials.teleop_config import TeleopTrialConfig
from vasim.trials.teleop_hands import CAMERA_FOV_DEG, CAMERA_ZOOM, Camera, ScriptedHands
from vasim.trials.teleop_model import (
    CYCLE_DT,
    MrcpLoop,
    StdtLoop,
    TeleopTrialModel,
    TeleopTrialState,
)
from vasim.trials.teleop_quality import TargetDeformation
from vasim.trials.vf import TrialResult

if TYPE_CHECKING:
    from vasim.abdomen.contact import ToolPose
    from vasim.abdomen.snapshot import AbdomenSnapshot
    from vasim.abdomen.world import Abdomen

OPERATOR_SUBSTEPS = 3
"""Steps of the scripted hands per control cycle (6 ms each)."""

GRIPPER_TIME = 0.25
"""Duration of closing or opening a jaw once decided [s] (plus the reaction delay)."""

PREGRASP_REACH = 0.005
"""The operator judges the jaw at the pre-grasp point within this distance [m]."""

GRASP_REACH = 0.003
"""... and at the grasp point within this distance, then closes it [m]."""

MAX_GRASP_ATTEMPTS = 5
"""After this many misses the next closing holds the needle (misaligned at worst)."""

FAULT_ACK_TIME = 1.0
"""After an MRCP safety stop (RSel collision) the operator acknowledges it this long after
the reaction delay [s] and starts a new movement."""

MAX_SAFETY_STOPS = 5
"""A trial with more safety stops than this is ended (not completed)."""

NTT_THRESHOLD = 2.0
"""The kernel starts a transfer when NTT >= this (module docstring, decisions)."""

REPULSION_INFLUENCE = 0.03
"""Influence distance of the MRCP planner's repulsion at this station [m] (module
docstring, decisions: 3 cm since the shared needle route)."""

TISSUE_METRICS = {
    "contact_time": "contact_time", "contact_count": "contact_count",
    "accumulated_force": "force_integral", "accumulated_torque": "torque_integral",
    "max_force": "max_force", "delicate_contact_time": "delicate_time",
    "delicate_contact_count": "delicate_count"}
"""Trial metric -> the abdomen's quality field replacing it in a trial with tissue."""


def _seed(seed: int, *key: int) -> int:
    return int(np.random.SeedSequence([int(seed), *key]).generate_state(1)[0])


def kernel_config(station: Station, seed: int = 0) -> KernelConfig:
    """The MRCP kernel settings of the study station (module docstring, decisions)."""
    return KernelConfig(
        dt=CYCLE_DT, seed=seed % 2**32, default_tcp_speed=0.1, ntt_threshold=NTT_THRESHOLD,
        planner=PlannerParams(dr_max=0.002, influence=REPULSION_INFLUENCE),
        indices=(IndexSpec("rj"), IndexSpec("cone", {"cones": dict(station.cones)})))


def needle_points() -> list[TaskPoint]:
    """The needle's grasp points (right instrument: 0, left: 1) in the needle frame."""
    return [TaskPoint(grasp_offset(s), approach=pregrasp_offset(s) - grasp_offset(s))
            for s in ("right", "left")]


class TeleopTrial:
    """One trial of a teleoperation mode (module docstring).

    Args:
        config: the trial; ``config.mode`` names the mode.
        n_rings: rings of the needle task (default: all of ``RING_SITES``); their pass
            radius is ``config.reach_radius`` (the protocol's), else ``RING_RADIUS``.
        abdomen: a fresh abdomen to use (of ``config.scene``; it accumulates this trial's
            quality metrics); default: a new one (``config.scene == "none"``: no tissue,
            static rings).
        holder: the tool holder of the station (``build_station``).
        effects: the operator's mode penalties (``vasim.operator.teleop_profile``);
            None: ``config.mode_effects`` (a session's declared teleoperation scenario),
            else ``NEUTRAL`` (the mechanism alone).
        hand_factory: makes the hand of each new path (``vasim.operator.port.HandFactory``:
            it gets a ``HandRequest``, the path's goals, start, reach, seed and whether the
            needle is carried to a ring); None: the scripted person's
            (``teleop_hands.ScriptedHands`` of the model's profiles). The viewer's
            person-driven trials pass hands that read the page's device.
    """

    def __init__(self, config: TeleopTrialConfig, *, n_rings: int | None = None,
                 abdomen: Abdomen | None = None, holder: str = "positioner",
                 effects: TeleopEffects | None = None,
                 hand_factory: HandFactory | None = None) -> None:
        self.model = model = TeleopTrialModel.build(config, n_rings, effects)
        self.hand_factory: HandFactory = (
            hand_factory if hand_factory is not None
            else ScriptedHands(model.adjustment, model.task, config.practice))
        """Where the trial's hands come from (the operator hook; ``__init__``)."""
        self.rng = np.random.default_rng(_seed(config.seed, 41))
        self.station = build_station({"right": model.task.start + grasp_offset("right")},
                                     holder=holder)
        self.abdomen = abdomen
        if self.abdomen is None and config.scene != "none":
            from vasim.abdomen.world import Abdomen

            self.abdomen = Abdomen(config.scene)
        snap: AbdomenSnapshot | None = None
        if self.abdomen is not None:
            from vasim.abdomen.quality import TissueQuality

            self.abdomen.quality = TissueQuality()    # this trial's Q from its start
            self.abdomen.bind_targets(model.task.rings)
            snap = self.abdomen.latest
        follows = model.mode == "mrcp_cam"
        cam = CameraRobot(self.station.camera.fulcrum, fov_deg=CAMERA_FOV_DEG if follows
                          else DEFAULT_ENDOSCOPE.fov_deg)
        self.camera = Camera(cam, model.task.start.copy() if follows
                             else model.task.rings.mean(axis=0), follows)
        self.deformation = TargetDeformation()
        """Q as the seed measures it (``vasim.trials.teleop_quality``)."""
        self.state = TeleopTrialState.initial(model, snap)

    # -- the model's parts, as attributes of the trial -----------------------------------
    @property
    def config(self) -> TeleopTrialConfig:
        return self.model.config

    @property
    def mode(self) -> str:
        return self.model.mode

    @property
    def task(self) -> NeedleTask:
        return self.model.task

    @property
    def profile(self) -> OperatorProfile:
        return self.model.profile

    @property
    def effects(self) -> TeleopEffects:
        return self.model.effects

    @property
    def adjustment(self) -> TeleopAdjustment:
        """The hands' profiles of this mode and mode practice (``teleop_profile``)."""
        return self.model.adjustment

    @property
    def dt(self) -> float:
        return self.model.dt

    # -- shared pieces ---------------------------------------------------------------
    def _hand(self, points: np.ndarray, start: np.ndarray, reach: float | tuple[float, ...],
              key: int, *, carry: bool = False) -> MasterHand:
        """A new path of a hand, from the trial's ``hand_factory``; ``carry``: the needle
        is carried to a ring (the threading movement, ``vasim.operator.teleop_profile``)."""
        return self.hand_factory(HandRequest(points, start, reach,
                                             _seed(self.config.seed, 43, key), carry))

    def instruments(self) -> dict[str, ToolPose]:
        """Every instrument in the abdomen now: ``"right"``, ``"left"`` (trocar to tool tip)
        and ``"camera"`` (camera trocar to lens), in this order (module docstring)."""
        from vasim.abdomen.contact import ToolPose

        st = self.station
        poses = {side: ToolPose(st.arms[side].fulcrum.point, st.tip(side))
                 for side in ("right", "left")}
        cam = self.camera.robot
        poses["camera"] = ToolPose(cam.fulcrum, cam.lens(self.camera.aim))
        return poses

    def _physics(self) -> None:
        """Steps the abdomen up to the current time with every instrument as its tools."""
        ts = self.state
        ab = self.abdomen
        if ab is None:
            return
        tools = self.instruments()
        while ab.t + 0.5 * ab.dt <= ts.t:
            ts.snap = ab.step(tools)
            self.deformation.add(ab.dt, ts.snap.target_displacement)
            for kind, detail in ts.snap.events:
                ts.events.append((ts.snap.t, kind, detail))
        if ts.snap is not None:
            ts.rings = np.array(ts.snap.targets)

    def _goal(self) -> np.ndarray:
        return self.state.rings[min(self.state.i, self.task.n_rings - 1)]

    def _waypoint(self) -> np.ndarray:
        """The next waypoint of the needle route (``needle_route``; the same in every
        mode): the via point before ring ``i`` (from the rings where they are now), or
        ring ``i``."""
        ts = self.state
        if ts.via:
            return handover_point(ts.rings[ts.i - 1], ts.rings[ts.i])
        return self._goal()

    def _check_via(self) -> bool:
        """Marks the via point reached when the needle is within the ring radius of it."""
        ts = self.state
        w = self._waypoint()
        if ts.via and vector_norm(ts.needle - w) <= self.task.ring_radius:
            ts.via = False
            ts.route_j += 1
            ts.route_log.append((-1, ts.t, w.copy(), ts.needle.copy()))
            ts.events.append((ts.t, "route", f"via point {ts.i - 1}->{ts.i} "
                              f"({ts.holder}) at " + ", ".join(
                                  f"{1e3 * v:.2f}" for v in w) + " mm"))
            return True
        return False

    def _check_ring(self) -> None:
        ts = self.state
        if ts.i < self.task.n_rings and not ts.via and vector_norm(
                ts.needle - self._goal()) <= self.task.ring_radius:
            ts.reach_times.append(ts.t)
            ts.route_log.append((ts.i, ts.t, self._goal().copy(), ts.needle.copy()))
            ts.events.append((ts.t, "ring", f"ring {ts.i} passed ({ts.holder})"))
            ts.i += 1
            ts.route_j += 1
            ts.via = needs_via(self.task.sides, ts.i)

    def _log(self, g: np.ndarray, i: int) -> None:
        ts = self.state
        snap = ts.snap
        view = 1 if self.camera.contains(ts.needle) else 0
        if snap is not None and snap.any_contact:
            held = snap.tool(ts.holder)
            ts.samples.append(ts.k, ts.t, ts.needle, g, i, None, None,
                              self.camera.zoom, 0.0, 0.0, 0.0, 1, held.force, held.torque,
                              1 if snap.delicate_any else 0, ts.clutch, view)
        else:
            ts.samples.append(ts.k, ts.t, ts.needle, g, i, None, None,
                              self.camera.zoom, 0.0, 0.0, 0.0, 0, None, None, 0,
                              ts.clutch, view)

    # -- the phases of a cycle (module docstring) ----------------------------------------
    def before_step(self) -> None:
        """The clock: k += 1, t = (k + 1) dt."""
        st = self.state
        st.k += 1
        st.t = (st.k + 1) * self.dt

    def after_step(self) -> None:
        """The cycle's common phases after the mode's operator and master phases: the
        needle's path, physics, the route (via point, ring), the camera hand, the sample
        (with the ring it was compared with: the goal advances after the row, as in
        ``vasim.trials.vf``), then ``done = should_terminate()``."""
        self.path_phase()
        self._physics()
        g, i = self._goal().copy(), self.state.i
        self.route_phase()
        self.camera_phase()
        self._log(g, i)
        self.state.done = self.should_terminate()

    def path_phase(self) -> None:
        """The needle's path of this cycle, by what moved it (``EM_PARTS``)."""
        st = self.state
        part = "transfer" if st.transferring else "to_via" if st.via else "to_ring"
        st.em_parts[part] += vector_norm(st.needle - st.em_from)
        st.em_from = st.needle.copy()

    def route_phase(self) -> None:
        """The route's tests: the via point, then the ring."""
        self._check_via()
        self._check_ring()

    def camera_phase(self) -> None:
        """The camera hand follows the needle (``mrcp_cam``; the others stay aimed)."""
        self.camera.follow(self.state.needle, self.dt)

    def should_terminate(self) -> bool:
        """Every ring passed, or the time limit."""
        return (self.state.i >= self.task.n_rings
                or self.state.t >= self.config.max_time - 1e-12)

    # -- the modes -------------------------------------------------------------------
    def run(self) -> TrialResult:
        """Runs the trial to the end (all rings passed or ``max_time``)."""
        t0 = time.perf_counter()
        for _ in self.cycles():
            pass
        return self.result(wall_time=time.perf_counter() - t0)

    def cycles(self) -> Iterator[int]:
        """Runs the trial cycle by cycle, yielding the cycle index after each."""
        loop = self._stdt() if self.mode == "stdt" else self._mrcp()
        yield from loop

    def _mrcp(self) -> Iterator[int]:
        """The ``mrcp`` modes' cycles: the operator moves the master, the kernel the
        robots, then the safety stop and the common phases."""
        ts = self.state
        m = self.mrcp_begin()
        while not ts.done:
            self.before_step()
            self.mrcp_operator_phase(m)
            rec = self.mrcp_master_phase(m)
            self.mrcp_events_phase(m, rec)
            if self.mrcp_fault_phase(m, rec):      # too many safety stops: the end
                self.after_step()
                ts.done = True
                yield ts.k
                break
            self.mrcp_after_step(m)
            yield ts.k
        ts.master_path += self.camera.path

    def mrcp_begin(self) -> MrcpLoop:
        """The kernel, the master at the needle, the first path's hand."""
        ts, st = self.state, self.station
        kernel = MRCPKernel(st.arms, st.world, needle_points(), "right", 0, ts.needle,
                            config=kernel_config(st, self.config.seed))
        return MrcpLoop(kernel, ts.needle.copy(), self._mrcp_hand(0))

    def _mrcp_hand(self, key: int) -> MasterHand:
        """A new path of the one hand, to the route's next waypoint."""
        ts = self.state
        return self._hand(self._waypoint()[None, :], ts.needle, self.task.ring_radius, key,
                          carry=not ts.via)

    def mrcp_operator_phase(self, m: MrcpLoop) -> None:
        """The hand moves the master (not while the kernel is stopped by a fault)."""
        ts = self.state
        if m.kernel.state is KernelState.FAULT:
            return
        dt_op = self.dt / OPERATOR_SUBSTEPS
        for _ in range(OPERATOR_SUBSTEPS):
            dx = m.hand.move(dt_op, ts.needle, self._waypoint(), self.camera.zoom)
            m.master = m.master + dx
            ts.master_path += vector_norm(dx)

    def mrcp_master_phase(self, m: MrcpLoop) -> CycleRecord:
        """The kernel applies the master's increments: the needle, its holder, the clutch
        (decoupled but in TOp) and the transfer time."""
        ts = self.state
        rec = m.kernel.step(ts.t, m.master)
        ts.needle = m.kernel.task_pose()[0]
        ts.holder = "right" if m.kernel.rsel == "right" else "left"
        ts.clutch = 0 if rec.state is KernelState.TOP else 1
        ts.transferring = rec.state.mode == "TT"
        if ts.clutch:
            ts.tt_time += self.dt
        return rec

    def mrcp_events_phase(self, m: MrcpLoop, rec: CycleRecord) -> None:
        """The kernel's events counted, and logged but for repeats (module docstring)."""
        ts = self.state
        hold_now = False
        for e in rec.events:
            kind = e.split(" ", 1)[0]
            if kind == "transfer_done":
                ts.counts["transfers"] += 1
            elif kind == "transfer_abort":
                ts.counts["transfer_aborts"] += 1
            elif kind == "rsel_hold":
                ts.counts["rsel_holds"] += 1
                hold_now = True
                if m.holding:
                    continue               # one event per run of held cycles
            elif kind == "fault:":
                continue                   # "fault: no motion", every stopped cycle
            ts.events.append((ts.t, "mrcp", e))
        m.holding = hold_now

    def mrcp_fault_phase(self, m: MrcpLoop, rec: CycleRecord) -> bool:
        """A safety stop: counted when it happens, acknowledged after the reaction delay
        plus ``FAULT_ACK_TIME`` (a new movement); True when there were too many (the trial
        is aborted)."""
        ts = self.state
        if rec.state is not KernelState.FAULT:
            return False
        if m.ack <= 0.0:                       # the stop has just happened
            ts.counts["safety_stops"] += 1
            m.ack = self.profile.reaction_delay + FAULT_ACK_TIME
            if ts.counts["safety_stops"] > MAX_SAFETY_STOPS:
                ts.events.append((ts.t, "aborted", "repeated safety stops"))
                return True
            return False
        m.ack -= self.dt
        if m.ack <= 0.0:                       # acknowledged: resume, a new movement
            m.kernel.reset_fault()
            ts.events.append((ts.t, "mrcp", "safety stop acknowledged"))
            m.key += 1
            m.hand = self._mrcp_hand(m.key)
        return False

    def mrcp_after_step(self, m: MrcpLoop) -> None:
        """The common phases (``after_step``); a waypoint reached: a new path."""
        ts = self.state
        before = ts.route_j
        self.after_step()
        if ts.route_j != before and not ts.done:
            m.key += 1
            m.hand = self._mrcp_hand(m.key)

    def _stdt(self) -> Iterator[int]:
        """The ``stdt`` cycles: the operator's phase (carry or hand-over, approach, close,
        release), then the common phases and what follows a ring."""
        ts = self.state
        s = self.stdt_begin()
        phases = {"carry": self.stdt_carry_phase, "handover": self.stdt_carry_phase,
                  "approach": self.stdt_approach_phase, "close": self.stdt_close_phase,
                  "release": self.stdt_release_phase}
        while not ts.done:
            self.before_step()
            phases[s.phase](s)
            self.stdt_after_step(s)
            yield ts.k

    def stdt_begin(self) -> StdtLoop:
        """The right instrument holds the needle and carries it to the first ring."""
        ts = self.state
        return StdtLoop(
            hand=self._hand(ts.rings[:1], ts.needle, self.task.ring_radius, 0, carry=True),
            offset=ts.needle - self.station.tip(ts.holder),
            sigma=grasp_sigma(self.adjustment.handover, self.config.practice),
            delay=self.profile.reaction_delay + GRIPPER_TIME)

    def _stdt_hand_step(self, s: StdtLoop, moved: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """The hand's increment over one cycle's substeps, ``moved`` where it starts."""
        dt_op = self.dt / OPERATOR_SUBSTEPS
        dx = np.zeros(3)
        for _ in range(OPERATOR_SUBSTEPS):
            dx = dx + s.hand.move(dt_op, moved + dx, goal, self.camera.zoom)
        return dx

    def stdt_carry_phase(self, s: StdtLoop) -> None:
        """The holder carries the needle to the next waypoint; at the hand-over point the
        free instrument starts its approach."""
        ts = self.state
        dx = self._stdt_hand_step(s, ts.needle, self._waypoint())
        self._move_tool(ts.holder, dx)
        ts.needle = self.station.tip(ts.holder) + s.offset
        self._check_via()
        if s.phase == "handover" and not ts.via:
            s.phase, s.attempts = "approach", 0
            ts.events.append((ts.t, "stdt", f"at hand-over point; {s.other} approaches"))
            s.key += 1
            s.hand = self._approach_hand(s.other, s.key)

    def stdt_approach_phase(self, s: StdtLoop) -> None:
        """The free instrument to the pre-grasp, then the grasp point; there its jaw
        closes."""
        ts, st, other = self.state, self.station, s.other
        goal = ts.needle + (pregrasp_offset(other) if s.hand.j == 0
                            else grasp_offset(other))
        dx = self._stdt_hand_step(s, st.tip(other), goal)
        self._move_tool(other, dx)
        s.hand.check(st.tip(other), goal)
        if s.hand.done:
            s.phase, s.wait = "close", s.delay
            ts.events.append((ts.t, "stdt", f"{other} closes its jaw"))

    def stdt_close_phase(self, s: StdtLoop) -> None:
        """The jaw closes after the gripper delay: a miss is a re-grasp (up to
        ``MAX_GRASP_ATTEMPTS``), a grasp off the point a misaligned transfer."""
        ts, other = self.state, s.other
        s.wait -= self.dt
        if s.wait > 0.0:
            return
        s.attempts += 1
        # across the needle: where the tip is, plus the misjudgement
        error = self.station.tip(other) - (ts.needle + grasp_offset(other))
        error = error * np.array([0.0, 1.0, 1.0]) + lateral_error(self.rng, s.sigma)
        miss = vector_norm(error)
        outcome = classify_grasp(miss)
        if outcome == "missed" and s.attempts < MAX_GRASP_ATTEMPTS:
            ts.counts["regrasps"] += 1
            ts.events.append((ts.t, "regrasp",
                              f"{other} missed the needle by {1e3 * miss:.1f} mm"))
            s.key += 1
            s.hand = self._approach_hand(other, s.key)
            s.phase = "approach"
            return
        if outcome != "clean":
            ts.counts["misaligned_transfers"] += 1
            ts.events.append((ts.t, "misaligned_transfer",
                              f"{other} grasped {1e3 * miss:.1f} mm off the grasp point"))
        ts.needle = ts.needle + error     # the closing jaw drags it
        s.phase, s.wait = "release", s.delay

    def stdt_release_phase(self, s: StdtLoop) -> None:
        """The first jaw opens after the gripper delay: the other instrument holds the
        needle and carries it to the ring."""
        ts = self.state
        s.wait -= self.dt
        if s.wait > 0.0:
            return
        ts.counts["transfers"] += 1
        ts.events.append((ts.t, "transfer", f"{ts.holder} -> {s.other}"))
        ts.holder, s.other = s.other, ts.holder
        s.offset = ts.needle - self.station.tip(ts.holder)
        s.key += 1
        s.hand = self._hand(self._goal()[None, :], ts.needle, self.task.ring_radius, s.key,
                            carry=True)
        s.phase = "carry"

    def stdt_after_step(self, s: StdtLoop) -> None:
        """The common phases (``after_step``); a ring passed: a hand-over to the via point
        when the next ring is on the other side, else a carry to it."""
        ts = self.state
        before = ts.i
        ts.transferring = s.phase in ("approach", "close", "release")
        self.after_step()
        if ts.i == before or ts.done:
            return
        s.key += 1
        if self.task.sides[ts.i] != ts.holder:
            # the route's via point (needle_route) is the hand-over point
            s.hand = self._hand(self._waypoint()[None, :], ts.needle,
                                self.task.ring_radius, s.key)
            s.phase = "handover"
        else:
            s.hand = self._hand(self._goal()[None, :], ts.needle, self.task.ring_radius,
                                s.key, carry=True)
            s.phase = "carry"

    def _approach_hand(self, side: Side, key: int) -> MasterHand:
        needle = self.state.needle
        pts = np.array([needle + pregrasp_offset(side), needle + grasp_offset(side)])
        return self._hand(pts, self.station.tip(side), (PREGRASP_REACH, GRASP_REACH), key)

    def _move_tool(self, side: Side, dx: np.ndarray) -> None:
        """A master increment moves its tool tip (IK through the fulcrum; held if none)."""
        st = self.station
        arm = st.arms[side]
        q = st.world.configuration(side)
        self.state.master_path += vector_norm(dx)
        sol = arm.ik(st.tip(side) + dx, None, q)
        if sol is None:
            self.state.counts["tool_holds"] += 1
            return
        st.world.set_configuration(side, sol)

    # -- result ----------------------------------------------------------------------
    def result(self, wall_time: float = 0.0, *,
               metric_params: MetricParams | None = None) -> TrialResult:
        """Samples, per-ring metrics, summary and trial metrics (module docstring)."""
        ts = self.state
        from vasim.fixtures.schema import load_schema

        view = ts.samples.view()
        n = self.task.n_rings
        metrics, summary = evaluate_trial(
            view["t"], view["x"], view["g"], view["goal_index"], self.task.rings,
            r_reach=self.task.ring_radius,
            t_reached=ts.reach_times + [math.nan] * (n - len(ts.reach_times)))
        summary.update({
            "finished": bool(ts.i >= n), "sim_time": ts.t, "steps": ts.k + 1,
            # how it ended (TRIAL_OUTCOMES): an abort for repeated safety stops failed it
            "outcome": ("reached_all" if ts.i >= n else "failed"
                        if any(e[1] == "aborted" for e in ts.events) else "timed_out"
                        if ts.t >= self.config.max_time - 1e-12 else "stopped"),
            "schema": "none", "active_fixtures": "", "nonfinite_inputs": 0,
            "scene": self.config.scene, "mode": self.mode, "task": "needle",
            "n_rings": n, "n_transfers_needed": self.task.n_transfers,
            "mode_practice": self.adjustment.mode_practice,
            "teleop_effects": (f"thread_time={self.effects.thread_time} stdt_noise="
                               f"{self.effects.stdt_noise} camera_cost="
                               f"{self.effects.camera_cost}"),
            **{k: int(v) for k, v in ts.counts.items()},
        })
        if self.abdomen is not None:
            summary.update({f"tissue_{k}": v
                            for k, v in self.abdomen.quality.as_dict().items()})
        tm = trial_metrics(view, summary=summary,
                           params=metric_params if metric_params is not None else MetricParams())
        if self.abdomen is not None:   # Q over every instrument (module docstring)
            quality = self.abdomen.quality.as_dict()
            tm.update({k: float(quality[v]) for k, v in TISSUE_METRICS.items()})
        tm.update({"master_path_l2": ts.master_path, "camera_path_l2": self.camera.path,
                   "transfers": float(ts.counts["transfers"]),
                   "regrasps": float(ts.counts["regrasps"]),
                   "misaligned_transfers": float(ts.counts["misaligned_transfers"]),
                   "safety_stops": float(ts.counts["safety_stops"]),
                   "tt_time": ts.tt_time,
                   **{f"em_{k}": v for k, v in ts.em_parts.items()}})
        if self.abdomen is not None:
            tm.update(self.deformation.as_metrics())
        return TrialResult(config=self.config, schema=load_schema("none"),
                           task=self.task.operator_task(self.task.rings, self.task.start),
                           samples=ts.samples, metrics=metrics, summary=summary,
                           events=list(ts.events), wall_time=wall_time, trial_metrics=tm)


__all__ = [
    "CAMERA_FOV_DEG",
    "CAMERA_ZOOM",
    "CYCLE_DT",
    "GRIPPER_TIME",
    "OPERATOR_SUBSTEPS",
    "REPULSION_INFLUENCE",
    "TISSUE_METRICS",
    "TeleopTrial",
    "kernel_config",
    "needle_points",
]
