"""The viewer's own live trial publishes its frame as a long catch-up goes (vasim/viewer/
live.py ``SimThreadTrial._advance``, issue #31): at 1000x one loop iteration runs 50 s of
simulated time, seconds of wall time, and the pages and the "running behind" meter saw the
trial only at its end. The chunked run makes the same steps in the same order."""

from __future__ import annotations

import numpy as np

from vasim.trials.vf import TrialConfig, TrialRunner
from vasim.viewer.live import FRAME_STEPS, SimThreadTrial

CONFIG = TrialConfig(schema="ff", scene="none", seed=3, max_time=5.0)


def test_a_long_catch_up_publishes_a_frame_every_frame_steps_steps() -> None:
    trial = SimThreadTrial(CONFIG, speed=1000.0)
    published: list[int] = []
    publish = trial.runner._publish

    def counting() -> None:
        publish()
        published.append(trial.runner.frame.k)

    trial.runner._publish = counting  # type: ignore[method-assign]
    n = 5 * FRAME_STEPS + 37
    trial._advance(n)
    # a frame after each FRAME_STEPS steps and one at the end, each at the step it shows
    assert published == [*range(FRAME_STEPS - 1, n, FRAME_STEPS), n - 1]


def test_the_chunked_catch_up_runs_the_same_trial_as_one_advance() -> None:
    trial = SimThreadTrial(CONFIG, speed=1000.0)
    trial._advance(2 * FRAME_STEPS + 11)
    trial._advance(3 * FRAME_STEPS)
    whole = TrialRunner(CONFIG)
    whole.advance((5 * FRAME_STEPS + 11) * CONFIG.dt)
    a, b = trial.runner.frame, whole.frame
    assert (a.k, a.t, a.goal_index, a.error_l1) == (b.k, b.t, b.goal_index, b.error_l1)
    np.testing.assert_array_equal(a.tcp, b.tcp)
    np.testing.assert_array_equal(a.master, b.master)
    ra, rb = trial.result(), whole.result()
    assert len(ra.samples) == 5 * FRAME_STEPS + 11
    assert ra.samples.to_frame().equals(rb.samples.to_frame())
