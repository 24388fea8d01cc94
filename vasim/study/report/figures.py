"""Figures of the study report (``vasim report``): pure functions DataFrame -> Figure.

Every function takes tidy DataFrames (the report's tables) and returns a
``matplotlib.figure.Figure`` built without ``pyplot``: no global state, no GUI backend, safe
in threads and headless runs; :func:`figure_png` renders one with the Agg rasteriser to PNG
bytes. Nothing here reads the store or the file system.

Conventions: axes carry the quantity and its unit in brackets (``latency Σl_i [s]``);
conditions appear in the order given by the caller (the report passes none, VG, AG, MS,
Mag, FF and StdT, MRCP, MRCP+Cam); colours are the Okabe-Ito palette (readable with the
common colour-vision deficiencies); box plots show the median (line), the mean (white
diamond), the quartiles (box), whiskers at 1.5 IQR and every subject as a dot.

Example:
    >>> import pandas as pd
    >>> s = pd.DataFrame({"trial": [1, 2, 3], "n": [4, 4, 4], "mean": [3.0, 2.0, 1.5],
    ...                   "q25": [2.5, 1.5, 1.0], "q75": [3.5, 2.5, 2.0]})
    >>> fig = learning_curve_figure(s, CurveText(ylabel="latency [s]", title="Latency"))
    >>> figure_png(fig)[:8] == b"\\x89PNG\\r\\n\\x1a\\n"
    True
"""

from __future__ import annotations

import io
import math
import textwrap
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from matplotlib.axes import Axes
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.lines import Line2D
from matplotlib.patches import Patch

PALETTE: tuple[str, ...] = ("#0072B2", "#E69F00", "#009E73", "#D55E00", "#CC79A7", "#56B4E9",
                            "#F0E442", "#000000")
"""Okabe-Ito colours (blue, orange, green, vermillion, purple, sky blue, yellow, black)."""

_DPI = 100


def _new_figure(width: float, height: float) -> Figure:
    fig = Figure(figsize=(width, height), dpi=_DPI, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def figure_png(fig: Figure, *, dpi: int = _DPI) -> bytes:
    """Renders a figure to PNG bytes (Agg), white background.

    Args:
        fig: the figure. dpi: resolution [dots per inch].

    Returns:
        The PNG file content.
    """
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=dpi, facecolor="white")
    return buf.getvalue()


def _colors_for(order: Sequence[Any], colors: Mapping[Any, str] | None) -> list[str]:
    """A colour per level: the mapping's, else the palette colours the mapping leaves free
    (in turn), so that an unmapped level never takes a mapped level's colour."""
    if colors is None:
        return [PALETTE[i % len(PALETTE)] for i in range(len(order))]
    free = [c for c in PALETTE if c not in set(colors.values())] or list(PALETTE)
    out, k = [], 0
    for lev in order:
        if lev in colors:
            out.append(colors[lev])
        else:
            out.append(free[k % len(free)])
            k += 1
    return out


def _tick(text: str, width: int = 10) -> str:
    """A tick label wrapped onto lines of ``width`` characters ('_' read as a space)."""
    return textwrap.fill(text.replace("_", " "), width=width, break_long_words=True)


def _label(labels: Mapping[Any, str] | None, key: Any) -> str:
    if labels is not None and key in labels:
        return labels[key]
    return str(key)


def empty_figure(message: str, *, width: float = 6.0, height: float = 1.2) -> Figure:
    """A small figure that only says why there is nothing to plot."""
    fig = _new_figure(width, height)
    ax = fig.add_subplot()
    ax.axis("off")
    ax.text(0.5, 0.5, message, ha="center", va="center", wrap=True)
    return fig


def _curve(ax: Axes, part: pd.DataFrame, color: str, label: str, *, iqr_label: str) -> None:
    part = part.sort_values("trial")
    x = part["trial"].to_numpy(dtype=float)
    ax.fill_between(x, part["q25"].to_numpy(dtype=float), part["q75"].to_numpy(dtype=float),
                    color=color, alpha=0.22, linewidth=0, label=iqr_label)
    ax.plot(x, part["mean"].to_numpy(dtype=float), "o-", color=color, linewidth=1.8,
            markersize=5, label=label)


@dataclass(frozen=True)
class CurveText:
    """The words and marks around a learning curve.

    Attributes:
        ylabel: y-axis label with unit. title: axes title. xlabel: x-axis label.
        split_after: draw a dotted vertical line at this x (e.g. 3.5 between the baseline
            and the later probe trials) with ``split_labels`` on either side (None: none).
    """

    ylabel: str
    title: str
    xlabel: str = "VF-free trial number"
    split_after: float | None = None
    split_labels: tuple[str, str] = ("baseline", "after fixture blocks")


@dataclass(frozen=True)
class CurveGroups:
    """One curve per level of a column of the summary.

    Attributes:
        condition: the column of ``summary`` giving one curve per level.
        order: the levels in drawing order (default: order of appearance).
        labels: display names of the levels.
        bands: per level, its fit band (dashed line, no shading).
        colors: per level, its colour (default: the palette in order).
    """

    condition: str
    order: Sequence[Any] | None = None
    labels: Mapping[Any, str] | None = None
    bands: Mapping[Any, pd.DataFrame] | None = None
    colors: Mapping[Any, str] | None = None


def learning_curve_figure(
    summary: pd.DataFrame,
    text: CurveText,
    *,
    band: pd.DataFrame | None = None,
    fit_label: str | None = None,
    groups: CurveGroups | None = None,
) -> Figure:
    """Mean and interquartile range per trial index, with an optional power-law fit.

    Args:
        summary: ``learning_curve_summary`` table: columns ``trial, n, mean, q25, q75`` (and
            ``groups.condition`` when given), one row per trial index (and condition).
        text: the axes' labels, title and baseline split (``CurveText``).
        band: single curve only: the fit's confidence band (``PowerLawFit.band``: columns
            ``trial, fit, lower, upper``) drawn as a dashed line and a hatched band.
        fit_label: legend text of the fitted curve (e.g. the model and its parameters).
        groups: one curve per level of a column (``CurveGroups``), or None: one curve.

    Returns:
        The figure (one axes).
    """
    condition = None if groups is None else groups.condition
    order = None if groups is None else groups.order
    labels = None if groups is None else groups.labels
    bands = None if groups is None else groups.bands
    colors = None if groups is None else groups.colors
    xlabel, ylabel, title = text.xlabel, text.ylabel, text.title
    split_after, split_labels = text.split_after, text.split_labels
    fig = _new_figure(7.0, 4.2)
    ax = fig.add_subplot()
    if summary.empty:
        ax.text(0.5, 0.5, "no data", ha="center", va="center", transform=ax.transAxes)
    elif condition is None:
        _curve(ax, summary, PALETTE[0], "mean over subjects",
               iqr_label="interquartile range (25-75 %)")
        if band is not None and not band.empty:
            x = band["trial"].to_numpy(dtype=float)
            ax.fill_between(x, band["lower"].to_numpy(dtype=float),
                            band["upper"].to_numpy(dtype=float), facecolor="none",
                            edgecolor=PALETTE[3], hatch="///", linewidth=0.0, alpha=0.6,
                            label="95 % confidence band of the fit")
            ax.plot(x, band["fit"].to_numpy(dtype=float), "--", color=PALETTE[3],
                    linewidth=1.8, label=fit_label or "power-law fit")
    else:
        levels = list(order) if order is not None else list(pd.unique(summary[condition]))
        for i, lev in enumerate(levels):
            part = summary[summary[condition] == lev]
            if part.empty:
                continue
            color = _colors_for(levels, colors)[i]
            name = _label(labels, lev)
            _curve(ax, part, color, name, iqr_label="_nolegend_")
            if bands is not None and lev in bands and not bands[lev].empty:
                b = bands[lev]
                ax.plot(b["trial"].to_numpy(dtype=float), b["fit"].to_numpy(dtype=float), "--",
                        color=color, linewidth=1.2, label="_nolegend_")
    if not summary.empty:
        trials = np.sort(pd.unique(summary["trial"].to_numpy(dtype=float)))
        ax.set_xticks(trials)
        n_of = summary.groupby("trial")["n"].sum() if condition is None else None
        if n_of is not None and n_of.nunique() > 1:  # subjects per trial differ: say so
            ax.set_xticklabels([f"{t:g}\n(n={int(n_of.get(t, 0))})" for t in trials])
        else:
            ax.set_xticklabels([f"{t:g}" for t in trials])
        if split_after is not None and trials.min() < split_after < trials.max():
            ax.axvline(split_after, color="0.4", linestyle=":", linewidth=1.0)
            top = 0.98
            ax.text(split_after - 0.08, top, split_labels[0], transform=ax.get_xaxis_transform(),
                    ha="right", va="top", fontsize=8, color="0.3")
            ax.text(split_after + 0.08, top, split_labels[1],
                    transform=ax.get_xaxis_transform(), ha="left", va="top", fontsize=8,
                    color="0.3")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(True, alpha=0.3)
    if condition is not None and not summary.empty:
        # one entry per curve (its mean line) plus one for the shading and one for the fits
        handles = list(ax.get_legend_handles_labels()[0])  # the mean lines only
        handles.append(Patch(facecolor="0.6", alpha=0.35, label="interquartile range"))
        if bands:
            handles.append(Line2D([], [], color="0.3", linestyle="--", label="power-law fit"))
        ax.legend(handles=handles, fontsize=8, loc="upper right", framealpha=0.9)
    elif ax.get_legend_handles_labels()[0]:
        ax.legend(fontsize=8, loc="upper right", framealpha=0.9)
    return fig


def _boxes(ax: Axes, data: pd.DataFrame, group: str, value: str, order: Sequence[Any],
           labels: Mapping[Any, str] | None, colors: Mapping[Any, str] | bool | None,
           rng: np.random.Generator) -> None:
    series = [data.loc[data[group] == lev, value].to_numpy(dtype=float) for lev in order]
    series = [s[np.isfinite(s)] for s in series]
    if colors is False:
        cols = [PALETTE[0]] * len(order)
    else:
        cols = _colors_for(order, colors if isinstance(colors, Mapping) else None)
    pos = np.arange(1, len(order) + 1)
    present = [i for i, s in enumerate(series) if s.size]
    if present:
        bp = ax.boxplot([series[i] for i in present], positions=pos[present], widths=0.55,
                        whis=1.5, showfliers=False, patch_artist=True,
                        medianprops={"color": "black", "linewidth": 1.5},
                        boxprops={"linewidth": 1.0})
        for box, i in zip(bp["boxes"], present, strict=True):
            box.set_facecolor(cols[i])
            box.set_alpha(0.35)
    for i, s in enumerate(series):
        if not s.size:
            continue
        jitter = rng.uniform(-0.12, 0.12, size=s.size)
        ax.plot(pos[i] + jitter, s, "o", color=cols[i], markersize=3, alpha=0.75,
                markeredgewidth=0)
        ax.plot([pos[i]], [float(s.mean())], "D", color="white", markeredgecolor="black",
                markersize=6, zorder=5)
    sizes = {s.size for s in series}
    ax.set_xticks(pos)
    if len(sizes) == 1:  # the same n everywhere: said once, in the axis label
        ax.set_xticklabels([_tick(_label(labels, lev)) for lev in order])
    else:
        ax.set_xticklabels([f"{_tick(_label(labels, lev))}\n(n={s.size})"
                            for lev, s in zip(order, series, strict=True)])
    ax.set_xlim(0.4, len(order) + 0.6)
    ax.grid(True, axis="y", alpha=0.3)


def box_figure(
    data: pd.DataFrame,
    *,
    group: str,
    values: Sequence[tuple[str, str]],
    order: Sequence[Any],
    labels: Mapping[Any, str] | None = None,
    colors: Mapping[Any, str] | bool | None = None,
    xlabel: str,
    title: str,
    ncols: int = 3,
) -> Figure:
    """Box plots of one or more variables per group, one panel per variable.

    Args:
        data: one row per observation (the report: one per subject and cell).
        group: the grouping column. values: ``(column, y-axis label with unit)`` per panel.
        order: the group levels in x order. labels: display names of the levels.
        colors: per level its colour; None: the palette in order; False: one colour for
            all (levels that are not categories, e.g. trial numbers).
        xlabel: x-axis label (the number of observations per box is added when it is the
            same for every box, else it is given under each box). title: figure title.
        ncols: panels per row.

    Returns:
        The figure.
    """
    n = max(1, len(values))
    cols = min(n, ncols)
    rows = math.ceil(n / cols)
    fig = _new_figure(max(5.0, 4.6 * cols), 4.0 * rows + 0.3)
    axes = fig.subplots(rows, cols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.axis("off")
    rng = np.random.default_rng(0)  # fixed jitter: the same data give the same picture
    for ax, (col, ylabel) in zip(axes, values, strict=False):
        _boxes(ax, data, group, col, order, labels, colors, rng)
        ns = {int(np.isfinite(data.loc[data[group] == lev, col].to_numpy(dtype=float)).sum())
              for lev in order}
        ax.set_ylabel(ylabel)
        ax.set_xlabel(f"{xlabel} (n = {ns.pop()} per box)" if len(ns) == 1 else xlabel)
    fig.suptitle(title)
    return fig


def choice_rating_figure(
    best: pd.DataFrame | None,
    worst: pd.DataFrame | None,
    ratings: pd.DataFrame | None,
    *,
    order: Sequence[Any],
    labels: Mapping[Any, str] | None = None,
    colors: Mapping[Any, str] | None = None,
    rating_range: tuple[float, float] = (0.0, 10.0),
    noun: str = "VF",
) -> Figure:
    """The seed's Fig. 6.19: % choosing each condition as best and as worst, mean rating.

    Only the panels with data are drawn (one to three, in that order).

    Args:
        best, worst: columns ``condition, percent`` (None or empty: no panel).
        ratings: columns ``condition, mean, sd`` (None or empty: no panel).
        order: conditions in x order. labels: their display names. colors: their colours.
        rating_range: the rating scale (the rating panel's y axis, with room for the sd).
        noun: what the conditions are, in the titles ("VF", "mode").

    Returns:
        The figure.
    """
    panels: list[tuple[str, pd.DataFrame]] = []
    for kind, table in (("best", best), ("worst", worst), ("rating", ratings)):
        if table is not None and not table.empty:
            panels.append((kind, table))
    if not panels:
        return empty_figure("no choice or rating answered")
    fig = _new_figure(4.0 * len(panels) + 0.5, 3.8)
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    x = np.arange(len(order))
    names = [_tick(_label(labels, c)) for c in order]
    cols = _colors_for(order, colors)
    for ax, (kind, table) in zip(axes, panels, strict=True):
        ax.set_xticks(x)
        ax.set_xticklabels(names)
        ax.grid(True, axis="y", alpha=0.3)
        if kind in ("best", "worst"):
            ax.set_title(f"chosen as {kind} {noun}")
            pct = table.set_index("condition")["percent"].reindex(list(order)).fillna(0.0)
            bars = ax.bar(x, pct.to_numpy(dtype=float), color=cols)
            ax.bar_label(bars, labels=[f"{v:.0f} %" for v in pct], fontsize=8, padding=2)
            ax.set_ylabel("respondents [%]")
            ax.set_ylim(0, min(112.0, max(10.0, float(pct.max()) * 1.15)))
            continue
        ax.set_title(f"rating of each {noun} (mean ± sd, clipped to the scale)")
        r = table.set_index("condition").reindex(list(order))
        m = r["mean"].to_numpy(dtype=float)
        sd = np.nan_to_num(r["sd"].to_numpy(dtype=float))
        bars = ax.bar(x, np.nan_to_num(m), yerr=clipped_error_bars(m, sd, rating_range),
                      capsize=4, color=cols, error_kw={"linewidth": 1.0})
        ax.bar_label(bars, labels=["" if math.isnan(v) else f"{v:.2f}" for v in m],
                     fontsize=8, label_type="center")
        ax.set_ylabel(f"rating [{rating_range[0]:g}-{rating_range[1]:g}]")
        span = rating_range[1] - rating_range[0]
        ax.set_ylim(rating_range[0], rating_range[1] + 0.02 * span)
        ax.axhline(rating_range[1], color="0.5", linewidth=0.8, linestyle=":")
    return fig


def clipped_error_bars(mean: np.ndarray, sd: np.ndarray, scale: tuple[float, float]
                       ) -> np.ndarray:
    """Error bars mean ± sd clipped to a rating scale, as matplotlib's ``yerr`` (2, n).

    **Decision** (issue #15): ratings are shown within their scale, so the whiskers of
    mean ± 1 sd (the seed's Fig. 6.19 form) stop at the scale's ends instead of switching to
    an IQR, which would not be centred on the mean the bar shows. A NaN mean gets no bar.

    Args:
        mean: mean rating per condition. sd: its standard deviation (same unit).
        scale: (lowest, highest) value of the rating scale.

    Returns:
        ``[[lower lengths], [upper lengths]]`` (both >= 0).

    Example:
        >>> clipped_error_bars(np.array([9.0, 5.0]), np.array([2.0, 1.0]), (0.0, 10.0))
        array([[2., 1.],
               [1., 1.]])
    """
    m = np.nan_to_num(np.asarray(mean, dtype=float))
    s = np.nan_to_num(np.asarray(sd, dtype=float))
    lo = np.clip(m - s, scale[0], scale[1])
    hi = np.clip(m + s, scale[0], scale[1])
    return np.vstack([np.maximum(m - lo, 0.0), np.maximum(hi - m, 0.0)])


def label_png(png: bytes, label: str, *, dpi: int = _DPI) -> bytes:
    """Adds a text band under a PNG figure (the *synthetic* label of a simulated cohort).

    Args:
        png: a PNG image (``figure_png``'s output). label: the text; ``""`` returns
            ``png`` unchanged.

    Returns:
        A PNG as wide as ``png`` and a band taller, the label in dark red in the band.
    """
    if not label:
        return png
    from matplotlib.image import imread

    img = imread(io.BytesIO(png), format="png")
    h, w = img.shape[:2]
    band = round(0.28 * dpi)
    fig = Figure(figsize=(w / dpi, (h + band) / dpi), dpi=dpi)
    fig.figimage(img, xo=0, yo=band)
    fig.text(0.01, band / 2 / (h + band), label, color="#8b0000", fontsize=9,
             va="center", ha="left", style="italic")
    buf = io.BytesIO()
    FigureCanvasAgg(fig)
    fig.savefig(buf, format="png", dpi=dpi, facecolor="white")
    return buf.getvalue()


def counts_figure(
    counts: pd.DataFrame,
    *,
    label: str,
    value: str = "count",
    xlabel: str = "proposals",
    title: str,
    second: pd.DataFrame | None = None,
    second_label: str | None = None,
    second_title: str | None = None,
) -> Figure:
    """Horizontal bar chart of counts (the seed's Figs. 6.24-6.25: proposed schemas).

    Args:
        counts: one row per category: the ``label`` column and the ``value`` column.
        label: category column. value: count column. xlabel: x-axis label.
        title: panel title.
        second: optional second panel (e.g. how often each fixture is part of a proposal),
            same ``value`` column and ``second_label`` categories.
        second_label: category column of ``second``. second_title: its panel title.

    Returns:
        The figure.
    """
    n_rows = max(len(counts), len(second) if second is not None else 0, 1)
    fig = _new_figure(11.0 if second is not None else 6.5, max(2.4, 0.32 * n_rows + 1.3))
    axes = fig.subplots(1, 2 if second is not None else 1, squeeze=False)[0]
    panels = [(axes[0], counts, label, title)]
    if second is not None:
        panels.append((axes[1], second, second_label or label, second_title or ""))
    for ax, table, col, ttl in panels:
        ax.set_title(ttl)
        if table.empty:
            ax.text(0.5, 0.5, "no proposals", ha="center", va="center", transform=ax.transAxes)
            ax.set_yticks([])
            continue
        t = table.iloc[::-1]  # largest on top
        y = np.arange(len(t))
        bars = ax.barh(y, t[value].to_numpy(dtype=float), color=PALETTE[0], alpha=0.8)
        ax.bar_label(bars, fontsize=8, padding=2)
        ax.set_yticks(y)
        ax.set_yticklabels([str(v) for v in t[col]])
        ax.set_xlabel(xlabel)
        ax.set_xlim(0, float(t[value].max()) * 1.15 + 0.5)
        ax.grid(True, axis="x", alpha=0.3)
    return fig


def demographics_figure(
    counts: pd.DataFrame,
    *,
    fields: Sequence[tuple[str, str]],
    groups: Sequence[str],
    levels: Mapping[str, Sequence[str]],
) -> Figure:
    """The seed's Fig. 6.16: the cohort by specialisation and experience, per group.

    Args:
        counts: columns ``field, value, group, n`` (subjects per field value and group).
        fields: ``(field, panel title)`` per panel, in order.
        groups: group names stacked in each bar (e.g. surgeon, resident).
        levels: per field, its values in axis order.

    Returns:
        The figure (2 columns of panels).
    """
    n = max(1, len(fields))
    n_cols = 2
    n_rows = math.ceil(n / n_cols)
    fig = _new_figure(11.0, 3.2 * n_rows)
    axes = fig.subplots(n_rows, n_cols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.axis("off")
    for ax, (fld, ttl) in zip(axes, fields, strict=False):
        vals = list(levels.get(fld, ()))
        part = counts[counts["field"] == fld]
        y = np.arange(len(vals))
        left = np.zeros(len(vals))
        for gi, g in enumerate(groups):
            sub = part[part["group"] == g].set_index("value")["n"].reindex(vals).fillna(0)
            w = sub.to_numpy(dtype=float)
            ax.barh(y, w, left=left, color=PALETTE[gi % len(PALETTE)], label=g)
            left += w
        ax.set_yticks(y)
        ax.set_yticklabels([v.replace("_", " ") for v in vals])
        ax.invert_yaxis()
        ax.set_xlabel("subjects")
        ax.set_title(ttl)
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.grid(True, axis="x", alpha=0.3)
        if left.size and left.max() > 0:
            ax.set_xlim(0, left.max() * 1.1 + 0.5)
    if fields:
        handles, names = axes[0].get_legend_handles_labels()
        fig.legend(handles, names, loc="outside upper center", ncols=len(groups),
                   fontsize=9)
    return fig


__all__ = [
    "PALETTE",
    "CurveGroups",
    "CurveText",
    "box_figure",
    "choice_rating_figure",
    "counts_figure",
    "demographics_figure",
    "empty_figure",
    "figure_png",
    "learning_curve_figure",
]
