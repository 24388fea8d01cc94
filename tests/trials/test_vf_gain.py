"""A VF trial at a fixture gain (vasim/trials/vf.py with vasim/fixtures/gain_runtime.py;
issue #18 item 1): gain 0 is no assistance, the gain is logged per sample, the trial's
configuration stores and restores its rule."""

from __future__ import annotations

import json

import numpy as np
import pytest

from vasim.core.errors import ConfigError
from vasim.fixtures.gain import AdaptiveRule
from vasim.trials.vf import TrialConfig, TrialRunner, make_profile
from vasim.trials.vf_run import config_record

T = 2.0
RULE = AdaptiveRule(gain_min=0.25, gain_max=1.0, tau_s=0.3, deviation_full_m=0.003,
                    initial=0.5)


def trial(schema: str, gain=1.0, seed: int = 4):
    r = TrialRunner(TrialConfig(schema=schema, seed=seed, max_time=T, scene="none",
                                gain=gain))
    r.advance(T)
    return r.result()


@pytest.mark.parametrize("schema", ["ff", "mag", "ag_mag"])
def test_gain_zero_is_the_fixture_free_trial(schema: str):
    free = trial("none").samples.view()
    zero = trial(schema, 0.0).samples.view()
    assert np.array_equal(free["x"], zero["x"])
    assert not zero["force"].any() and not zero["audio_volume"].any()
    assert np.all(zero["zoom"] == 1.0) and np.all(zero["gain"] == 0.0)
    full = trial(schema).samples.view()
    assert not np.array_equal(free["x"], full["x"])  # the fixture does act at gain 1
    assert np.all(full["gain"] == 1.0)


def test_constant_gain_is_logged_and_summarised():
    res = trial("ff", 0.5)
    v = res.samples.view()
    assert np.all(v["gain"] == 0.5) and np.abs(v["force"]).max() > 0
    assert res.summary["gain_mean"] == 0.5
    assert "gain_mean" not in trial("ff").summary  # a constant schema's summary is as before


def test_adaptive_gain_is_logged_within_its_bounds_and_reacts_to_the_deviation():
    res = trial("ff", RULE)
    g = res.samples.view()["gain"]
    assert g.min() >= 0.25 and g.max() <= 1.0
    assert abs(g[0] - 0.5) < 0.01  # from the start gain (one step of 1 ms)
    assert g.std() > 0.01  # it moves with the deviation
    assert res.summary["gain_mean"] == pytest.approx(float(g.mean()))


def test_the_stored_configuration_keeps_and_restores_the_rule():
    cfg = TrialConfig(schema="ff", seed=1, max_time=1.0, gain=RULE)
    rec = json.loads(json.dumps(config_record(cfg, make_profile(cfg))))
    assert rec["gain"]["tau_s"] == 0.3
    restored = TrialConfig(**{k: v for k, v in rec.items() if k != "profile"})
    assert restored.gain == RULE
    assert "gain" not in config_record(TrialConfig(), make_profile(TrialConfig()))
    with pytest.raises(ConfigError) as err:
        TrialConfig(gain=1.5)
    assert err.value.field == "gain" and "got 1.5" in str(err.value)
