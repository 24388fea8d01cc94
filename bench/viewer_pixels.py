"""What a drawn frame of the trainee's page costs the browser's software renderer, per
render scale (vasim/viewer/render_scale.py).

The trainee's page of ``vasim serve`` (default abdomen, ``trajectory_following``, a scripted
demo trial) in headless Chromium at a laptop's 1280x800, drawing in software (no GPU:
SwiftShader in Chromium's GPU process). For each scale of ``render_scale.SCALES`` (set by
hand: the automatic rule is stopped for the run), over ``SECONDS`` (10 s; ``--seconds``):

* frames three.js drew (``window.__vasimScale.renders``) per second,
* CPU seconds of Chromium's GPU process and of the page's renderer process per drawn
  frame [ms] (``psutil``: CPU time, not wall time, so a loaded host changes how many
  frames are drawn, not what each costs),
* the ratio of each scale's GPU cost per frame to full resolution's, in the same run.

A bare viser page (one box moved at 30 Hz) is measured the same way as the floor.

``--smoke`` (``VASIM_BENCH_SMOKE=1``): 1 s at full resolution and at the coarsest scale
(checks it runs; the figures mean nothing).
"""

from __future__ import annotations

import argparse
import os
import sys
import threading
import time
from typing import Any

import psutil

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
SECONDS = 1.0 if SMOKE else 10.0


def _chromium(kind: str) -> list[psutil.Process]:
    """This process's Chromium processes of one ``--type`` (gpu-process, renderer)."""
    out = []
    for p in psutil.Process().children(recursive=True):
        try:
            if f"--type={kind}" in " ".join(p.cmdline()):
                out.append(p)
        except psutil.Error:
            continue
    return out


def _cpu(procs: list[psutil.Process]) -> float:
    total = 0.0
    for p in procs:
        try:
            t = p.cpu_times()
            total += t.user + t.system
        except psutil.Error:
            continue
    return total


def _per_frame(page: Any, seconds: float, renders_js: str) -> dict[str, float]:
    gpu, ren = _chromium("gpu-process"), _chromium("renderer")
    n0, g0, r0, t0 = page.evaluate(renders_js), _cpu(gpu), _cpu(ren), time.monotonic()
    time.sleep(seconds)
    n = page.evaluate(renders_js) - n0
    g, r, wall = _cpu(gpu) - g0, _cpu(ren) - r0, time.monotonic() - t0
    return {"frames_per_s": n / wall, "gpu_ms": 1000 * g / max(n, 1),
            "renderer_ms": 1000 * r / max(n, 1), "frames": float(n)}


def run(seconds: float = SECONDS) -> list[tuple[str, dict[str, float]]]:
    from playwright.sync_api import sync_playwright

    from tests.browser.conftest import ACTION_TIMEOUT_MS, LAUNCH_ARGS, wait_ready
    from vasim.viewer import TrialOptions, ViewerApp
    from vasim.viewer.render_scale import SCALES

    scales = (SCALES[0], SCALES[-1]) if SMOKE else SCALES
    rows: list[tuple[str, dict[str, float]]] = []
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path="/usr/bin/chromium", headless=True,
                                    args=LAUNCH_ARGS)
        try:
            app = ViewerApp(port=0, scene="default",
                            trials=TrialOptions(schema="trajectory_following")).start()
            app.notices.show = lambda *a, **k: None  # type: ignore[method-assign]
            try:
                page = browser.new_page(viewport={"width": 1280, "height": 800})
                page.set_default_timeout(ACTION_TIMEOUT_MS)
                page.goto(app.url)
                wait_ready(page, "/organs/liver")
                page.wait_for_function("() => window.__vasimScale && window.__vasimScale.gl",
                                       timeout=ACTION_TIMEOUT_MS)
                key = next(k for k in app.notices.handles if k[0] == app.acks.port)
                for scale in scales:
                    app.notices._send_scale(key, scale)
                    page.wait_for_function(
                        "(s) => Math.abs(window.__vasimScale.gl.getPixelRatio() - s * "
                        "(window.devicePixelRatio || 1)) < 1e-6", arg=scale,
                        timeout=ACTION_TIMEOUT_MS)
                    time.sleep(1.0)
                    rows.append((f"trainee page at {scale:.2f}", _per_frame(
                        page, seconds, "() => window.__vasimScale.renders")))
                    print(f"  {rows[-1][0]} measured", flush=True)
                page.close()
            finally:
                app.stop()
            rows.append(("bare viser page (floor)", _bare(browser, seconds)))
        finally:
            browser.close()
    return rows


def _bare(browser: Any, seconds: float) -> dict[str, float]:
    import viser

    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    box = server.scene.add_box("/box", color=(200, 50, 50), dimensions=(0.1, 0.1, 0.1))
    stop = threading.Event()

    def move() -> None:
        k = 0
        while not stop.wait(1 / 30):
            box.position = (0.1 * (k % 50) / 50, 0.0, 0.0)
            k += 1

    threading.Thread(target=move, daemon=True).start()
    page = browser.new_page(viewport={"width": 1280, "height": 800})
    try:
        page.goto(f"http://127.0.0.1:{server.get_port()}/")
        page.wait_for_function("() => window.__viserMutable && window.__viserMutable.scene",
                               timeout=180_000)
        page.evaluate("""() => { const S = window.__bareRenders = {n: 0};
          const sc = window.__viserMutable.scene, prev = sc.onBeforeRender;
          sc.onBeforeRender = function () { S.n += 1; return prev.apply(this, arguments); };
          return true; }""")
        time.sleep(1.0)
        return _per_frame(page, seconds, "() => window.__bareRenders.n")
    finally:
        page.close()
        stop.set()
        server.stop()


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=SECONDS, help="per scale [s]")
    args = parser.parse_args(sys.argv[1:] if argv is None and __name__ == "__main__"
                             else [] if argv is None else argv)
    print("the trainee's page at 1280x800 in software (SwiftShader), per drawn frame:")
    rows = run(args.seconds)
    full = rows[0][1]["gpu_ms"]
    print(f"  {'page':28s} {'frames/s':>9s} {'GPU proc ms':>12s} {'renderer ms':>12s} "
          f"{'GPU / full':>10s}")
    for name, r in rows:
        print(f"  {name:28s} {r['frames_per_s']:9.1f} {r['gpu_ms']:12.1f} "
              f"{r['renderer_ms']:12.1f} {r['gpu_ms'] / full:10.3f}")


if __name__ == "__main__":
    main()
