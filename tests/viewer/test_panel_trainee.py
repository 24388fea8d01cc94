"""The trainee's live numbers (vasim/viewer/panel.py ``metrics_text``): distances in mm to
the planned path and to the goal, points reached, time; no sum of samples shown as a
length."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from vasim.viewer.panel import metrics_text

POINTS = np.array([[0.01, 0.0, 0.0], [0.02, 0.0, 0.0]])


def _text(tcp, goal_index):
    info = SimpleNamespace(number=2, mode="demo", trial_id=None, points=POINTS,
                           start=np.zeros(3), title="demo run 2 (not stored)",
                           config=SimpleNamespace(max_time=180.0), fixtures=(),
                           gain_plan="constant")
    goal = POINTS[min(goal_index, 1)]
    frame = SimpleNamespace(t=1.25, tcp=np.asarray(tcp, float), goal=goal,
                            goal_index=goal_index, n_points=2, done=goal_index >= 2,
                            gain=1.0)
    return metrics_text(info, frame, [0.5])


def test_distances_to_path_and_goal_in_mm():
    text = _text([0.005, 0.003, 0.004], 0)     # 5 mm from the start, 3-4-5 off the path
    assert "| Distance to path | 5.0 mm |" in text
    goal_mm = 1000 * np.linalg.norm([0.005, 0.003, 0.004])
    assert f"| Distance to goal | {goal_mm:.1f} mm |" in text
    assert "| Points | 0 / 2 |" in text and "| Time | 1.25 s of 180 s |" in text
    assert "e_i" not in text and "error_l1" not in text


def test_after_the_last_point_there_is_no_path_distance():
    text = _text([0.02, 0.0, 0.0], 2)
    assert "| Distance to path | — |" in text and "| Points | 2 / 2 |" in text
