"""Synthetic cohorts from the outcome engine (``vasim.operator.outcome``), in memory.

A cohort here is drawn exactly as ``vasim study simulate`` draws it -- the scenario's
subjects (``cohort_subjects``), each subject's schedule (``generate_schedule`` of its
session seed) and each scheduled trial's adjusted operator and effective practice
(``Session.trial_config`` of a session carrying the scenario and effect scale) -- but each
trial's mean path deviation comes from the trial-level outcome model instead of the 1 kHz
simulation, and the post-questionnaire from the subject's own measured benefits
(``vasim.study.cohort.measured_benefits``, ``simulated_answers``). It is what the
simulation-based validation (``tests/study/test_recovery_validation.py``) and
:func:`validate_recovery` run.

Subject j's outcome draws use ``SeedSequence([seed, 9, j])`` (its subject effect first,
then one draw per trial in schedule order); its answers ``SeedSequence([session seed, 8])``
as a stored simulated session's.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import pandas as pd

from vasim.core.errors import ConfigError
from vasim.operator.outcome import draw_path_deviation
from vasim.operator.scenario import Scenario
from vasim.study.cohort import (
    cohort_subjects,
    measured_benefits,
    scenario_record,
    simulated_answers,
    subject_stream,
)
from vasim.study.power.cohort import subject_session
from vasim.study.power.design import surgeons_for
from vasim.study.protocol import Protocol
from vasim.study.recovery import PATH_DEV, estimate_effects


@dataclass(frozen=True)
class OutcomeCohort:
    """One outcome-engine cohort.

    Attributes:
        trials: one row per trial: ``subject, group, trial_index, condition, probe,
            probe_index,
            variant, trial_id, path_dev_mean_mm``.
        answers: subject code -> its post-questionnaire answers.
    """

    trials: pd.DataFrame
    answers: Mapping[str, Mapping[str, Any]]


def outcome_cohort(protocol: Protocol, scenario: Scenario, *, n_subjects: int, seed: int,
                   effect_scale: float = 1.0, n_surgeons: int | None = None,
                   answers: bool = True) -> OutcomeCohort:
    """Draws one cohort (module docstring).

    Args:
        protocol: the protocol every subject runs. scenario: the declared scenario.
        n_subjects: cohort size. seed: cohort seed. effect_scale: x the fixture effects.
        n_surgeons: surgeons among them (None: the VF study's share, ``surgeons_for``).
        answers: also draw the post-questionnaires.
    """
    model = scenario.outcome
    if model is None:   # a teleoperation scenario: its trials run on the MRCP station only
        raise ConfigError(f"scenario {scenario.name!r} has no [outcome] (a teleoperation "
                          "scenario); the outcome engine runs VF protocols with a VF "
                          "scenario", field="--scenario")
    subjects = cohort_subjects(n_subjects,
                               surgeons_for(n_subjects) if n_surgeons is None else n_surgeons,
                               seed, latin_square=protocol.block_order == "latin_square",
                               scenario=scenario)
    extra = {"scenario": scenario_record(scenario, effect_scale)}
    rows: list[dict[str, Any]] = []
    post: dict[str, Mapping[str, Any]] = {}
    tid = 0
    for subj in subjects:
        session = subject_session(protocol, subj, dt=1e-3, max_trial_time=None, extra=extra)
        rng = subject_stream(seed, 9, subj.number)
        u = float(rng.normal(0.0, model.subject_sd_log))
        first = tid
        for st in session.schedule:
            cfg = session.trial_config(st)
            assert cfg.profile is not None
            tid += 1
            rows.append({"subject": subj.code, "group": subj.group,
                         "trial_index": st.index, "condition": st.condition,
                         "probe": st.probe, "probe_index": st.probe_index,
                         "variant": st.variant, "trial_id": tid,
                         PATH_DEV: draw_path_deviation(model, subj.profile,
                                                       cfg.profile, cfg.practice, u, rng)})
        if answers and not protocol.post.empty:
            mine = pd.DataFrame(rows[first:])
            b = measured_benefits(mine, dict(zip(mine["trial_id"], mine[PATH_DEV],
                                                 strict=True)))
            post[subj.code] = simulated_answers(protocol, "post",
                                                subject_stream(subj.session_seed, 8), measured=b,
                                                model=scenario.questionnaire)
    return OutcomeCohort(trials=pd.DataFrame(rows), answers=post)


def recovery_rows(protocol: Protocol, scenario: Scenario, *, n_subjects: int, seed: int,
                  effect_scale: float = 1.0, level: float = 0.95) -> list[dict[str, Any]]:
    """One outcome cohort analysed by ``vasim.study.recovery.estimate_effects``: one row
    per fixture with the assumed ratio, the recovered ratio, its interval, p, whether the
    interval covers the assumed ratio and whether the test rejects at 1 - level."""
    coh = outcome_cohort(protocol, scenario, n_subjects=n_subjects, seed=seed,
                         effect_scale=effect_scale, answers=False)
    est = estimate_effects(coh.trials, level=level)
    assumed = scenario.effects(effect_scale)
    out = []
    for c, r in est["fixtures"].items():
        a = assumed[c].accuracy if c in assumed else 1.0
        ok = r["ratio"] is not None
        out.append({"seed": seed, "fixture": c, "assumed": a, "recovered": r["ratio"],
                    "ci_low": r["ci_low"], "ci_high": r["ci_high"], "p": r["p"],
                    "covers": bool(ok and r["ci_low"] <= a <= r["ci_high"]),
                    "rejects": bool(ok and r["p"] < 1.0 - level)})
    return out



def _rows_job(args: tuple[str, str, int, int, float]) -> list[dict[str, Any]]:
    from vasim.operator.scenario import scenario_from_text
    from vasim.study.protocol import parse_protocol

    proto_text, scen_text, n_subjects, seed, scale = args
    return recovery_rows(parse_protocol(proto_text), scenario_from_text(scen_text),
                         n_subjects=n_subjects, seed=seed, effect_scale=scale)


def validate_recovery(protocol: Protocol, scenario: Scenario, *, n_cohorts: int,
                      n_subjects: int, seed: int = 0, effect_scale: float = 1.0,
                      workers: int = 0, progress: bool = False) -> pd.DataFrame:
    """Simulation-based validation of the recovery: ``n_cohorts`` outcome cohorts
    (cohort k has seed ``seed + k``), each analysed; one :func:`recovery_rows` row per
    cohort and fixture. ``workers`` > 0: a process pool (``spawn``) of that size.

    Coverage is ``rows["covers"].mean()``, the rejection rate ``rows["rejects"].mean()``
    (the false-positive rate when the scenario has no fixture effect).
    """
    from vasim.core.progress import progress_bar

    if protocol.text is None:
        raise ValueError(f"protocol {protocol.name!r} has no text to send to the workers")
    jobs = [(protocol.text, scenario.text, n_subjects, seed + k, effect_scale)
            for k in range(n_cohorts)]
    rows: list[dict[str, Any]] = []
    bar = progress_bar(n_cohorts, f"recovery {scenario.name}", "cohort", enabled=progress)
    try:
        if workers <= 0:
            for job in jobs:
                rows.extend(_rows_job(job))
                bar.update(1)
        else:
            import multiprocessing
            from concurrent.futures import ProcessPoolExecutor

            ctx = multiprocessing.get_context("spawn")
            with ProcessPoolExecutor(max_workers=workers, mp_context=ctx) as pool:
                for part in pool.map(_rows_job, jobs):
                    rows.extend(part)
                    bar.update(1)
    finally:
        bar.close()
    return pd.DataFrame(rows)


__all__ = ["OutcomeCohort", "outcome_cohort", "recovery_rows", "validate_recovery"]
