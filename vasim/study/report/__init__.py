"""The study report: ``vasim report --db study.sqlite --out report/ [--protocol NAME]``.

:func:`build_report` reads a study store (read-only) and writes

* ``report/index.html``: one self-contained page (figures embedded as PNG, no script;
  :mod:`vasim.study.report.html_page`), and
* ``report/tables/*.csv``: every table of the page at full precision, ``provenance.csv`` and
  ``manifest.json`` (the tables written, their rows and columns, whether the data are
  synthetic), and
* ``report/summary.json``: the headline results, machine-readable
  (:mod:`vasim.study.report.summary` gives the schema).

Sections (spec/study.md §3-4): cohort; learning curves over the VF-free probe trials;
effect of fixture (subject-level RM-ANOVA, post hoc tests, the seed's per-sample ANOVA as a
labelled replication, the practice-adjusted mixed model); box plots; surgeons vs residents
(mixed ANOVA group x probe trial); questionnaires; the MRCP vs standard-teleoperation
comparison; traceability. A section whose data are missing says what is missing and which
subjects or trials it leaves out; it never fails the report.

The package, one job per module: :mod:`~vasim.study.report.data` (reading the store),
:mod:`~vasim.study.report.analysis` (per-trial outcomes and cells of the VF study),
:mod:`~vasim.study.report.models` (mixed model and mixed ANOVA of the VF study),
:mod:`~vasim.study.report.summary` (``summary.json``),
:mod:`~vasim.study.report.sections` (one module per section),
:mod:`~vasim.study.report.html_page` (the HTML content model and renderer),
:mod:`~vasim.study.report.figures` (matplotlib figures),
:mod:`~vasim.study.report.writing` (CSV, manifest and page files) and
:mod:`~vasim.study.report.build` (:func:`build_report`, the assembly).

What is read: sessions, the realised schedules, trial rows, per-point metrics, per-trial
metrics, demographics and answers. The ``samples`` table is never read (the per-point and
per-trial metrics are computed from the samples when a trial closes and stored with it).

**Decisions** (the seed leaves them open; each is also stated in the report's text):

* One report covers one protocol: ``--protocol NAME``, or the only protocol of the store's
  sessions (several protocols without ``--protocol`` is a ``ConfigError`` naming them).
  The protocol text stored with the latest session gives the questionnaire items.
* Analysed trials: the completed attempt of each scheduled trial
  (``scheduled_trials.trial_id``). Interrupted attempts and trials outside sessions are
  counted in the cohort section but not analysed.
* Per-trial outcomes of the VF study (issue #25; docs/study-design.md): the mean path
  deviation [mm] (``path_dev_mean_mm``: THE accuracy measure; RMS, maximum and the
  fraction outside the tolerance tube beside it), latency ``L = Σ_i l_i`` [s] over the
  *reached* points, i.e. the reach time of the last reached point (the trial's completion
  time when every point is reached), and the seed's eq. 6.5 measure ``eq65 = Σ_i e_i Δt``
  [mm·s] (the Manhattan distance to the next point of interest integrated over time: not
  a length, and it grows with time; the report states how strongly it tracks latency). A
  trial with no reached point has no latency and is excluded (listed).
* PRIMARY analysis (:mod:`~vasim.study.report.transfer`): the VF-free probe after each
  fixture block ~ fixture just practised + block position + variant, random intercept per
  subject; carry-over by a likelihood-ratio test of the previous block's fixture.
* Fixture factor (the seed's design, secondary; 6 levels none, VG, AG, MS, Mag, FF): the
  cell of a subject and fixture is
  the mean of E (or L) over the subject's analysed trials of that condition (6 assisted
  trials; "none" = the 5 VF-free probe trials that follow the blocks: the 3 baseline
  probes always come first and would mix practice into the factor, issue #15). A linear
  mixed model ``measure ~ fixture + log(practice)`` (random intercept per subject, every
  analysed trial) reports the fixture effects adjusted for practice as a secondary,
  sensitivity analysis. Trial factor (8 levels):
  the probe trials 1..8, one trial per cell. The two factors are not crossed (assisted
  trials have no probe number), so each gets its own one-way subject-level RM-ANOVA
  (spec §3 decision: the primary result) over the subjects with every cell (the others
  are listed as excluded).
* Learning curves are plotted against the practice count: the trial's 1-based position in
  the session (probe 4 is the 10th trial), not the probe number.
* Synthetic data: a store whose sessions were run by the scripted operator gets
  :data:`~vasim.study.report.data.SYNTHETIC_LABEL` on every figure (a band under the
  image) and table (title and caption), in ``manifest.json`` and ``summary.json``; no
  analysis depends on it.
* The seed's per-sample ANOVA (replication only, ``stats.seed_per_sample_anova``): one row
  per trajectory point of every analysed trial (e_i or l_i), factors fixture and "trial";
  an assisted trial's "trial" level is the probe number of the VF-free trial that closes
  its block (the stage of the session it belongs to), a probe trial's its own number.
* MRCP (spec §4) per trial: ET = ``completion_time`` [s], EM = ``path_l2`` (Euclidean
  needle path length) [m], Q = ``target_deformation`` [mm s] (the rings' displacement by
  contacts integrated over time, ``vasim.trials.teleop_quality``),
  ``target_displacement_max`` [m] (when stored),
  ``contact_time`` [s], ``accumulated_force`` [N s], ``accumulated_torque`` [N m s].
  Per subject and mode the cell is the mean over the mode's trials; means, sds, paired
  t-tests and gains use the subjects with every mode; gain = mean(StdT) / mean(mode) of
  those cell means (``stats.gain``); the learning curve's trial number is the trial's
  position among the session's trials of that mode (1..6).
* Traceability: every CSV has a ``trial_id``/``trial_ids`` (or, for questionnaire tables,
  ``session_ids``) column, or rows in ``provenance.csv`` (``table, group, subject,
  session_ids, trial_ids``) listing per table cell the stored trial ids it was computed
  from.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.study.store import TrialStore
    >>> with tempfile.TemporaryDirectory() as d:
    ...     TrialStore(pathlib.Path(d) / "s.sqlite").close()
    ...     res = build_report(pathlib.Path(d) / "s.sqlite", pathlib.Path(d) / "rep")
    ...     res.index.name, "no sessions" in res.index.read_text()
    ('index.html', True)
"""

from __future__ import annotations

from vasim.study.report.analysis import (
    VfAnalysis,
    analyse_vf,
    complete_subjects,
    vf_trial_outcomes,
)
from vasim.study.report.build import STEPS, ReportResult, build_report
from vasim.study.report.common import (
    FIXTURE_LABELS,
    FIXTURE_ORDER,
    LABEL_PAIRED,
    LABEL_TUKEY,
    MODE_LABELS,
    MODE_ORDER,
    PROVENANCE_COLUMNS,
    fixture_label,
    ids_text,
    ordered_conditions,
)
from vasim.study.report.data import SYNTHETIC_LABEL, StudyData, load_study
from vasim.study.report.sections.mrcp import MRCP_METRICS, MrcpMetric

write_report = build_report
"""Alias of :func:`build_report` (the name issue #14 uses for the report's entry point)."""

__all__ = [
    "FIXTURE_LABELS",
    "FIXTURE_ORDER",
    "LABEL_PAIRED",
    "LABEL_TUKEY",
    "MODE_LABELS",
    "MODE_ORDER",
    "MRCP_METRICS",
    "PROVENANCE_COLUMNS",
    "STEPS",
    "SYNTHETIC_LABEL",
    "MrcpMetric",
    "ReportResult",
    "StudyData",
    "VfAnalysis",
    "analyse_vf",
    "build_report",
    "complete_subjects",
    "fixture_label",
    "ids_text",
    "load_study",
    "ordered_conditions",
    "vf_trial_outcomes",
    "write_report",
]
