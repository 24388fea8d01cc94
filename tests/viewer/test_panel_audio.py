"""Pure parts of the experimenter panel (escaping, texts, the f5PL curve) and the AG audio
stream's per-client delivery and rate, without a browser."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace
from typing import Any

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

import vasim.viewer.audio as audio
from vasim.fixtures.logistic import Logistic5
from vasim.fixtures.types import AudioCue
from vasim.viewer.audio import SYNTH_JS, AudioStream, cue_params
from vasim.viewer.controller import PanelState
from vasim.viewer.panel import f5pl_curve, md_escape, progress_text, summary_text


@given(st.text())
def test_md_escape_leaves_no_markup(text: str) -> None:
    out = md_escape(text)
    assert "<" not in out and ">" not in out and '"' not in out
    # Every markdown special character is backslash-escaped.
    stripped = out.replace("\\\\", "")
    for ch in "*_`[]()#|~":
        assert stripped.count(ch) == stripped.count("\\" + ch)


def test_progress_shows_trial_k_of_n_and_escapes_the_subject() -> None:
    p = PanelState(mode="protocol", subject="<b>S1</b>", protocol="vf_learning_curve",
                   position=3, total=38, completed=2, condition="vg")
    text = progress_text(p)
    assert "trial **3 of 38**" in text and "condition **vg**" in text
    assert "<b>" not in text and "&lt;b&gt;" in text
    assert "free" in progress_text(PanelState(mode="free"))


def test_summary_table_shows_missing_values_as_dashes() -> None:
    text = summary_text({"completion_time": math.nan, "points_reached": 30, "x": None,
                         "mean_latency": 0.8123})
    assert "| completion\\_time | — |" in text and "| points\\_reached | 30 |" in text
    assert "0\\.8123" in text
    assert "no finished trial" in summary_text(None)


@given(a=st.floats(-5, 5), d=st.floats(-5, 5), b=st.floats(0.1, 10), c=st.floats(1e-3, 1),
       g=st.floats(0.2, 5))
def test_f5pl_curve_spans_zero_to_three_c_and_matches_the_function(a, d, b, c, g) -> None:
    p = Logistic5(a=a, b=b, c=c, d=d, g=g)
    x, y = f5pl_curve(p, n=20)
    assert x[0] == 0.0 and math.isclose(x[-1], 3 * c)
    np.testing.assert_allclose(y, [p(float(v)) for v in x], rtol=1e-12, atol=1e-12)


class _Conn:
    def __init__(self) -> None:
        self.sources: list[str] = []

    def queue_message(self, msg: Any) -> None:
        self.sources.append(msg.source)


def _client(cid: int) -> Any:
    return SimpleNamespace(client_id=cid, _websock_connection=_Conn())


def _params(client: Any) -> list[dict[str, Any]]:
    out = []
    for s in client._websock_connection.sources:
        if s.startswith("window.__vasimAudioSet"):
            out.append(json.loads(s[s.index("(", 30) + 1: s.rindex(")")]))
    return out


def test_audio_goes_to_each_client_never_broadcast_at_the_stream_rate() -> None:
    clients = {1: _client(1)}
    # A server object without any broadcast method: using one would raise.
    server = SimpleNamespace(get_clients=lambda: dict(clients))
    stream = AudioStream(server, rate_hz=20.0)  # type: ignore[arg-type]
    stream.install(clients[1])
    assert clients[1]._websock_connection.sources == [SYNTH_JS]
    cue = AudioCue(600.0, 0.3, 0.5)
    for i in range(100):  # 1 s of view updates at 100 Hz
        stream.update(cue, now=10.0 + i * 0.01)
    sent = _params(clients[1])
    assert len(sent) == 20 and sent[-1] == cue_params(cue)
    # A second tab (or a reload) gets the synth and the current cue at once.
    clients[2] = _client(2)
    stream.install(clients[2])
    assert _params(clients[2]) == [cue_params(cue)]
    # AG goes away (schema without AG): one "off" to each, then nothing.
    stream.update(None, now=12.0)
    stream.update(None, now=13.0)
    assert _params(clients[1])[-1] == {"on": False} and _params(clients[2]) [-1] == {"on": False}
    assert sum(p == {"on": False} for p in _params(clients[1])) == 1
    # A client that left is forgotten.
    del clients[1]
    stream.update(cue, now=14.0)
    assert stream._installed == {2}


# -- The audio stream survives clients connecting while it sends.
def test_audio_install_during_an_update_does_not_break_the_stream(
        monkeypatch: pytest.MonkeyPatch) -> None:
    """A client connecting (viser callback thread) while update() sends (view thread): the
    send to the first client installs another, deterministically, in the middle of the
    iteration (this raised "Set changed size during iteration")."""
    clients: dict[int, Any] = {i: SimpleNamespace(client_id=i) for i in range(3)}
    sets: list[int] = []
    armed = [False]

    def run_js(client: Any, src: str, key: str | None = None) -> None:
        if src.startswith("window.__vasimAudioSet"):
            sets.append(client.client_id)
            if armed[0]:  # a client connects while update() is sending
                armed[0] = False
                clients[99] = SimpleNamespace(client_id=99)
                stream.install(clients[99])

    monkeypatch.setattr(audio, "run_js", run_js)
    stream = AudioStream(SimpleNamespace(get_clients=lambda: dict(clients)),  # type: ignore[arg-type]
                         rate_hz=1e9)
    for c in list(clients.values()):
        stream.install(c)
    cue = AudioCue(600.0, 0.2, 0.5)
    armed[0] = True
    stream.update(cue, now=1.0)  # raised "Set changed size during iteration"
    assert sorted(sets) == [0, 1, 2, 99]  # 99 got the cue from install()
    assert stream._installed == {0, 1, 2, 99}
    sets.clear()
    stream.update(cue, now=2.0)
    assert sorted(sets) == [0, 1, 2, 99]
