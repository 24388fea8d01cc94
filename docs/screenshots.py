"""Screenshots of the viewer's pages for the docs (issue #26): the trainee's page with its
score card, the experimenter's page, and the experimenter's f5PL editor, in headless
Chromium at 1280x800.

Run from the repository (Debian's ``/usr/bin/chromium`` and the ``playwright`` package, as
the browser tests; never ``playwright install``)::

    python docs/screenshots.py            # writes docs/trainee.png, docs/experimenter.png,
                                          # docs/f5pl_editor.png
    python docs/screenshots.py --smoke    # the same, into a temporary folder (a check)

What it does: a viewer on loopback (``scene="none"``: the static page without the deforming
abdomen keeps software WebGL responsive) with a temporary study store; free training for
the subject code ``DOC01`` with the scripted operator (no person behind it); one trial
run at 3x speed and stored, so the trainee's page shows its score card; then the
experimenter's page (its "Fixture schema" folder is open by default) during a second,
slow trial, and the same page, 1,100 px tall, scrolled to put the f5PL editor with FF's
curve chosen at the top of the panel (the operating point is that trial's tool tip).
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

CHROMIUM = os.environ.get("VASIM_CHROMIUM", "/usr/bin/chromium")
LAUNCH_ARGS = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-background-networking",
               "--disable-component-update", "--disable-sync", "--no-first-run"]
VIEWPORT = {"width": 1280, "height": 800}
READY_MS = 120_000
SHOT_MS = 300_000  # a screenshot with software WebGL on a loaded 2-core machine: 40-100 s


def wait_for(cond: Callable[[], bool], timeout: float = 60.0) -> bool:
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        if cond():
            return True
        time.sleep(0.1)
    return cond()


def ready(page: Any, node: str = "/tool/tip") -> None:
    page.wait_for_function("() => !document.body.innerText.includes('Connecting')",
                           timeout=READY_MS)
    page.wait_for_function(
        "(n) => window.__viserMutable && window.__viserMutable.nodeRefFromName[n]", arg=node,
        timeout=READY_MS)
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => "
                  "requestAnimationFrame(() => r(true))))")


def settle(page: Any, seconds: float = 1.5) -> None:
    page.wait_for_timeout(int(seconds * 1000))
    page.evaluate("() => new Promise(r => requestAnimationFrame(() => "
                  "requestAnimationFrame(() => r(true))))")


EDITOR_VIEWPORT = {"width": 1280, "height": 1100}
"""The editor's shot: the menu, the five fields, Apply, the curve and the parameter lines
are about 1,000 px of the panel."""


def editor_to_top(page: Any) -> None:
    """Scrolls the experimenter's panel so that the f5PL editor (its "f5PL of" menu's
    label) is at the top of the panel's view; RuntimeError when the editor is missing."""
    found = page.evaluate("""() => {
        const x = document.evaluate("//label[normalize-space()='f5PL of']", document, null,
            XPathResult.FIRST_ORDERED_NODE_TYPE, null).singleNodeValue;
        if (!x) { return false; }
        x.scrollIntoView({block: "start"});
        return true;
    }""")
    if not found:
        raise RuntimeError("the f5PL editor ('f5PL of') is not on the experimenter's page")


def shoot(out: Path) -> list[Path]:
    from playwright.sync_api import sync_playwright

    from vasim.viewer import TrialOptions, ViewerApp, ViewerPace

    out.mkdir(parents=True, exist_ok=True)
    written: list[Path] = []
    with tempfile.TemporaryDirectory() as tmp:
        app = ViewerApp(port=0, db=str(Path(tmp) / "s.sqlite"), scene="none",
                        trials=TrialOptions(schema="trajectory_following", pause_s=0.3,
                                            countdown_s=0.0),
                        pace=ViewerPace(speed=3.0, view_hz=5.0)).start()
        try:
            def request(kind: str, value: Any, cond: Callable[[], bool]) -> None:
                app.request(kind, value)
                if not wait_for(cond):
                    raise RuntimeError(f"{kind}={value!r} did not take effect: "
                                       f"{app.panel.status} {app.errors[-3:]}")

            request("mode", "free", lambda: app.panel.mode == "free")
            request("subject", "DOC01", lambda: app.panel.subject == "DOC01")
            request("start", None, lambda: app.snapshot.info.trial_id is not None)
            if not wait_for(lambda: app.panel.scorecard is not None, 240):
                raise RuntimeError(f"no score card: {app.panel.status} {app.errors[-3:]}")
            with sync_playwright() as p:
                browser = p.chromium.launch(executable_path=CHROMIUM, headless=True,
                                            args=LAUNCH_ARGS)
                try:
                    trainee = browser.new_page(viewport=VIEWPORT)
                    trainee.goto(app.url)
                    ready(trainee)
                    trainee.wait_for_function(
                        "() => document.body.innerText.includes('Score card')",
                        timeout=READY_MS)
                    settle(trainee)
                    written.append(out / "trainee.png")
                    trainee.screenshot(path=str(written[-1]), timeout=SHOT_MS)
                    trainee.close()

                    exp = browser.new_page(viewport=VIEWPORT)
                    exp.goto(app.experimenter_url)
                    ready(exp)
                    # the "Fixture schema" folder is open by default: choose FF's curve
                    exp.get_by_role("combobox", name="f5PL of").click(force=True, timeout=READY_MS)
                    exp.get_by_role("option", name="ff", exact=True).click(force=True,
                                                                           timeout=READY_MS)
                    # A second, slow trial runs while the page is shot: the live metrics
                    # and the editor's operating point are current.
                    app.controller.speed = 0.2
                    n = app.snapshot.info.number
                    request("start", None, lambda: app.snapshot.info.number > n)
                    settle(exp, 4.0)
                    written.append(out / "experimenter.png")
                    exp.screenshot(path=str(written[-1]), timeout=SHOT_MS)
                    # The whole editor in frame (issue #26 §5: a fixed mouse-wheel distance
                    # scrolled past the curve once the panel grew): a taller page, and the
                    # panel scrolled to put the editor's "f5PL of" menu at its top.
                    exp.set_viewport_size(EDITOR_VIEWPORT)
                    exp.mouse.move(600, EDITOR_VIEWPORT["height"] - 10)  # no hint tooltip
                    editor_to_top(exp)
                    settle(exp, 3.0)
                    editor_to_top(exp)      # again, after the resized page's layout settled
                    settle(exp, 1.0)
                    written.append(out / "f5pl_editor.png")
                    exp.screenshot(path=str(written[-1]), timeout=SHOT_MS)
                    exp.close()
                finally:
                    browser.close()
        finally:
            app.stop()
    return written


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", type=Path, default=Path(__file__).resolve().parent,
                    help="folder for the PNGs (default: docs/)")
    ap.add_argument("--smoke", action="store_true",
                    help="write into a temporary folder and only check the PNGs")
    args = ap.parse_args(argv)
    if not os.path.exists(CHROMIUM):
        print(f"error: {CHROMIUM} is missing (apt-get install chromium)", file=sys.stderr)
        return 2
    if args.smoke:
        with tempfile.TemporaryDirectory() as tmp:
            files = shoot(Path(tmp))
            sizes = {f.name: f.stat().st_size for f in files}
    else:
        files = shoot(args.out)
        sizes = {str(f): f.stat().st_size for f in files}
    for name, size in sizes.items():
        print(f"{name}: {size} bytes")
    return 0 if len(sizes) == 3 and all(s > 10_000 for s in sizes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
