"""The box-plot section: subject-level cells per fixture and per VF-free trial."""

from __future__ import annotations

from vasim.study.report.analysis import VfAnalysis
from vasim.study.report.common import (
    FIXTURE_COLORS,
    PLOT_NAMES,
    SectionOut,
)
from vasim.study.report.figures import (
    box_figure,
    figure_png,
)
from vasim.study.report.html_page import (
    FigureBlock,
    Section,
    TableBlock,
)


def box_plot_section(vf: VfAnalysis) -> tuple[Section, list[dict[str, str]]]:
    """Box plots of the subject-level cells per fixture and per VF-free trial."""
    out = SectionOut()
    values = [(dv, f"{PLOT_NAMES[dv]} [{unit}]") for dv, _, unit in vf.dvs]
    fc = vf.fixture_cells
    if fc.empty:
        out.notes.append("no analysed VF trial: no box plots")
        return out.section("boxplots", "Box plots"), []
    fig = box_figure(fc, group="fixture", values=values, order=list(vf.fixture_levels),
                     colors=FIXTURE_COLORS,
                     xlabel="fixture", title="Per fixture: subject means")
    out.blocks.append(FigureBlock(
        "box_fixture", "Per fixture", figure_png(fig),
        "One dot per subject: the subject's mean over its trials of the fixture ('none' = "
        "its VF-free trials); box = quartiles, line = median, diamond = mean, whiskers = "
        "1.5 IQR. Numbers: tables/vf_cells_fixture.csv (every subject; the RM-ANOVA uses "
        "the subjects with every cell)."))
    out.blocks.append(TableBlock(
        "vf_cells_fixture", "Subject x fixture cells", fc,
        "Mean per subject and fixture of each outcome (path_deviation [mm], latency [s], "
        "eq65 [mm·s]); trial_ids: the trials averaged.", display="csv"))
    tc = vf.trial_cells
    if tc.empty:
        out.notes.append("no VF-free probe trial: no box plot per trial")
    else:
        fig = box_figure(tc, group="trial", values=values, order=list(vf.trial_levels),
                         colors=False,
                         xlabel="VF-free trial number", title="Per VF-free trial")
        out.blocks.append(FigureBlock(
            "box_trial", "Per VF-free trial", figure_png(fig),
            "One dot per subject and probe trial. Numbers: tables/vf_cells_trial.csv."))
        out.blocks.append(TableBlock(
            "vf_cells_trial", "Subject x VF-free trial cells", tc,
            "One probe trial per subject and number.", display="csv"))
    return out.section("boxplots", "Box plots"), []


