"""Linear mixed model with a random intercept per subject (statsmodels ``MixedLM``, REML).

guides/study-science.md: the fixture effects adjusted for practice (trial index as a
covariate), with one random intercept per subject. This is a thin, validated wrapper: the
data are checked first (every column of the formula present, finite, no missing values),
the fit is statsmodels' own, and every warning the fit raises (non-convergence, a boundary
estimate, a singular Hessian) becomes a ``note`` on the result and a
:class:`~vasim.study.stats._data.StatsWarning`, never a silent number.
"""

from __future__ import annotations

import re
import warnings
from typing import Any

import numpy as np
import pandas as pd
import statsmodels.formula.api as smf
from patsy import PatsyError

from vasim.core.errors import ConfigError
from vasim.study.stats._data import (
    MAX_LISTED,
    StatsWarning,
    _where,
    factor_column,
    levels_of,
    require_columns,
    require_frame,
    source_of,
)

#: Column order of :func:`mixed_model`.
MIXED_MODEL_COLUMNS: tuple[str, ...] = (
    "term", "coef", "se", "z", "p", "ci_low", "ci_high", "note",
)

_NAME = re.compile(r"Q\(\s*['\"]([^'\"]+)['\"]\s*\)|[A-Za-z_][A-Za-z0-9_.]*")

# -- the formula whitelist (issue #30 item 7) ---------------------------------------------
TRANSFORMS: tuple[str, ...] = (
    "C", "Q", "I", "center", "standardize", "scale",
    "np.log", "np.log2", "np.log10", "np.log1p", "np.exp", "np.sqrt", "np.abs",
    "np.square",
)
"""Functions a formula may call: patsy's ``C`` (categorical), ``Q`` (quoted column name),
``I`` (arithmetic), ``center``/``standardize``/``scale``, and numpy's monotone transforms."""
CONTRASTS: tuple[str, ...] = ("Treatment", "Sum", "Diff", "Helmert", "Poly")
"""Contrast codings allowed as ``C(column, Treatment('ff'))`` (second argument of C)."""
KEYWORDS: tuple[str, ...] = ("reference", "levels", "omit")
"""Keyword arguments of the contrasts (``Treatment(reference='ff')``)."""
OPERATORS: tuple[str, ...] = ("~", "+", "-", "*", "/", ":", "**", "(", ")", ",", "=")
"""The formula operators and punctuation allowed."""
MAX_FORMULA_CHARS = 2000

_TOKEN = re.compile(r"""\s*(?:(?P<str>'[^'\\\n]*'|"[^"\\\n]*")|(?P<num>\d+(?:\.\d+)?)|"""
                    r"""(?P<name>[A-Za-z_][A-Za-z0-9_]*(?:\.[A-Za-z_][A-Za-z0-9_]*)*)|"""
                    r"""(?P<op>\*\*|[~+\-*/:(),=]))""")


def check_formula(formula: str, columns: list[str], *, source: str | None = None) -> None:
    """Refuses a formula that is anything but column names, operators and known transforms
    (issue #30 item 7: patsy *evaluates* formula terms as Python, so ``I(__import__('os')
    .system(...))`` ran the code).

    Allowed: the columns of the data (as names, or quoted with ``Q("a b")``), the operators
    :data:`OPERATORS`, numbers, the calls :data:`TRANSFORMS` (a column's values
    transformed), the contrasts :data:`CONTRASTS` as the second argument of ``C`` with
    a quoted level or :data:`KEYWORDS`; a string only inside ``Q`` (naming a column) or a
    contrast (a level). Nothing else reaches patsy: no attribute access, subscripts,
    other names or calls.

    **Decision**: a whitelist of tokens checked before patsy, rather than a sandboxed
    evaluation environment, because patsy evaluates its terms with ``eval`` in the
    caller's namespace and Python offers no safe sandbox for ``eval``.

    Raises:
        ConfigError: (field ``formula``) naming the token and what is allowed.

    Examples:
        >>> check_formula("y ~ C(f, Treatment('a')) + np.log(x) + I(x ** 2)", ["y", "f", "x"])
        >>> check_formula("y ~ I(__import__('os'))", ["y"])
        Traceback (most recent call last):
        ...
        vasim.core.errors.ConfigError: field 'formula': got '__import__' at character 6 of \
"y ~ I(__import__('os'))", expected a transform (C, Q, I, center, standardize, scale, \
np.log, np.log2, np.log10, np.log1p, np.exp, np.sqrt, np.abs, np.square) or, as C's \
second argument, a contrast (Treatment, Sum, Diff, Helmert, Poly)
    """
    cols = set(columns)
    col_text = (f"a column ({', '.join(map(str, columns[:MAX_LISTED]))}"
                f"{', ...' if len(columns) > MAX_LISTED else ''})")
    what = f"{col_text} or a transform ({', '.join(TRANSFORMS)})"

    def refuse(token: str, pos: int, expected: str) -> ConfigError:
        shown = formula if len(formula) <= 120 else formula[:120] + "..."
        return ConfigError(f"got {token!r} at character {pos} of {shown!r}, expected "
                           f"{expected}", file=source, field="formula")

    if not isinstance(formula, str) or len(formula) > MAX_FORMULA_CHARS:
        raise ConfigError(f"formula must be a string of at most {MAX_FORMULA_CHARS} "
                          f"characters, got {str(formula)[:80]!r}", file=source,
                          field="formula")
    tokens: list[tuple[str, str, int]] = []
    pos = 0
    while pos < len(formula):
        if formula[pos:].strip() == "":
            break
        m = _TOKEN.match(formula, pos)
        if m is None or m.end() == pos:
            start = len(formula) - len(formula[pos:].lstrip())
            raise refuse(formula[start:start + 1], start,
                         f"a column, a number, a transform or one of {' '.join(OPERATORS)}")
        kind = m.lastgroup or "op"
        tokens.append((kind, m.group(kind), m.start(kind)))
        pos = m.end()
    if sum(1 for k, t, _ in tokens if k == "op" and t == "~") != 1:
        raise ConfigError(f"formula must have exactly one '~' (response ~ terms), got "
                          f"{formula!r}", file=source, field="formula")
    stack: list[str | None] = []        # the call each open parenthesis belongs to
    for i, (kind, tok, at) in enumerate(tokens):
        nxt = tokens[i + 1][1] if i + 1 < len(tokens) else ""
        prev = tokens[i - 1][1] if i else ""
        inside = stack[-1] if stack else None
        if kind == "name":
            if nxt == "(":
                if tok in TRANSFORMS or (tok in CONTRASTS and inside == "C" and prev == ","):
                    continue
                raise refuse(tok, at, f"a transform ({', '.join(TRANSFORMS)}) or, as "
                             f"C's second argument, a contrast ({', '.join(CONTRASTS)})")
            if nxt == "=" and tok in KEYWORDS and inside in CONTRASTS:
                continue
            if tok in CONTRASTS and inside == "C" and prev == ",":
                continue              # C(f, Sum)
            if tok not in cols:
                raise refuse(tok, at, what)
        elif kind == "str":
            if inside == "Q" and prev == "(" and nxt == ")":
                if tok[1:-1] not in cols:
                    raise refuse(tok, at, f"inside Q(), {col_text}")
                continue
            if inside in CONTRASTS:
                continue              # a level: Treatment('ff'), reference='ff'
            raise refuse(tok, at, "a string only in Q(\"column\") or as a contrast's level")
        elif kind == "op":
            if tok == "(":
                stack.append(prev if tokens[i - 1][0] == "name" and i else None)
            elif tok == ")":
                if not stack:
                    raise refuse(tok, at, "a matching '('")
                stack.pop()
            elif tok == "=" and not (inside in CONTRASTS and prev in KEYWORDS):
                raise refuse(tok, at, f"'=' only after a contrast keyword ({', '.join(KEYWORDS)})")
    if stack:
        raise ConfigError(f"formula {formula!r} has an unclosed '('", file=source,
                          field="formula")


def mixed_model(data: pd.DataFrame, formula: str, groups: str) -> pd.DataFrame:
    """Fits ``formula`` with a random intercept per ``groups`` level by REML.

    Equivalent to ``statsmodels.formula.api.mixedlm(formula, data,
    groups=data[groups]).fit(reml=True)``, after validation.

    Args:
        data: long-format table, one row per observation.
        formula: patsy formula of the fixed effects, e.g. ``"error ~ C(fixture) + trial"``
            (columns named in it must exist; text columns enter through ``C(...)`` or as
            categorical automatically).
        groups: column whose levels get one random intercept each (the subject column).

    Returns:
        One row per fixed-effect term (statsmodels' names, e.g. ``Intercept``,
        ``C(fixture)[T.ff]``, ``trial``), columns :data:`MIXED_MODEL_COLUMNS`:

        - ``coef``: the REML estimate, in the unit of the response per unit of the term.
        - ``se``: its standard error; ``z = coef / se``; ``p``: two-sided normal p-value.
        - ``ci_low``, ``ci_high``: 95 % Wald interval ``coef -+ 1.96 se``.
        - ``note``: empty, or every warning of the fit ("did not converge", "MLE on the
          boundary", "Hessian not positive definite", ...) joined by ``"; "`` (the same on
          every row: it concerns the whole fit).

        ``result.attrs`` holds ``n_obs``, ``n_groups``, ``group_var`` (random-intercept
        variance, response unit squared), ``resid_var`` (residual variance), ``converged``,
        ``llf`` (REML log-likelihood) and ``formula``.

    Raises:
        ConfigError: ``formula`` is not a string with ``~``, names no column or a column
            that does not exist, a column of the formula has missing or non-finite values,
            ``groups`` is missing, has missing labels or fewer than 2 levels, or patsy /
            statsmodels refuse the model (message quoted).

    Examples:
        >>> rng = np.random.default_rng(0)
        >>> subj = np.repeat([f"S{i}" for i in range(12)], 6)
        >>> x = np.tile(np.arange(6.0), 12)
        >>> y = 1.0 + 0.5 * x + np.repeat(rng.normal(0, 1, 12), 6) + rng.normal(0, .2, 72)
        >>> fit = mixed_model(pd.DataFrame({"s": subj, "x": x, "y": y}), "y ~ x", "s")
        >>> fit["term"].tolist(), round(float(fit.loc[1, "coef"]), 1)
        (['Intercept', 'x'], 0.5)
    """
    result, note = fit_mixed_model(data, formula, groups)
    if note:
        warnings.warn(f"mixed_model {formula!r}: {note}", StatsWarning, stacklevel=2)
    model = result.model

    fe = result.fe_params.index
    ci = result.conf_int().loc[fe]
    out = pd.DataFrame({
        "term": [str(t) for t in fe],
        "coef": result.fe_params.to_numpy(dtype=float),
        "se": result.bse_fe.to_numpy(dtype=float),
        "z": result.tvalues.loc[fe].to_numpy(dtype=float),
        "p": result.pvalues.loc[fe].to_numpy(dtype=float),
        "ci_low": ci.iloc[:, 0].to_numpy(dtype=float),
        "ci_high": ci.iloc[:, 1].to_numpy(dtype=float),
        "note": note,
    }, columns=list(MIXED_MODEL_COLUMNS))
    out.attrs.update({
        "n_obs": int(result.nobs), "n_groups": len(model.group_labels),
        "group_var": float(np.asarray(result.cov_re)[0, 0]), "resid_var": float(result.scale),
        "converged": bool(result.converged), "llf": float(result.llf), "formula": formula,
    })
    return out


def fit_mixed_model(data: pd.DataFrame, formula: str, groups: str, *,
                    reml: bool = True) -> tuple[Any, str]:
    """The validated statsmodels fit behind :func:`mixed_model` (same checks and errors).

    Args:
        data, formula, groups: as :func:`mixed_model`. reml: REML (True) or maximum
            likelihood (False: what a likelihood-ratio test of fixed effects needs).

    Returns:
        (``statsmodels`` ``MixedLMResults``, note): the note joins every warning of the fit
        (empty when there was none); the caller decides how to report it.

    Raises:
        ConfigError: as :func:`mixed_model`.
    """
    data = require_frame(data)
    src = source_of(data)
    if not isinstance(formula, str) or "~" not in formula:
        raise ConfigError(f"formula must be a string 'response ~ terms', got {formula!r}",
                          file=src, field="formula")
    require_columns(data, [groups])
    g = factor_column(data, groups)
    if len(levels_of(g)) < 2:
        raise ConfigError(f"need at least 2 levels of {groups!r} for random intercepts, found "
                          f"{levels_of(g)!r}", file=src, field=groups)
    used = _formula_columns(data, formula)
    check_formula(formula, [str(c) for c in data.columns], source=src)  # before patsy
    data = _numbers_where_read_as_text(data, [c for c in used if c != groups])
    for col in used:
        _check_column(data, col)

    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            model = smf.mixedlm(formula, data, groups=data[groups])
            result = model.fit(reml=reml)
        except PatsyError as exc:
            raise ConfigError(f"cannot build the model of formula {formula!r}: "
                              f"{str(exc).splitlines()[0]}", file=src, field="formula") from None
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise ConfigError(f"statsmodels cannot fit formula {formula!r}: {exc}", file=src,
                              field="formula") from None
    notes = list(dict.fromkeys(_warning_text(w) for w in caught
                               if not issubclass(w.category, DeprecationWarning)))
    if not result.converged and not any("converge" in n for n in notes):
        notes.insert(0, f"the {'REML' if reml else 'ML'} fit did not converge")
    return result, "; ".join(notes)



def mixed_model_lr_test(data: pd.DataFrame, reduced: str, full: str, groups: str
                        ) -> dict[str, Any]:
    """Likelihood-ratio test of the fixed effects ``full`` adds to ``reduced`` (both fitted
    by maximum likelihood on the same rows, random intercept per ``groups``).

    Returns:
        ``{"chi2", "df", "p", "llf_reduced", "llf_full", "note"}``: chi2 = 2 (llf_full -
        llf_reduced), df = the difference in fixed-effect parameters, p its chi-square
        upper tail (scipy); note: the fits' warnings.

    Raises:
        ConfigError: as :func:`mixed_model`, or ``full`` does not add a parameter.

    Example:
        >>> rng = np.random.default_rng(1)
        >>> s = np.repeat([f"S{i}" for i in range(10)], 8)
        >>> x, z = np.tile(np.arange(8.0), 10), rng.normal(size=80)
        >>> y = x + np.repeat(rng.normal(0, 1, 10), 8) + rng.normal(0, .5, 80)
        >>> r = mixed_model_lr_test(pd.DataFrame({"s": s, "x": x, "z": z, "y": y}),
        ...                         "y ~ x", "y ~ x + z", "s")
        >>> r["df"], r["p"] > 0.01
        (1, True)
    """
    from scipy import stats as sps

    red, n1 = fit_mixed_model(data, reduced, groups, reml=False)
    ful, n2 = fit_mixed_model(data, full, groups, reml=False)
    df = len(ful.fe_params) - len(red.fe_params)
    if df < 1:
        raise ConfigError(f"formula {full!r} adds no fixed effect to {reduced!r}",
                          file=source_of(data), field="formula")
    chi2 = max(0.0, 2.0 * (float(ful.llf) - float(red.llf)))
    note = "; ".join(n for n in (n1, n2) if n)
    return {"chi2": chi2, "df": int(df), "p": float(sps.chi2.sf(chi2, df)),
            "llf_reduced": float(red.llf), "llf_full": float(ful.llf), "note": note}


def formula_columns(formula: str, columns: list[str]) -> list[str]:
    """The columns (of ``columns``) a formula names, as names or in ``Q("...")``, in order.

    >>> formula_columns('y ~ C(f) + Q("a b") + np.log(x)', ["x", "y", "f", "a b", "z"])
    ['y', 'f', 'a b', 'x']
    """
    known = set(columns)
    out: list[str] = []
    for m in _NAME.finditer(formula):
        name = m.group(1) or m.group(0)
        if name in known and name not in out:
            out.append(name)
    return out


def _formula_columns(data: pd.DataFrame, formula: str) -> list[str]:
    """The data columns a formula names (identifiers and ``Q("...")``); at least one."""
    src = source_of(data)
    names: list[str] = []
    for m in _NAME.finditer(formula):
        name = m.group(1) or m.group(0)
        if name in data.columns and name not in names:
            names.append(name)
    lhs = formula.split("~", 1)[0].strip()
    if not lhs:
        raise ConfigError(f"formula {formula!r} has no response left of '~'", file=src,
                          field="formula")
    if lhs.isidentifier() and lhs not in data.columns:
        avail = ", ".join(repr(str(c)) for c in data.columns)
        raise ConfigError(f"response column {lhs!r} of formula {formula!r} not found; "
                          f"available columns: {avail}", file=src, field=lhs)
    if not names:
        raise ConfigError(f"formula {formula!r} names no column of the data", file=src,
                          field="formula")
    return names


def _numbers_where_read_as_text(data: pd.DataFrame, columns: list[str]) -> pd.DataFrame:
    """Value columns that :func:`read_long_csv` left as text become numbers.

    **Decision**: ``read_long_csv`` keeps a column as text when its numbers would merge two
    different texts (``2`` and ``2.0``); for a value column in a formula that would make
    patsy treat the response or a covariate as categorical. A text column of the formula
    whose every value is a number, and that the caller did not name as a label
    (``data.attrs["text_columns"]``), is therefore converted to float; categorical use
    stays explicit with ``C(column)`` or by naming the column as text when reading.
    """
    labels = set(data.attrs.get("text_columns", ()))
    out = data
    for col in columns:
        s = data[col]
        if col in labels or pd.api.types.is_numeric_dtype(s) or pd.api.types.is_bool_dtype(s):
            continue
        present = s.dropna()
        nums = pd.to_numeric(present, errors="coerce")
        if len(present) and nums.notna().all():
            if out is data:
                out = data.copy()
            out[col] = pd.to_numeric(s, errors="coerce").astype("float64")
    return out


def _check_column(data: pd.DataFrame, col: str) -> None:
    """No missing values; numeric columns finite (positions and values named)."""
    src = source_of(data)
    s = data[col]
    missing = s.isna().to_numpy()
    if missing.any():
        raise ConfigError(f"column {col!r} has missing (NaN/empty) values at "
                          f"{_where(data, list(s.index[missing]))}", file=src, field=col)
    if pd.api.types.is_numeric_dtype(s) and not pd.api.types.is_bool_dtype(s):
        bad = ~np.isfinite(s.to_numpy(dtype=float))
        if bad.any():
            vals = ", ".join(repr(v) for v in s[bad].tolist()[:MAX_LISTED])
            raise ConfigError(f"column {col!r} has non-finite values at "
                              f"{_where(data, list(s.index[bad]))}: {vals}", file=src,
                              field=col)


def _warning_text(w: Any) -> str:
    """One line: the warning's category and the first line of its message."""
    first = str(w.message).strip().splitlines()[0] if str(w.message).strip() else ""
    return f"{w.category.__name__}: {first}"
