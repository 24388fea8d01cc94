"""What a power run leaves in ``--out``: ``power.csv``, ``power_cohorts.csv``,
``power.png`` and the printed table.

* ``power.csv``: :data:`~vasim.study.power.estimate.POWER_COLUMNS`, one row per primary
  test and N (power, its Monte Carlo standard error, 95 % Wilson interval).
* ``power_cohorts.csv``: every cohort's test results (F, p, partial eta squared), so
  another alpha or p-value can be recomputed without simulating again.
* ``power.png``: power against N, one panel per factor (the PRIMARY probe model's fixture
  test, then the seed's RM-ANOVAs: fixture effect, practice effect),
  one line per outcome, error bars +-1 Monte Carlo standard error, the target 0.8 dashed,
  and the synthetic-data label of every report figure.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.ticker import MaxNLocator

from vasim.study.power.estimate import smallest_n
from vasim.study.report.data import SYNTHETIC_LABEL

TARGET_POWER = 0.8
"""The power a plan usually asks for (dashed in the figure, ``N for 0.8`` in the table)."""
FACTOR_TITLES = {"practised": "PRIMARY: post-block probe model (fixture practised)",
                 "fixture": "seed's RM-ANOVA: fixture effect",
                 "trial": "seed's RM-ANOVA: practice effect (VF-free probes)"}
DV_STYLE = {"eq65": ("eq. 6.5 e", "tab:blue", "o"),
            "latency": ("latency", "tab:orange", "s"),
            "path_deviation": ("path deviation", "tab:green", "^")}


def format_table(power: pd.DataFrame) -> str:
    """The power table as printed: one line per test, one column per N,
    ``power +- mc_se``, and the smallest N of the grid reaching :data:`TARGET_POWER`.

    Example:
        >>> t = pd.DataFrame({"test": ["fixture effect on latency"] * 2,
        ...                   "n_subjects": [4, 8], "power": [0.5, 0.9],
        ...                   "mc_se": [0.1, 0.05]})
        >>> print(format_table(t))
        test                       N=4          N=8          N for 0.8
        fixture effect on latency  0.50 ± 0.10  0.90 ± 0.05  8
    """
    ns = sorted(int(n) for n in power["n_subjects"].unique())
    need = smallest_n(power, TARGET_POWER)
    tests = list(dict.fromkeys(power["test"]))
    w = max([len("test"), *(len(t) for t in tests)])
    head = ["test".ljust(w)] + [f"N={n}".ljust(11) for n in ns] + [f"N for {TARGET_POWER}"]
    lines = ["  ".join(head)]
    for t in tests:
        g = power[power["test"] == t].set_index("n_subjects")
        cells = [(f"{g.loc[n, 'power']:.2f} ± {g.loc[n, 'mc_se']:.2f}" if n in g.index
                  else "-").ljust(11) for n in ns]
        n80 = need.get(t)
        lines.append("  ".join([t.ljust(w), *cells, str(n80) if n80 else f"> {ns[-1]}"]))
    return "\n".join(lines)


def plot_power(power: pd.DataFrame, path: Path, *, title: str) -> Path:
    """Writes ``power.png``: power +- 1 MC standard error against N (module docstring)."""
    factors = [f for f in ("practised", "fixture", "trial") if f in set(power["factor"])]
    # a Figure without pyplot, as the report's figures: no global state, no GUI backend
    fig = Figure(figsize=(5.2 * max(1, len(factors)), 4))
    FigureCanvasAgg(fig)
    axes = fig.subplots(1, max(1, len(factors)), squeeze=False, sharey=True)
    for ax, factor in zip(axes[0], factors, strict=False):
        sub = power[power["factor"] == factor]
        for dv, g in sub.groupby("dv", sort=False):
            name, colour, marker = DV_STYLE.get(str(dv), (str(dv), None, "o"))
            g = g.sort_values("n_subjects")
            ax.errorbar(g["n_subjects"], g["power"], yerr=g["mc_se"], label=name,
                        color=colour, marker=marker, capsize=3, lw=1.4)
        ax.axhline(TARGET_POWER, ls="--", color="0.5", lw=1)
        ax.set_title(FACTOR_TITLES.get(factor, factor), fontsize=10)
        ax.set_xlabel("subjects N")
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="lower right")
    axes[0][0].set_ylabel("power (± 1 Monte Carlo s.e.)")
    fig.suptitle(title, fontsize=10)
    fig.text(0.5, 0.005, SYNTHETIC_LABEL, ha="center", va="bottom", fontsize=7, color="0.3")
    fig.tight_layout(rect=(0, 0.04, 1, 0.95))
    fig.savefig(path, dpi=110)
    return path


def write_outputs(out: Path, power: pd.DataFrame, cohorts: pd.DataFrame, *,
                  title: str) -> list[Path]:
    """Writes the three files into ``out`` (created) and returns their paths."""
    out.mkdir(parents=True, exist_ok=True)
    p_csv, c_csv, png = out / "power.csv", out / "power_cohorts.csv", out / "power.png"
    power.to_csv(p_csv, index=False)
    cohorts.to_csv(c_csv, index=False)
    plot_power(power, png, title=title)
    return [p_csv, c_csv, png]


__all__ = ["TARGET_POWER", "format_table", "plot_power", "write_outputs"]
