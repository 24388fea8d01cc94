"""A browser protocol session's later sitting (issue #18 §2): the trial that begins it
carries a 'sitting' event with the real time elapsed since the previous trial."""

from __future__ import annotations

import json
import time
from pathlib import Path

from vasim.study.session import SITTING_EVENT
from vasim.study.store import TrialStore
from vasim.viewer.controller import Command, TrainingController


def test_the_browser_records_the_sitting_that_begins_the_retention_block(
        tmp_path: Path) -> None:
    db = tmp_path / "s.sqlite"
    c = TrainingController(scene="none", db=db, speed=25.0, pause_s=0.05, max_time=0.3)

    def drive(cond, timeout: float = 30.0) -> bool:
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            c.poll()
            if cond():
                return True
            time.sleep(0.01)
        return cond()

    try:
        for cmd in (Command("mode", "protocol"), Command("subject", "B01"),
                    Command("protocol", "vf_retention")):
            c.handle(cmd)
        for _ in range(14):               # sitting 1 (13 trials) + the first retention probe
            c.handle(Command("start"))
            assert drive(lambda: c.info.trial_id is not None and not c.panel.running)
        sid = c.panel.session_id
        assert sid is not None
    finally:
        c.close()
    with TrialStore(db, readonly=True) as st:
        ids = [None if t is None else int(t) for t in st.schedule(sid)["trial_id"]
               .astype(object).where(st.schedule(sid)["trial_id"].notna(), None)]
        assert all(i is not None for i in ids[:14]) and ids[14] is None
        marked = [i for i in ids[:14] if (st.events(i)["kind"] == SITTING_EVENT).any()]
        assert marked == [ids[13]]
        ev = st.events(ids[13])
        rec = json.loads(ev[ev["kind"] == SITTING_EVENT]["detail"].iloc[0])
        assert (rec["sitting"], rec["block"], rec["delay_days"], rec["simulated"]) == (
            2, "retention", 7.0, False)
        # the real gap between trial 13's end and trial 14's start, in days
        assert 0.0 <= rec["elapsed_days"] < 60.0 / 86_400
