"""The MRCP control kernel's parameters (:class:`KernelConfig`) and the indices it evaluates
(:class:`IndexSpec`); the kernel itself is :mod:`vasim.mrcp.kernel`, which re-exports both.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from vasim.mrcp.indices import INDICES
from vasim.mrcp.planner import PlannerParams


@dataclass(frozen=True)
class IndexSpec:
    """An index of the registry by name, with its keyword parameters."""

    name: str
    params: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class KernelConfig:
    """Parameters of the control kernel (SI units).

    Attributes:
        dt: evaluation period [s] (the seed's hardware: 18 ms).
        horizon: ``K`` predicted points.
        stride: cycles between predicted points.
        window: samples of the task trajectory used by the predictor.
        texec_window: samples of each index used to fit ``texec``.
        texec_degree: polynomial degree of that fit.
        texec_min_samples: a series shorter than this gives ``t_max`` (**decision**: a fit
            through a handful of samples extrapolates noise over the whole window).
        t_max: the confidence window of ``texec`` [s].
        ntt_threshold: start a transfer when ``NTT >= ntt_threshold``.
        max_tcp_speed: robot name -> maximum TCP speed [m/s] (``default_tcp_speed`` else).
        ttc_samples: joint samples along a transfer line for TTC (ends included).
        trajectory_ik: ``"exact"`` (IK at every predicted point) or ``"linear"``
            (**decision**, an option for arms with costly IK: IK at the current point, then
            first-order steps ``q + J⁺ Δx`` along the prediction; a step leaving the joint
            limits makes the point unreachable).
        distance_points: ``"all"`` or ``"ends"``: where along the trajectory the world's
            distance queries are made (:class:`~vasim.mrcp.indices.EvalContext`).
        batch_ik: make the first IK attempt of every (robot, point) trajectory in one
            compiled call per cycle for arms that describe it (``first_attempt()``,
            :mod:`vasim.mrcp.batch_ik`); False: one ``arm.ik`` call per point. The same
            configurations either way (a cost option, for comparisons).
        batch_distances: the evaluation's distance queries of every robot in one call
            (the world's ``nearest_distances_many`` / ``min_distances_many``, one compiled
            call per cycle and robot model,
            :func:`~vasim.mrcp.indices.base.prefetch_distances_all`); False: one
            ``min_distances`` call per robot. The same values either way (a cost option,
            for comparisons).
        batch_indices: an index with ``evaluate_many(contexts)`` (Θ: one compiled call
            for every robot's Jacobians) evaluates all of a cycle's (robot, point)
            contexts in one call; False: ``evaluate`` per context. The same values either
            way (a cost option, for comparisons).
        planner: action planner parameters.
        indices: the indices evaluated each cycle.
        grasp_tolerance: RCnt is at a (pre-)grasp pose within this distance [m].
        grasp_cycles: cycles both robots hold the task before RSel releases.
        tt_timeout: a transfer not done within it is aborted [s].
        abort_cooldown: after an aborted transfer, that (robot, point) is not chosen as
            RCnt again for this long [s] (**decision**: otherwise the same blocked transfer
            would restart at once and keep the operator's input held).
        seed: seed of the planner's random force.
        hold_transfer_s: RSel that could not follow the operator (``rsel_hold``: the task
            pose unreachable, beyond its joint speed, or blocked by a robot that does not
            hold the task) for this long has no time left
            (``texec`` 0, cause ``hold``), so a candidate that can take the task over does
            [s] (**decision**, issue #26 §4: the predictor extrapolates the *achieved* task
            pose, which a held task does not change, so RSel's indices alone kept it
            holding a task it could not move: 11 s in ``eight_robots``); ``inf``: off.
    """

    dt: float = 0.018
    horizon: int = 3
    stride: int = 3
    window: int = 12
    predictor_degree: int = 2
    texec_window: int = 15
    texec_degree: int = 1
    texec_min_samples: int = 5
    t_max: float = 5.0
    ntt_threshold: float = 0.9
    max_tcp_speed: Mapping[str, float] = field(default_factory=dict)
    default_tcp_speed: float = 0.5
    ttc_samples: int = 4
    trajectory_ik: str = "exact"
    distance_points: str = "all"
    batch_ik: bool = True
    batch_distances: bool = True
    batch_indices: bool = True
    planner: PlannerParams = field(default_factory=PlannerParams)
    indices: Sequence[IndexSpec] = (IndexSpec("rj"), IndexSpec("theta"), IndexSpec("cr"))
    grasp_tolerance: float = 0.002
    grasp_cycles: int = 2
    tt_timeout: float = 5.0
    abort_cooldown: float = 1.0
    seed: int = 0
    hold_transfer_s: float = 0.2

    def __post_init__(self) -> None:
        def bad(name: str, value: object, rule: str) -> ValueError:
            return ValueError(f"KernelConfig.{name} must be {rule}, got {value!r}")

        for name in ("dt", "t_max", "default_tcp_speed", "tt_timeout", "grasp_tolerance",
                     "ntt_threshold"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0.0):
                raise bad(name, v, "finite and > 0")
        if not (math.isfinite(self.abort_cooldown) and self.abort_cooldown >= 0.0):
            raise bad("abort_cooldown", self.abort_cooldown, "finite and >= 0")
        if math.isnan(self.hold_transfer_s) or self.hold_transfer_s < 0.0:
            raise bad("hold_transfer_s", self.hold_transfer_s, ">= 0 (inf: off)")
        for name in ("horizon", "stride", "window", "texec_window", "ttc_samples",
                     "texec_min_samples", "grasp_cycles"):
            if getattr(self, name) < 1:
                raise bad(name, getattr(self, name), ">= 1")
        for name in ("predictor_degree", "texec_degree", "seed"):
            if getattr(self, name) < 0:
                raise bad(name, getattr(self, name), ">= 0")
        if self.texec_min_samples > self.texec_window:
            raise bad("texec_min_samples", self.texec_min_samples,
                      f"<= texec_window ({self.texec_window}): a longer series never forms")
        for robot, v in self.max_tcp_speed.items():
            if not (math.isfinite(v) and v > 0.0):
                raise bad(f"max_tcp_speed[{robot!r}]", v, "finite and > 0")
        if self.trajectory_ik not in ("exact", "linear"):
            raise ValueError(f"KernelConfig.trajectory_ik must be 'exact' or 'linear', got "
                             f"{self.trajectory_ik!r}")
        if self.distance_points not in ("all", "ends"):
            raise ValueError(f"KernelConfig.distance_points must be 'all' or 'ends', got "
                             f"{self.distance_points!r}")
        for spec in self.indices:
            if spec.name not in INDICES:
                raise ValueError(f"KernelConfig.indices: unknown index {spec.name!r}; "
                                 f"known: {INDICES.names()}")
