"""The traceability section: where every number comes from."""

from __future__ import annotations

from collections.abc import Sequence

import pandas as pd

from vasim.study.report.html_page import (
    Paragraph,
    Section,
    TableBlock,
)


# --------------------------------------------------------------------------- traceability
def traceability_section(tables: Sequence[TableBlock]) -> Section:
    """Where every number comes from: the CSV files and how each is traced."""
    rows = []
    for t in tables:
        cols = set(t.data.columns)
        if "trial_id" in cols or "trial_ids" in cols:
            how = "trial_id(s) column"
        elif "session_ids" in cols or "session_id" in cols:
            how = "session_id(s) column" + (" + provenance.csv" if t.name in {
                "questionnaire_spearman"} else "")
        else:
            how = "provenance.csv (rows with table = name)"
        if t.name in ("vf_rm_anova", "vf_posthoc_tukey", "vf_posthoc_paired",
                      "vf_seed_replication", "vf_learning_fit", "mrcp_paired", "mrcp_gains",
                      "mrcp_learning_fit", "questionnaire_spearman"):
            how = "provenance.csv (rows with table = name)"
        rows.append({"table": f"tables/{t.name}.csv", "title": t.title, "rows": len(t.data),
                     "traced_by": how})
    rows.append({"table": "tables/provenance.csv", "title": "provenance of the test tables",
                 "rows": "", "traced_by": "table, group (the cell), subject, session_ids, "
                                          "trial_ids"})
    return Section("traceability", "Traceability", (
        Paragraph(
            "Every number of this report traces back to stored trials. Tables with one row "
            "per trial carry its trial_id; tables of groups or cells carry the trial_ids "
            "(space-separated) they were computed from; questionnaire tables carry the "
            "session_ids of the answers; statistical-test tables (ANOVA, post hoc, fits, "
            "gains) are traced through tables/provenance.csv, which lists per table, cell "
            "(group) and subject the trial ids averaged into that cell. Trial ids are the "
            "store's trials.id (vasim study export writes the same ids). The samples table "
            "is not read: the per-point and per-trial metrics stored with each trial are."),
        TableBlock("", "Tables written", pd.DataFrame(rows)),
    ))


