"""Screenshots of the viewer's pages for the docs (issue #26): the trainee's page with its
score card and during a trial (README's picture), the experimenter's page, the
experimenter's f5PL editor and the MRCP station's page, in headless Chromium at 1280x800.

Run from the repository (Debian's ``/usr/bin/chromium`` and the ``playwright`` package, as
the browser tests; never ``playwright install``)::

    python docs/screenshots.py            # writes docs/trainee.png, docs/experimenter.png,
                                          # docs/viewer.png, docs/f5pl_editor.png,
                                          # docs/mrcp.png
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
from collections.abc import Callable, Iterator
from contextlib import contextmanager
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


@contextmanager
def chromium() -> Iterator[Any]:
    """Headless Debian Chromium at :data:`LAUNCH_ARGS` (closed on leaving)."""
    from playwright.sync_api import sync_playwright

    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=LAUNCH_ARGS)
        try:
            yield browser
        finally:
            browser.close()


def open_page(browser: Any, url: str, node: str = "/tool/tip") -> Any:
    """A new 1280x800 page at ``url``, ready (:func:`ready`) once ``node`` is drawn."""
    page = browser.new_page(viewport=VIEWPORT)
    page.goto(url)
    ready(page, node)
    return page


def dismiss_notices(page: Any) -> int:
    """Closes viser's pop-up notices (Chromium drawing in software gets "Software WebGL
    rendering detected"), as a reader would before looking at the page; returns how many."""
    return int(page.evaluate("""() => {
        const close = [...document.querySelectorAll('[class*="Notification-closeButton"]')];
        close.forEach(b => b.click());
        return close.length;
    }"""))


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
            with chromium() as browser:
                trainee = open_page(browser, app.url)
                trainee.wait_for_function(
                    "() => document.body.innerText.includes('Score card')",
                    timeout=READY_MS)
                dismiss_notices(trainee)
                settle(trainee)
                written.append(out / "trainee.png")
                trainee.screenshot(path=str(written[-1]), timeout=SHOT_MS)
                trainee.close()

                exp = open_page(browser, app.experimenter_url)
                # the "Fixture schema" folder is open by default: choose FF's curve
                exp.get_by_role("combobox", name="f5PL of").click(force=True, timeout=READY_MS)
                exp.get_by_role("option", name="ff", exact=True).click(force=True,
                                                                       timeout=READY_MS)
                # A second, slow trial runs while the page is shot: the live metrics
                # and the editor's operating point are current.
                # (both: the controller paces the next trial, the app judges "running
                # behind" against its speed)
                app.speed = app.controller.speed = 0.2
                n = app.snapshot.info.number
                request("start", None, lambda: app.snapshot.info.number > n)
                dismiss_notices(exp)
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
                # The trainee's page during that trial (README's picture): the path,
                # the fixtures at work and the live status, no score card yet; the
                # only page open (two pages drawing in software fall behind).
                live = open_page(browser, app.url)
                dismiss_notices(live)
                settle(live, 4.0)
                written.append(out / "viewer.png")
                live.screenshot(path=str(written[-1]), timeout=SHOT_MS)
                live.close()
        finally:
            app.stop()
    return written


MRCP_AT_S = 12.0
"""Simulated time of the MRCP shot: ``obstacle_hole``'s first two hand-overs (R0 to R1 at
about 6 s, and back at about 12 s) are on the charts."""


def shoot_mrcp(out: Path) -> Path:
    """The MRCP station's page of ``vasim serve --scene mrcp:obstacle_hole`` (coarse 36 ms
    cycle) at about :data:`MRCP_AT_S` of simulated time (of whichever run the scenario's
    loop is in once the page is ready): the station, the NTT / texec / tus charts."""
    from vasim.viewer.mrcp_panel import MrcpPace, MrcpViewerApp

    app = MrcpViewerApp(port=0, scenario="obstacle_hole", coarse=True,
                        pace=MrcpPace(view_hz=15.0, plot_hz=2.0)).start()
    try:
        with chromium() as browser:
            page = open_page(browser, app.url, "/mrcp/robots/R1/link6")

            def at_shot() -> bool:
                frame = app.live.latest()
                return frame is not None and MRCP_AT_S <= frame.sample.t < MRCP_AT_S + 2

            if not wait_for(at_shot, 300):
                raise RuntimeError(f"the MRCP run did not reach {MRCP_AT_S} s")
            dismiss_notices(page)
            settle(page, 1.0)       # the charts' next refresh (2 Hz) and the last poses
            path = out / "mrcp.png"
            page.screenshot(path=str(path), timeout=SHOT_MS)
            page.close()
    finally:
        app.stop()
    return path


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
            files = [*shoot(Path(tmp)), shoot_mrcp(Path(tmp))]
            sizes = {f.name: f.stat().st_size for f in files}
    else:
        files = [*shoot(args.out), shoot_mrcp(args.out)]
        sizes = {str(f): f.stat().st_size for f in files}
    for name, size in sizes.items():
        print(f"{name}: {size} bytes")
    return 0 if len(sizes) == 5 and all(s > 10_000 for s in sizes.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
