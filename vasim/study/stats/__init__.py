"""Statistics of the user studies (spec/study.md §3-4): pure functions on long-format data.

Every function takes a long-format ``pandas.DataFrame`` (one row per observation, with the
dependent variable, subject and factor columns named by argument, as pingouin) and returns
a tidy DataFrame with a fixed, documented column order (or a small result object). Input is
validated first (:mod:`vasim.study.stats._data`): a missing column, a non-numeric value, an
unbalanced design or too few subjects/levels raise :class:`vasim.core.errors.ConfigError` naming
the file (``data.attrs["source"]``, set by :func:`read_long_csv`), the column and the cells.

Primary analyses (spec §3 **decision**): :func:`rm_anova` on subject-level cell means, with
:func:`tukey_hsd_rm` (as in the seed) and Holm-corrected :func:`pairwise_paired` (within-
subject-correct) as post hoc tests. :func:`seed_per_sample_anova` only replicates the
seed's per-sample ANOVA and is labelled as such. Groups (surgeons vs residents) x a within
factor: :func:`mixed_anova`; fixture effects adjusted for practice: :func:`mixed_model`
(statsmodels ``MixedLM``, random intercept per subject).

Statistics refuse what they cannot estimate (issue #16): a value that is undefined for the
data (an effect size with zero error variance, Mauchly's test of a singular covariance, a
fit that did not converge) is NaN with a ``note`` and a :class:`StatsWarning`, never a
made-up number. Subject and factor labels are text when read from CSV (``01`` and ``1``
are two subjects); a duplicated column name is refused.

This package is a leaf: of vasim it imports only :mod:`vasim.core` (an import-linter
contract in pyproject.toml; issue #14), so importing it loads neither the store nor tqdm.
"""

from __future__ import annotations

from vasim.study.stats._data import StatsWarning as StatsWarning
from vasim.study.stats._data import nan_to_none as nan_to_none
from vasim.study.stats._data import python_scalar as python_scalar
from vasim.study.stats._data import read_long_csv as read_long_csv
from vasim.study.stats.anova import RM_ANOVA_COLUMNS as RM_ANOVA_COLUMNS
from vasim.study.stats.anova import rm_anova as rm_anova
from vasim.study.stats.correlation import SPEARMAN_COLUMNS as SPEARMAN_COLUMNS
from vasim.study.stats.correlation import spearman_items as spearman_items
from vasim.study.stats.learning import PowerLawFit as PowerLawFit
from vasim.study.stats.learning import fit_learning_curves as fit_learning_curves
from vasim.study.stats.learning import fit_power_law as fit_power_law
from vasim.study.stats.learning import learning_curve_summary as learning_curve_summary
from vasim.study.stats.mixed import MIXED_ANOVA_COLUMNS as MIXED_ANOVA_COLUMNS
from vasim.study.stats.mixed import mixed_anova as mixed_anova
from vasim.study.stats.mixed_model import MIXED_MODEL_COLUMNS as MIXED_MODEL_COLUMNS
from vasim.study.stats.mixed_model import fit_mixed_model as fit_mixed_model
from vasim.study.stats.mixed_model import mixed_model as mixed_model
from vasim.study.stats.mixed_model import mixed_model_lr_test as mixed_model_lr_test
from vasim.study.stats.paired import PAIRED_COLUMNS as PAIRED_COLUMNS
from vasim.study.stats.paired import gain as gain
from vasim.study.stats.paired import min_n_for_power as min_n_for_power
from vasim.study.stats.paired import n_for_power as n_for_power
from vasim.study.stats.paired import paired_power as paired_power
from vasim.study.stats.paired import pairwise_paired as pairwise_paired
from vasim.study.stats.posthoc import TUKEY_COLUMNS as TUKEY_COLUMNS
from vasim.study.stats.posthoc import TukeyResult as TukeyResult
from vasim.study.stats.posthoc import tukey_hsd as tukey_hsd
from vasim.study.stats.posthoc import tukey_hsd_rm as tukey_hsd_rm
from vasim.study.stats.seed_replication import SEED_LABEL as SEED_LABEL
from vasim.study.stats.seed_replication import seed_per_sample_anova as seed_per_sample_anova

__all__ = [
    "MIXED_ANOVA_COLUMNS",
    "MIXED_MODEL_COLUMNS",
    "PAIRED_COLUMNS",
    "RM_ANOVA_COLUMNS",
    "SEED_LABEL",
    "SPEARMAN_COLUMNS",
    "TUKEY_COLUMNS",
    "PowerLawFit",
    "StatsWarning",
    "TukeyResult",
    "fit_learning_curves",
    "fit_mixed_model",
    "fit_power_law",
    "gain",
    "learning_curve_summary",
    "min_n_for_power",
    "mixed_anova",
    "mixed_model",
    "mixed_model_lr_test",
    "n_for_power",
    "nan_to_none",
    "paired_power",
    "pairwise_paired",
    "python_scalar",
    "read_long_csv",
    "rm_anova",
    "seed_per_sample_anova",
    "spearman_items",
    "tukey_hsd",
    "tukey_hsd_rm",
]
