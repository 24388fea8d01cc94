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

The host is shared (other jobs run), so compare the two runs within one invocation.
"""

from __future__ import annotations

import argparse
import os
import time
from typing import Any

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
    from vasim.viewer import ViewerApp

    rows: list[tuple[str, dict[str, float]]] = []
    app = ViewerApp(port=0, schema="trajectory_following", scene="default").start()
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

        from tests.browser.conftest import LAUNCH_ARGS, VIEWPORT, wait_ready

        with sync_playwright() as p:
            b = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True,
                                  args=LAUNCH_ARGS)
            try:
                page = b.new_page(viewport=VIEWPORT)
                page.goto(app.url)
                wait_ready(page, "/organs/liver")
                page.evaluate(COUNTER_JS)
                rows.append(("one headless Chromium attached", _measure(app, seconds, page)))
            finally:
                b.close()
    finally:
        app.stop()
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description="browser viewer: cost, streaming, loop rates")
    parser.add_argument("--seconds", type=float, default=SECONDS, help="length of each run [s]")
    args = parser.parse_args([] if argv is None else argv)
    rows = run(args.seconds)
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


if __name__ == "__main__":
    main()
