"""Each page's notice line: "running behind" (flow.py) and the resolution it draws at
(render_scale.py), refreshed at most twice a second from the view thread.

The stateful shell of :class:`vasim.viewer.app.ViewerApp`'s pages: one hidden markdown
line per page (both servers), and per page its resolution step (:class:`PageScales`),
told to the page when it changes.
"""

from __future__ import annotations

import logging
import threading
import time
from typing import Any

import viser

from vasim.viewer.audio import run_js
from vasim.viewer.flow import RATE_WINDOW_S, PageAcks, behind_notice
from vasim.viewer.render_scale import SCALE_JS, PageScales, scale_notice, set_scale_js

log = logging.getLogger(__name__)

REFRESH_S = 0.5
"""The notice lines are refreshed at most this often [s]."""


class PageNotices:
    """The notice lines and resolution steps of the pages of one viewer's servers.

    Args:
        acks: the acknowledgement channels of the viewer's servers (trainee's first).
    """

    def __init__(self, *acks: PageAcks):
        self.acks = {a.port: a for a in acks}
        self.lock = threading.Lock()
        self.handles: dict[tuple[int, int], Any] = {}
        """Each page's notice line, by (server port, client id)."""
        self.scales = PageScales(self._send_scale, RATE_WINDOW_S)
        self._next = 0.0

    def install(self, client: viser.ClientHandle, acks: PageAcks) -> None:
        """A new page of ``acks``' server: its line, its acknowledgement and scale scripts."""
        notice = client.gui.add_markdown("", visible=False)
        key = (acks.port, client.client_id)
        with self.lock:
            self.handles[key] = notice
        self.scales.add(key)
        acks.install(client)
        run_js(client, SCALE_JS)   # fewer pixels when the page cannot keep up

    def show(self, t_trial: float, factor: float | None, speed: float, view_hz: float,
             frames: int, now: float | None = None) -> None:
        """Refreshes every page's line (at most every :data:`REFRESH_S`): the loop's
        realtime ``factor``, the trial time ``t_trial`` and the ``frames`` produced so far."""
        now = time.monotonic() if now is None else now
        if now < self._next:
            return
        self._next = now + REFRESH_S
        produced = self.scales.produced(now, frames)
        with self.lock:
            notices = list(self.handles.items())
        for (port, cid), handle in notices:
            acks = self.acks[port]
            page = acks.pages().get(cid)
            if page is None:  # gone: forget its line
                with self.lock:
                    self.handles.pop((port, cid), None)
                self.scales.drop((port, cid))
                continue
            t_shown = acks.marks.trial_time(page.applied_seq)
            # In wall seconds (**decision**: at speed 1000 a page 40 ms late showed a clock
            # 40 trial seconds behind and was called late).
            lag = None if t_shown is None else max(0.0, t_trial - t_shown) / speed
            scale = self.scales.update((port, cid), page.update_rate(now) if page.acking
                                       else None, produced, now)
            text = "  \n".join(x for x in (behind_notice(factor, speed, page, view_hz, lag),
                                           scale_notice(scale)) if x)
            try:
                if text != handle.content:
                    handle.content = text
                    handle.visible = bool(text)
            except Exception:  # a page closing meanwhile: the next round forgets it
                log.debug("notice for client %s not updated", cid, exc_info=True)

    def _send_scale(self, key: tuple[int, int], scale: float) -> None:
        client = self.acks[key[0]].server.get_clients().get(key[1])
        if client is not None:
            run_js(client, set_scale_js(scale), key="render_scale")
            log.info("page %s of port %s draws at %.2f of its resolution", key[1], key[0],
                     scale)


__all__ = ["REFRESH_S", "PageNotices"]
