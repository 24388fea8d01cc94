"""The trainee's and the experimenter's pages through the app (no browser): one trial number
on both, the time left, a timed-out trial said as such (never "done"), the score card, and
the endoscope's light following the scope (issue #19 §1, §4; issue #20 §1, §5)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from tests.polling import wait_for
from vasim.viewer import TrialOptions, ViewerApp, ViewerPace
from vasim.viewer.controller import Command


def test_a_timed_out_trial_on_both_pages(tmp_path: Path) -> None:
    app = ViewerApp(port=0, db=str(tmp_path / "s.sqlite"), scene="none",
                    trials=TrialOptions(schema="vg", max_time=1.5, countdown_s=0.0),
                    pace=ViewerPace(speed=3.0)).start()
    try:
        for cmd in (Command("mode", "free"), Command("subject", "S01"), Command("start")):
            app.submit(cmd)
        assert wait_for(lambda: app.snapshot.info.trial_id is not None), app.errors
        info = app.snapshot.info
        title = f"trial {info.trial_id}"
        assert wait_for(lambda: f"**{title}** — running" in app.hud.text), app.hud.text
        assert "s left)" in app.hud.text
        ended = f"**{title}** — ended: time ran out"
        assert wait_for(lambda: ended in app.hud.text), app.hud.text
        assert "done" not in app.hud.text and "s left)" not in app.hud.text
        # the card's text and its visibility are two updates: wait for both
        assert wait_for(lambda: f"Score card — {title}" in app.score.content
                        and app.score.visible), app.errors
        assert "**time ran out**" in app.score.content
        # The experimenter's page names the same trial the same way.
        assert wait_for(lambda: f"| Trial | {title} (free, ended: time ran out) |"
                        in app.panel_view.metrics_md), app.panel_view.metrics_md
        assert f"Score card — {title}" in app.panel_view.card.content
        assert app.panel.status.startswith(f"{title} stored")
        # The scope's light sits at the camera, shining at what it looks at.
        pose = app.camera.target
        np.testing.assert_allclose(app.light.spot.position, pose.position)
    finally:
        app.stop()
