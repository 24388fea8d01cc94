"""The browser viewer: server cost per rendered frame, updates streamed to a real browser,
and the trial's loop rates with and without a browser attached.

``vasim serve``'s app (``ViewerApp``) on the default deforming abdomen with the
``trajectory_following`` schema, which draws every overlay (VG arrow, FF arrow, MS ghost,
Mag camera, AG audio stream), a scripted operator playing the trial in real time (the
1 kHz servo loop of ``vasim.trials.realtime`` when present). Two runs of ``SECONDS``
(8 s; ``--seconds`` or ``VASIM_BENCH_VIEWER_S`` override), each on a fresh trial:

1. no browser: the views are updated all the same (40 Hz), nobody receives them;
2. a bare websocket client (Python, viser's subprotocol) that receives the stream without
   rendering it: the server's streaming cost alone, with no browser competing for the CPU;
3. one headless Chromium attached (Debian's ``/usr/bin/chromium`` + playwright; the run is
   skipped with the reason when either is missing). Its software WebGL shares the host's
   cores with the servo loop: compare its loop rates with run 2 to tell the two apart.

Figures per run:

* server cost per rendered frame: the view thread's CPU time per update (all organ
  vertices, tool, trajectory, arrows, ghost, HUD, panel, camera, audio) [ms], p50/p95, and
  the whole process's CPU per wall second (the difference between the runs is what the
  websocket streaming to the browser costs);
* view updates per wall second (the view thread's rate);
* in the browser: scene batches received per second that move the tool tip (the
  "updates/s streamed", target >= 30/s; capped by the view thread's 40 Hz and viser's
  1/60 s send window), every message per second, and the page's frames per second
  (``requestAnimationFrame``: software WebGL here, 2 cores shared);
* the trial: servo rate achieved [Hz] and the physics thread's rate [Hz]
  (``RealtimeTrial.timing()``), or the viewer's sim thread's control rate.

0. before any page (issue #26.2, "measure first"): the messages the trainee's server
   queues per view frame, by node group (organs, task points, instrument, overlays, frame
   mark, light, text/GUI), for ``ViewerPace(scene_hz=None)`` (the organs and the task's
   points with every frame, as before) and for the default (``flow.ScenePacer``: 10 Hz,
   slower for a slow page);

4. the same Chromium page at a laptop's 1280x800 with its CPU throttled 4x (DevTools
   ``Emulation.setCPUThrottlingRate``), the trainee driving the instrument (a keyboard
   trial): the page's **backlog** (messages waiting in its queue, sampled every 50 ms:
   max and p95), the **displayed-clock lag** (trial time now minus the trial time of the
   frame the page has applied, from its acknowledgements: p50 and max [s]), windows of
   updates in flight, the page's update rate, and the **control-to-photon latency** (a key press in
   the page to the first animation frame that shows the tool tip moved, page clock,
   median of several presses [ms]). Goals (issue #26.2): backlog < 10 updates, lag
   < 0.5 s, latency < 150 ms. The backlog is given both in frame updates (frame marks
   waiting in the page's queue: each window of a frame carries one) and in messages; the
   messages the page received per frame update it applied, by node group. Run twice, on a
   fresh app each: the organs with every frame (before) and paced (after).

``--smoke``: 2 s runs (checks that everything runs; figures are not meaningful).
The host is shared (other jobs run), so compare the two runs within one invocation.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from typing import Any

from vasim.viewer.flow import MARK_NODE

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""
SECONDS = float(os.environ.get("VASIM_BENCH_VIEWER_S", "1" if SMOKE else "8"))

COUNTER_JS = """() => {
  const m = window.__viserMutable, q = m.messageQueue;
  const c = window.__vasimBench = {tip: 0, messages: 0, frames: 0, batches: 0};
  let pending = false, tipInBatch = false;
  const push = q.push;
  q.push = function (...msgs) {
    for (const msg of msgs) {
      c.messages += 1;
      if (!pending) {
        pending = true; c.batches += 1; tipInBatch = false;
        queueMicrotask(() => { pending = false; });
      }
      if (msg.type === "SetPositionMessage" && msg.name === "/tool/tip" && !tipInBatch) {
        tipInBatch = true; c.tip += 1;
      }
    }
    return push.apply(this, msgs);
  };
  const frame = () => { c.frames += 1; requestAnimationFrame(frame); };
  requestAnimationFrame(frame);
  return true;
}"""


def _cpu() -> float:
    t = os.times()
    return t.user + t.system


class _BareClient:
    """Receives the viewer's websocket stream on a thread without rendering it."""

    def __init__(self, url: str):
        import threading

        self.url = url.replace("http://", "ws://")
        self.messages = 0
        self.bytes = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def __enter__(self) -> _BareClient:
        self._thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop.set()
        self._thread.join(5.0)

    def _run(self) -> None:
        import asyncio

        asyncio.run(self._recv())

    async def _recv(self) -> None:
        import asyncio

        import viser
        import websockets

        async with websockets.connect(self.url, subprotocols=[f"viser-v{viser.__version__}"],
                                      max_size=None) as ws:
            while not self._stop.is_set():
                try:
                    m = await asyncio.wait_for(ws.recv(), 0.2)
                except TimeoutError:
                    continue
                self.messages += 1
                self.bytes += len(m)


def _measure(app: Any, seconds: float, page: Any = None,
             bare: _BareClient | None = None) -> dict[str, float]:
    """Restarts the demo trial, runs ``seconds`` and returns the run's figures."""
    app.request_restart()
    n0 = app.snapshot.info.number
    t_end = time.monotonic() + 10.0
    while app.snapshot.info.number == n0 and time.monotonic() < t_end:
        time.sleep(0.02)
    app._view_costs.clear()
    u0, c0, w0 = app._view_updates, _cpu(), time.perf_counter()
    b0 = page.evaluate("() => ({...window.__vasimBench})") if page is not None else None
    m0 = (bare.messages, bare.bytes) if bare is not None else (0, 0)
    time.sleep(seconds)
    wall = time.perf_counter() - w0
    stats = app.stats()
    out = {
        "view_ms_p50": float(_pct(app._view_costs, 50)),
        "view_ms_p95": float(stats["view_ms_p95"]),
        "view_hz": (app._view_updates - u0) / wall,
        "process_cpu": (_cpu() - c0) / wall,
        "servo_hz": stats.get("trial_achieved_hz", stats.get("trial_control_hz", float("nan"))),
        "physics_hz": stats.get("trial_physics_rate_hz", float("nan")),
        "sim_t": float(app.snapshot.frame.t),
        "wall": wall,
    }
    if bare is not None:
        out["ws_messages_per_s"] = (bare.messages - m0[0]) / wall
        out["ws_kb_per_s"] = (bare.bytes - m0[1]) / wall / 1e3
    if page is not None:
        b1 = page.evaluate("() => ({...window.__vasimBench})")
        for k in ("tip", "messages", "frames", "batches"):
            out[f"browser_{k}_per_s"] = (b1[k] - b0[k]) / wall
    return out


BACKLOG_JS = """() => {
  const m = window.__viserMutable, q = m.messageQueue;
  const b = window.__vasimBacklog = {samples: [], frames: [], got: {}, n: 0};
  const group = (msg) => {
    const n = msg.name || "";
    for (const [label, prefix] of %(groups)s) { if (n.startsWith(prefix)) { return label; } }
    return msg.type.startsWith("Gui") ? "text/GUI" : msg.type;
  };
  const push = q.push;
  q.push = function (...msgs) {
    for (const msg of msgs) { const g = group(msg); b.got[g] = (b.got[g] || 0) + 1; b.n += 1; }
    return push.apply(this, msgs);
  };
  setInterval(() => {
    b.samples.push(q.length);
    // Frame updates waiting: each window of a frame carries one frame mark.
    b.frames.push(q.filter((msg) => msg.name === "%(mark)s").length);
  }, 50);
  return true;
}"""

GROUPS = (("organs", "/organs/"), ("task points", "/trajectory/"), ("instrument", "/tool/"),
          ("overlays", "/overlays/"), ("frame mark", "/vasim/"), ("light", "/endoscope/"),
          ("gizmo", "/input/"))
"""Scene node groups of the per-frame message counts (by node name prefix)."""


def _group(msg: Any) -> str:
    name = getattr(msg, "name", None)
    if isinstance(name, str):
        for label, prefix in GROUPS:
            if name.startswith(prefix):
                return label
    kind = type(msg).__name__
    return "text/GUI" if kind.startswith("Gui") else kind


def frame_messages(seconds: float, scene_hz: float | None) -> dict[str, float]:
    """Messages the trainee's server queues per view frame, by node group (the broadcast
    stream every trainee page gets; no page attached), for a ``ViewerPace(scene_hz=...)``
    on the default abdomen with ``trajectory_following`` (every overlay)."""
    import collections

    from vasim.viewer import TrialOptions, ViewerApp, ViewerPace

    app = ViewerApp(port=0, scene="default", trials=TrialOptions(schema="trajectory_following"),
                    pace=ViewerPace(scene_hz=scene_hz)).start()
    try:
        assert app.server is not None
        ws = app.server._websock_server  # private (viser 1.1.1): where every message goes
        counts: collections.Counter[str] = collections.Counter()
        original = ws.queue_message

        def counted(msg: Any) -> None:
            counts[_group(msg)] += 1
            original(msg)

        time.sleep(2.0)  # kernels compiled, the first trial under way
        ws.queue_message = counted  # type: ignore[method-assign,assignment]
        u0 = app._view_updates
        time.sleep(seconds)
        ws.queue_message = original  # type: ignore[method-assign]
        frames = max(app._view_updates - u0, 1)
    finally:
        app.stop()
    out = {k: v / frames for k, v in counts.items()}
    out["total"] = sum(counts.values()) / frames
    return out

LATENCY_JS = """(key) => { window.__vasimLatency = undefined; new Promise((resolve) => {
  const m = window.__viserMutable, tip = () => m.nodeRefFromName['/tool/tip'];
  const p0 = tip().position.clone();
  // Arrival times of the tip's messages in the page (for the split of the latency).
  if (!window.__vasimTipArrivals) {
    const got = window.__vasimTipArrivals = [], q = m.messageQueue, push = q.push;
    q.push = function (...msgs) {
      for (const msg of msgs) {
        if (msg.type === "SetPositionMessage" && msg.name === "/tool/tip") {
          got.push(performance.now()); if (got.length > 400) { got.shift(); }
        }
      }
      return push.apply(this, msgs);
    };
  }
  // The key's time stamp as the instrument's script took it (its listener stops the event,
  // so a listener here would never hear it).
  const armed = performance.now(), S = window.__vasimInput;
  const pressed = () => (S && S.lastDown && S.lastDown.code === key && S.lastDown.t >= armed
                         ? S.lastDown.t : null);
  const give_up = performance.now() + 20000;
  const look = (now) => {
    const t0 = pressed();
    if (t0 !== null && tip().position.distanceTo(p0) > 1e-5) {
      const d = S.lastDown, recv = window.__vasimTipArrivals.find((x) => x >= d.h);
      window.__vasimLatencySplit = {t0: t0, handler: d.h, seq: d.seq, drawn: now,
        received: recv === undefined ? null : recv, origin: performance.timeOrigin};
      resolve(now - t0); return;
    }
    if (now > give_up) { resolve(null); return; }
    requestAnimationFrame(look);
  };
  requestAnimationFrame(look);
}).then((ms) => { window.__vasimLatency = ms; }); return true; }"""


LATENCY_PARTS = ("handler", "server", "received", "drawn")
"""The key-to-picture latency split at the key's handler running in the page, its batch
arriving at the server, the first tip message after it arriving in the page's queue, and
the frame that shows the tip moved: the time of each step after the previous one."""


def _latency_split(split: Any, arrivals: Any) -> tuple[float, float, float, float] | None:
    """One key press's :data:`LATENCY_PARTS` [ms] from the page's time stamps and the
    server's batch arrivals ``(seq, wall-clock s)``; None when a step was not seen. The
    page's and the server's clocks are one machine's (``performance.timeOrigin`` is wall
    time), so the server's step is within a millisecond or so."""
    if not split or split.get("received") is None or not split.get("seq"):
        return None
    at = next((t for seq, t in list(arrivals) if seq == split["seq"]), None)
    if at is None:
        return None
    server = at * 1000.0 - split["origin"]  # on the page's clock [ms]
    a, b, c, d, e = split["t0"], split["handler"], server, split["received"], split["drawn"]
    return (float(b - a), float(c - b), float(d - c), float(e - d))


def _throttled(app: Any, browser: Any, seconds: float, rate: float = 4.0) -> dict[str, float]:
    """Run 4: a 1280x800 page, CPU throttled ``rate``x, a keyboard trial (module doc)."""
    import numpy as np

    from tests.browser.conftest import ACTION_TIMEOUT_MS, wait_ready
    from vasim.viewer.controller import Command

    page = browser.new_page(viewport={"width": 1280, "height": 800})
    page.set_default_timeout(ACTION_TIMEOUT_MS)  # a loaded host: minutes, not 30 s
    page.set_default_navigation_timeout(ACTION_TIMEOUT_MS)
    try:
        page.goto(app.url)
        wait_ready(page, "/organs/liver")
        page.wait_for_function("() => window.__vasimFlow && window.__vasimFlow.acks > 0",
                               timeout=60_000)
        cdp = page.context.new_cdp_session(page)
        cdp.send("Emulation.setCPUThrottlingRate", {"rate": rate})
        for kind, value in (("mode", "free"), ("input", "laparoscopic"), ("start", None)):
            app.submit(Command(kind, value))
        t_end = time.monotonic() + 60
        while app.controller.instrument is None and time.monotonic() < t_end:
            time.sleep(0.05)
        if app.controller.instrument is None:
            raise RuntimeError(f"the keyboard trial did not start: {app.errors[-3:]}")
        while app.controller.countdown_until is not None and time.monotonic() < t_end:
            time.sleep(0.05)
        time.sleep(1.0)
        page.evaluate(BACKLOG_JS % {"groups": json.dumps([list(g) for g in GROUPS]),
                                    "mark": MARK_NODE})
        u0 = app._view_updates
        a0 = sum(f.total_acks for f in app.acks.pages().values())
        lags, ahead, rates = [], [], []
        t_end = time.monotonic() + seconds
        while time.monotonic() < t_end:
            f = app.flow_stats()
            lags.append(f["trainee_clock_lag_s_max"])
            ahead.append(f["trainee_windows_ahead_max"])
            rates.append(f["trainee_page_update_hz_min"])
            time.sleep(0.25)
        latencies: list[float] = []
        splits: list[tuple[float, float, float, float]] = []
        for i in range(1 if SMOKE else 5):
            key = "ArrowRight" if i % 2 == 0 else "ArrowLeft"
            page.evaluate(LATENCY_JS, key)
            page.keyboard.down(key)
            time.sleep(0.25)
            page.keyboard.up(key)
            try:
                page.wait_for_function("() => window.__vasimLatency !== undefined",
                                       timeout=5_000 if SMOKE else 60_000)
            except Exception:  # a page this slow: no figure rather than no bench
                break
            ms = page.evaluate("() => window.__vasimLatency")
            if ms is not None:
                latencies.append(float(ms))
                split = _latency_split(page.evaluate("() => window.__vasimLatencySplit"),
                                       app.instrument_input.arrivals)
                if split is not None:
                    splits.append(split)
            time.sleep(0.5)
        got = page.evaluate("() => window.__vasimBacklog")
        backlog = np.array(got["samples"], dtype=float)
        waiting = np.array(got["frames"], dtype=float)
        frames_sent = max(app._view_updates - u0, 1)
        applied_n = sum(f.total_acks for f in app.acks.pages().values()) - a0
        factor = app.flow_stats()["realtime_factor_recent"]
        app.submit(Command("stop"))
    finally:
        page.close()
    lag = np.array([x for x in lags if x == x])
    applied = np.array([x for x in rates if x == x])
    out = {f"received {k}": float(v) for k, v in got["got"].items()}
    out["received_per_frame"] = float(got["n"]) / frames_sent
    out["received_per_update"] = (float(got["n"]) / applied_n if applied_n > 0
                                  else float("nan"))
    out["frames_waiting_max"] = float(waiting.max()) if len(waiting) else float("nan")
    out["frames_waiting_p95"] = (float(np.percentile(waiting, 95)) if len(waiting)
                                 else float("nan"))
    out["page_update_hz_mean"] = float(applied.mean()) if len(applied) else float("nan")
    return out | {
        "backlog_max": float(backlog.max()) if len(backlog) else float("nan"),
        "backlog_p95": float(np.percentile(backlog, 95)) if len(backlog) else float("nan"),
        "lag_p50": float(np.median(lag)) if len(lag) else float("nan"),
        "lag_max": float(lag.max()) if len(lag) else float("nan"),
        "windows_ahead_max": float(max(ahead, default=float("nan"))),
        "page_update_hz": float(np.nanmedian(rates)) if rates else float("nan"),
        "latency_ms_p50": float(np.median(latencies)) if latencies else float("nan"),
        "latency_ms_max": float(max(latencies)) if latencies else float("nan"),
        "latency_n": float(len(latencies)),
        **{f"latency_{k}_ms_p50": (float(np.median([x[i] for x in splits])) if splits
                                   else float("nan"))
           for i, k in enumerate(LATENCY_PARTS)},
        "realtime_factor": factor,
        "render_scale_min": app.notices.scales.coarsest.get(app.acks.port, 1.0),
    }


def _pct(costs: Any, q: float) -> float:
    import numpy as np

    a = np.array(costs) * 1e3
    return float(np.percentile(a, q)) if len(a) else float("nan")


def _browser_missing() -> str | None:
    import importlib.util

    if not os.path.exists("/usr/bin/chromium"):
        return "/usr/bin/chromium is missing"
    if importlib.util.find_spec("playwright") is None:
        return "the playwright package is missing"
    return None


def run(seconds: float = SECONDS) -> list[tuple[str, dict[str, float]]]:
    import tempfile

    from vasim.viewer import TrialOptions, ViewerApp, ViewerPace

    rows: list[tuple[str, dict[str, float]]] = []
    tmp = tempfile.TemporaryDirectory(prefix="vasim-bench-viewer-")
    # A store: the throttled run's keyboard trial is a free-training trial (stored).
    app = ViewerApp(port=0, scene="default", db=os.path.join(tmp.name, "bench.sqlite"),
                    trials=TrialOptions(schema="trajectory_following")).start()
    try:
        time.sleep(2.0)  # kernels compiled, the first trial under way
        rows.append(("no browser", _measure(app, seconds)))
        with _BareClient(app.url) as bare:
            time.sleep(1.0)
            rows.append(("bare websocket client", _measure(app, seconds, bare=bare)))
        reason = _browser_missing()
        if reason:
            print(f"browser run skipped: {reason}")
            return rows
        from playwright.sync_api import sync_playwright

        from tests.browser.conftest import ACTION_TIMEOUT_MS, LAUNCH_ARGS, VIEWPORT, wait_ready

        with sync_playwright() as p:
            b = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True,
                                  args=LAUNCH_ARGS)
            try:
                page = b.new_page(viewport=VIEWPORT)
                page.set_default_timeout(ACTION_TIMEOUT_MS)
                page.set_default_navigation_timeout(ACTION_TIMEOUT_MS)
                page.goto(app.url)
                wait_ready(page, "/organs/liver")
                page.evaluate(COUNTER_JS)
                rows.append(("one headless Chromium attached", _measure(app, seconds, page)))
                page.close()
                app.stop()
                # Before/after (issue #26.2): the organs with every frame, then paced.
                # (smoke: the paced run only, which checks the code path; its figures, like
                # every smoke figure, are not meaningful)
                for label, scene_hz in THROTTLED_RUNS[-1:] if SMOKE else THROTTLED_RUNS:
                    with tempfile.TemporaryDirectory(prefix="vasim-bench-viewer-") as d:
                        a = ViewerApp(port=0, scene="default", db=os.path.join(d, "bench.sqlite"),
                                      trials=TrialOptions(schema="trajectory_following"),
                                      pace=ViewerPace(scene_hz=scene_hz)).start()
                        name = f"Chromium 1280x800, CPU 4x slower, {label}"
                        try:
                            time.sleep(2.0)
                            rows.append((name, _throttled(a, b, seconds)))
                        except Exception as exc:  # a page too slow to load: say so
                            print(f"{name}: no figures ({type(exc).__name__}: "
                                  f"{str(exc).splitlines()[0]})")
                        finally:
                            a.stop()
            finally:
                b.close()
    finally:
        app.stop()
        tmp.cleanup()
    return rows


THROTTLED_RUNS: tuple[tuple[str, float | None], ...] = (
    ("organs with every frame (before)", None), ("unsteered scene paced (after)", 10.0))
"""The throttled page's runs: ``ViewerPace(scene_hz=...)`` (None: the organs and the task's
points with every frame, as before issue #26.2; 10 Hz: ``flow.SCENE_HZ``)."""


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="browser viewer: cost, streaming, loop rates")
    parser.add_argument("--seconds", type=float, default=SECONDS, help="length of each run [s]")
    parser.add_argument("--smoke", action="store_true", help="2 s runs: checks it all runs")
    args = parser.parse_args(sys.argv[1:] if argv is None and __name__ == "__main__"
                             else [] if argv is None else argv)
    if args.smoke:
        args.seconds = 2.0
    per_frame = [(label, frame_messages(args.seconds, hz)) for label, hz in THROTTLED_RUNS]
    rows = run(args.seconds)
    throttled = [(name, r) for name, r in rows if name.startswith("Chromium 1280")]
    rows = [(name, r) for name, r in rows if not name.startswith("Chromium 1280")]
    print("messages the trainee's server queues per view frame, by node group (no page):")
    groups = sorted({k for _, r in per_frame for k in r if k != "total"},
                    key=lambda k: -max(r.get(k, 0.0) for _, r in per_frame))
    print(f"  {'group':24s}" + "".join(f" {label[:32]:>33s}" for label, _ in per_frame))
    for k in [*groups, "total"]:
        print(f"  {k:24s}" + "".join(f" {r.get(k, 0.0):33.2f}" for _, r in per_frame))
    print(f"default abdomen, trajectory_following (VG, FF, MS, Mag, AG), {args.seconds:g} s "
          "per run, scripted operator in real time")
    head = (f"{'run':32s} {'view ms p50':>11s} {'p95':>6s} {'view/s':>7s} {'CPU/s':>6s} "
            f"{'servo Hz':>9s} {'physics Hz':>10s} {'tip upd/s':>9s} {'msgs/s':>7s} "
            f"{'page fps':>8s} {'ws msg/s':>8s} {'ws kB/s':>8s}")
    print(head)
    for name, r in rows:
        def f(k: str, fmt: str, r: dict[str, float] = r) -> str:
            v = r.get(k)
            return "—" if v is None or v != v else format(v, fmt)

        print(f"{name:32s} {f('view_ms_p50', '.2f'):>11s} {f('view_ms_p95', '.2f'):>6s} "
              f"{f('view_hz', '.1f'):>7s} {f('process_cpu', '.2f'):>6s} "
              f"{f('servo_hz', '.1f'):>9s} {f('physics_hz', '.1f'):>10s} "
              f"{f('browser_tip_per_s', '.1f'):>9s} {f('browser_messages_per_s', '.0f'):>7s} "
              f"{f('browser_frames_per_s', '.1f'):>8s} {f('ws_messages_per_s', '.0f'):>8s} "
              f"{f('ws_kb_per_s', '.0f'):>8s}")
    a = rows[0][1]
    for name, r in rows[1:]:
        print(f"{name}: servo rate / no browser {r['servo_hz'] / a['servo_hz']:.3f}, physics "
              f"rate / no browser {r['physics_hz'] / a['physics_hz']:.3f}")
    if len(rows) == 3:
        print(f"tool-tip updates received by the browser: "
              f"{rows[2][1].get('browser_tip_per_s', 0):.1f}/s (target >= 30/s)")
    for name, t in throttled:
        print(f"{name}, keyboard trial (goals: backlog < 10 updates, lag < 0.5 s, latency "
              "< 150 ms):")
        print(f"  backlog: frame updates waiting in the page's queue max "
              f"{t['frames_waiting_max']:.0f}, p95 {t['frames_waiting_p95']:.0f}; messages "
              f"max {t['backlog_max']:.0f}, p95 {t['backlog_p95']:.0f}; windows of updates "
              f"in flight max {t['windows_ahead_max']:.0f}")
        got = sorted(((k[9:], v) for k, v in t.items() if k.startswith("received ")),
                     key=lambda kv: -kv[1])
        print(f"  messages received per frame update the page applied "
              f"{t['received_per_update']:.1f} (per frame the server made "
              f"{t['received_per_frame']:.1f}); by group over the run: "
              + ", ".join(f"{k} {v:.0f}" for k, v in got))
        print(f"  displayed-clock lag: p50 {t['lag_p50']:.2f} s, max {t['lag_max']:.2f} s; "
              f"page updates {t['page_update_hz']:.1f}/s (mean "
              f"{t['page_update_hz_mean']:.1f}/s); loop {t['realtime_factor']:.2f}x "
              f"real time; the page drew at {t['render_scale_min']:.2f} of its resolution "
              "at the coarsest (render_scale.py)")
        print(f"  control-to-photon latency: p50 {t['latency_ms_p50']:.0f} ms, max "
              f"{t['latency_ms_max']:.0f} ms ({t['latency_n']:.0f} key presses)")
        print("  where it goes (p50 of each step after the previous one): "
              + ", ".join(f"{k} {t[f'latency_{k}_ms_p50']:.0f} ms" for k in LATENCY_PARTS)
              + " (key -> its handler ran in the page -> its batch at the server -> the "
              "first tip message after it in the page -> the frame showing the tip moved)")


if __name__ == "__main__":
    main()
