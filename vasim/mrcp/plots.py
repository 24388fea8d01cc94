"""The seed's MRCP run plots (Figs. 4.23-4.26): indices, ``texec``, ``ttransf*``, NTT and
RSel against time, one figure per scenario run.

Panels (shared time axis): (a) every index of every robot (colour = robot, line style =
index; RSel at CuTP, a candidate at its best point); (b) ``texec`` (the minimum over the
indices); (c) ``ttransf*`` of the candidates (0 for RSel); (d) NTT with the transfer
threshold (an infinite NTT — RSel has no useful time left — is drawn at the top of the
axis); (e) RSel. Dashed lines mark transfer starts, solid ones their completion. TT cycles
are not evaluated (gaps in (a)-(d)). A run with a state graph of subtasks
(``suture_combined``) shades its StdT subtasks in every panel (no MRCP kernel runs there).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from vasim.mrcp.scenarios.runner import RunResult

_STYLES = ("-", "--", ":", "-.", (0, (5, 1, 1, 1)), (0, (1, 3)))
NTT_TOP = 1.5


def _series(res: RunResult, robot: str, what: str, index: str | None = None) -> np.ndarray:
    out = np.full(len(res.samples), np.nan)
    for i, s in enumerate(res.samples):
        rs = s.robots.get(robot)
        if rs is None:
            continue
        if what == "value" and index is not None:
            out[i] = rs.values.get(index, math.nan)
        elif what == "texec":
            out[i] = rs.texec_min
        elif what == "ttransf":
            out[i] = rs.ttransf
    return out


def plot_run(res: RunResult, path: str | Path, ntt_threshold: float = 0.9,
             title: str | None = None) -> Path:
    """Saves the figure of a run to ``path`` (format from the suffix) and returns the path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    t = np.array([s.t for s in res.samples])
    indices = sorted({k for s in res.samples for rs in s.robots.values() for k in rs.values})
    colours = plt.get_cmap("tab10")
    fig, axes = plt.subplots(5, 1, sharex=True, figsize=(10, 11),
                             gridspec_kw={"height_ratios": [3, 2, 2, 2, 1]})
    ax_i, ax_te, ax_tt, ax_ntt, ax_sel = axes
    for ri, r in enumerate(res.robots):
        c = colours(ri % 10)
        for ii, name in enumerate(indices):
            ax_i.plot(t, _series(res, r, "value", name), color=c,
                      linestyle=_STYLES[ii % len(_STYLES)], label=f"{name} {r}")
        ax_te.plot(t, _series(res, r, "texec"), color=c, label=f"texec {r}")
        tt = _series(res, r, "ttransf")
        ax_tt.plot(t, np.where(np.isfinite(tt), tt, np.nan), color=c, label=f"ttransf* {r}")
    ntt = np.array([s.ntt for s in res.samples])
    ax_ntt.plot(t, np.where(np.isinf(ntt), NTT_TOP, np.clip(ntt, 0.0, NTT_TOP)), color="k",
                label="NTT")
    ax_ntt.axhline(ntt_threshold, color="r", linewidth=0.8, label="threshold")
    ax_ntt.set_ylim(-0.05, NTT_TOP + 0.05)
    sel = np.array([res.robots.index(s.rsel) for s in res.samples])
    ax_sel.step(t, sel, where="post", color="k")
    ax_sel.set_yticks(range(len(res.robots)), res.robots)
    ax_sel.set_ylim(-0.5, len(res.robots) - 0.5)
    for tr in res.transfers():
        for ax in axes:
            ax.axvline(tr["t_start"], color="grey", linestyle="--", linewidth=0.8)
            if tr["t_done"] is not None:
                ax.axvline(tr["t_done"], color="grey", linewidth=0.8)
    for sub in res.extra.get("subtasks", []):
        if sub.get("mode") == "stdt":
            for ax in axes:
                ax.axvspan(sub["t_start"], sub["t_end"], color="0.85", alpha=0.6, linewidth=0)
            ax_sel.text(0.5 * (sub["t_start"] + sub["t_end"]), len(res.robots) - 0.7,
                        f"StdT: {sub['name']}", ha="center", fontsize="small")
    for ax, label in zip(axes, ("index value", "texec [s]", "ttransf* [s]", "NTT", "RSel"),
                         strict=True):
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    ax_i.set_ylim(-0.05, 1.05)
    ax_i.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    for ax in (ax_te, ax_tt, ax_ntt):
        ax.legend(loc="upper left", bbox_to_anchor=(1.0, 1.0), fontsize="small")
    ax_sel.set_xlabel("t [s]")
    fig.suptitle(title or f"MRCP scenario {res.scenario}")
    fig.tight_layout()
    out = Path(path)
    fig.savefig(out, dpi=110)
    plt.close(fig)
    return out
