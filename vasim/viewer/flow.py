"""Keep up, or say so (issue #26.2): per-page flow control of the viser stream.

A page that draws in software (no GPU) may apply scene updates more slowly than the view
thread produces them. viser sends every window of updates as soon as the socket takes it;
the browser's network thread takes them at once and the page's main thread falls behind:
backlogs of thousands of messages, a displayed clock 15-55 s late. Here:

* **Frame marks.** Every view update ends by moving an invisible scene node,
  ``/vasim/frame``, to ``(seq, 0, 0)`` inside the same ``server.atomic()`` block, so a
  window that carries a frame carries its mark (:class:`FrameMarks`).
* **Acknowledgements.** A small script sent to each page (:data:`ACK_JS`) reads, after each
  animation frame, which mark the page has *applied* (the node's position) and how many
  messages wait in its queue, and reports them through a hidden per-client GUI field
  (viser's own message; validated like any other by :mod:`vasim.viewer.isolation`).
* **Credit.** The producer of viser's broadcast stream for that connection
  (``viser.infra._infra._message_producer``, wrapped by :func:`paced_producer`) sends the
  next window only while fewer than :data:`MAX_AHEAD` windows are in flight (sent, and
  the frame mark they carry not yet applied by the page); the page's own stream (camera,
  audio parameters, notices) waits likewise. While it waits, viser's buffer keeps only
  the newest message per scene node and property (its redundancy keys), so the page,
  when ready, gets the present state of each node, never the queue of past ones:
  latest-wins per node per client, and each page's update rate adapts to what it can
  draw. A page that never acknowledges (no script: a bare websocket client) is not
  paced; the script repeats its acknowledgement every :data:`HEARTBEAT_S`, and a page
  that applies no new frame for :data:`STALE_S` while its stream waits gets one window
  every :data:`TRICKLE_S` until it applies a frame again (the stall is counted): a broken
  page script does not freeze its stream, and a page that is merely very slow is not
  flooded (**decision**, issue #26.2: it used to be unpaced, and a throttled page on a
  loaded host that stalled once was then sent 40 windows a second: 90 frames, 926
  messages waiting in its queue).

* **Less per frame** (:class:`ScenePacer`): what the trainee does not steer (the organs'
  surfaces, breathing and pushed by the tool, and the task's points riding on them: 29 of
  the ~38 messages a frame of the default abdomen carried) is sent at :data:`SCENE_HZ`,
  and less often still when a page of that server applies few frames per second (at most
  one of every :data:`FRAMES_PER_SCENE` frames the slowest page applies carries them, never
  below :data:`MIN_SCENE_HZ`); the instrument, its tip, the fixtures' arrows and the MS
  ghost, which follow the trainee's hand, go with every frame. Measured with
  ``bench/viewer.py`` (per-frame messages by node, before and after).

The figures per page (update rate, frames in flight, queued messages, displayed-clock lag)
feed the "running behind" notices and the trial record (``ViewerApp.flow_stats``).
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import threading
import time
from typing import Any

import viser
import viser.infra._infra as _infra

log = logging.getLogger(__name__)

MAX_AHEAD = 2
"""Windows of updates a page may have in flight (sent, its frame mark not yet applied)
before its stream waits."""
STALE_S = 30.0
"""A page that applies no new frame this long while its stream waits gets one window per
:data:`TRICKLE_S` (a broken page script must not freeze its stream; the credit returns
with its next applied frame)."""
TRICKLE_S = 2.0
"""A stalled page's stream sends one window this often."""
HEARTBEAT_S = 1.0
"""The page repeats its acknowledgement this often even when nothing new was applied."""
RATE_WINDOW_S = 3.0
"""Window of the rates (page updates per second, realtime factor)."""
MARK_NODE = "/vasim/frame"
SCENE_HZ = 10.0
"""Rate of the scene the trainee does not steer (organs, the task's points on them) [Hz].
**Decision**: breathing (0.2-0.3 Hz) and tissue pushed at hand speed read as continuous at
10 Hz (a film's motion-picture threshold is ~10-12 frames/s); the hand-steered nodes keep
the view rate (40 Hz), so control-to-photon latency is not bounded by this rate."""
MIN_SCENE_HZ = 0.2
"""The unsteered scene is never sent less often than this, however slow the page [Hz]
(**decision**: at least every 5 s; with a floor of 1 Hz, a page drawing a frame every 3-10 s
on a loaded host got the organs with every frame it drew: 54 messages per frame applied,
against 65 without pacing, ``bench/viewer.py``)."""
FRAMES_PER_SCENE = 3
"""On a slow page at most one of this many applied frames carries the unsteered scene (the
frames between carry only what the hand steers: a few small messages)."""

ACK_JS = r"""
(function () {
  var UUID = "%(uuid)s", NODE = "%(node)s";
  if (window.__vasimFlow && window.__vasimFlow.uuid === UUID) { return; }
  var S = window.__vasimFlow = {uuid: UUID, applied: -1, acks: 0, frames: 0, last: 0};
  function tick(now) {
    S.frames += 1;
    var m = window.__viserMutable;
    var o = m && m.nodeRefFromName && m.nodeRefFromName[NODE];
    if (o && m.sendMessage) {
      var seq = Math.round(o.position.x);
      if (seq !== S.applied || now - S.last > %(heartbeat_ms)d) {
        S.applied = seq; S.acks += 1; S.last = now;
        m.sendMessage({type: "GuiUpdateMessage", uuid: UUID, updates: {value:
          JSON.stringify({seq: seq, q: m.messageQueue ? m.messageQueue.length : 0,
                          n: S.acks})}});
      }
    }
    requestAnimationFrame(tick);
  }
  requestAnimationFrame(tick);
})();
"""


class FrameMarks:
    """The frame marks of one server: a counter moved into ``/vasim/frame`` per update,
    and the trial time of recent marks (for the displayed-clock lag)."""

    def __init__(self, server: viser.ViserServer):
        self.node = server.scene.add_frame(MARK_NODE, show_axes=False, visible=False)
        self.seq = 0
        self._t: collections.OrderedDict[int, float] = collections.OrderedDict()
        self._lock = threading.Lock()

    def mark(self, t_trial: float) -> int:
        """Marks one more frame (call inside the frame's ``atomic()`` block); returns it."""
        with self._lock:
            seq = self.seq + 1
            self._t[seq] = float(t_trial)
            while len(self._t) > 4000:
                self._t.popitem(last=False)
            # Pushed before ``seq`` is published: a producer reading ``seq`` knows the
            # mark is already in viser's buffer (its lower bound holds).
            self.node.position = (float(seq), 0.0, 0.0)
            self.seq = seq
        return seq

    def trial_time(self, seq: int) -> float | None:
        """Trial time of mark ``seq`` (None when unknown or too old)."""
        with self._lock:
            return self._t.get(seq)


class PageFlow:
    """One page's stream: marks sent and applied, its acknowledgements, its stalls."""

    def __init__(self) -> None:
        self.in_flight: collections.deque[int] = collections.deque(maxlen=256)
        """The newest mark at the sending of each window not yet applied by the page."""
        self.applied_seq = -1
        self.queued = 0
        """Messages waiting in the page's queue at its last acknowledgement."""
        self.acking = False
        self.windows = 0
        self.stalls = 0
        self.acks: collections.deque[float] = collections.deque()
        self.last_ack = 0.0
        self.last_progress = 0.0
        """When the page last applied a new mark (or first acknowledged)."""
        self.total_acks = 0
        """Acknowledgements of new frames since the page connected."""
        self.event: asyncio.Event | None = None
        self.max_ahead = 0
        self.stalled = False
        """The page applied no new frame for :data:`STALE_S` (its stream trickles)."""
        self.last_trickle = 0.0
        self.first_ack = 0.0
        """When the page first acknowledged (monotonic s; 0: never)."""

    def ahead(self) -> int:
        """Windows sent whose frame mark the page has not applied yet."""
        return len(self.in_flight) if self.acking else 0

    async def credit(self) -> None:
        """Waits (on the server's loop) while the page has :data:`MAX_AHEAD` windows in
        flight; a page that applied nothing for :data:`STALE_S` gets one window per
        :data:`TRICKLE_S` (counted as a stall)."""
        if self.event is None:
            self.event = asyncio.Event()
        while self.acking and self.ahead() >= MAX_AHEAD:
            now = time.monotonic()
            if now - self.last_progress >= STALE_S:  # stalled: trickle, never flood
                if not self.stalled:
                    self.stalled = True
                    self.stalls += 1
                left = self.last_trickle + TRICKLE_S - now
                if left <= 0:
                    self.last_trickle = now
                    return
            else:
                left = self.last_progress + STALE_S - now
            self.event.clear()
            try:
                await asyncio.wait_for(self.event.wait(), timeout=left)
            except TimeoutError:
                pass

    def applied(self, seq: int) -> None:
        """The page has applied mark ``seq`` (and so every window sent before it)."""
        while self.in_flight and self.in_flight[0] <= seq:
            self.in_flight.popleft()

    def update_rate(self, now: float | None = None) -> float:
        """Distinct frames the page applied per second (last :data:`RATE_WINDOW_S`)."""
        now = time.monotonic() if now is None else now
        while self.acks and now - self.acks[0] > RATE_WINDOW_S:
            self.acks.popleft()
        return len(self.acks) / RATE_WINDOW_S


class FlowRegistry:
    """Pages by (server port, client id); the marks of each server by port."""

    def __init__(self) -> None:
        self.pages: dict[tuple[int, int], PageFlow] = {}
        self.marks: dict[int, FrameMarks] = {}
        self.lock = threading.Lock()

    def page(self, port: int, client_id: int) -> PageFlow:
        with self.lock:
            return self.pages.setdefault((port, client_id), PageFlow())

    def drop(self, port: int, client_id: int) -> None:
        with self.lock:
            self.pages.pop((port, client_id), None)

    def of_port(self, port: int) -> dict[int, PageFlow]:
        with self.lock:
            return {cid: f for (p, cid), f in self.pages.items() if p == port}


registry = FlowRegistry()


def _port(websocket: Any) -> int:
    try:
        return int(websocket.local_address[1])
    except Exception:
        return -1


class _PacedSocket:
    """A websocket whose ``send`` waits, after each window, for the page's credit."""

    def __init__(self, ws: Any, flow: PageFlow, marks: FrameMarks | None, counted: bool):
        self._ws, self._flow, self._marks, self._counted = ws, flow, marks, counted
        self._pulled = self._mark()

    def _mark(self) -> int:
        return self._marks.seq if self._marks is not None else 0

    def __getattr__(self, name: str) -> Any:
        return getattr(self._ws, name)

    async def send(self, data: Any) -> None:
        # The window being sent was pulled after ``_pulled`` was read, so every mark up to
        # ``_pulled`` had reached viser's buffer: once the page has applied this window its
        # mark is >= ``_pulled`` (a lower bound: never a window counted applied too late).
        flow, seq = self._flow, self._pulled
        await self._ws.send(data)
        flow.windows += 1
        if flow.acking:
            if self._counted:
                flow.in_flight.append(seq)
                flow.applied(flow.applied_seq)
                flow.max_ahead = max(flow.max_ahead, flow.ahead())
            await flow.credit()
        self._pulled = self._mark()  # read before the producer pulls its next window


_original_producer = _infra._message_producer


async def paced_producer(websocket: Any, buffer: Any, client_id: int,
                         backlog_done_message: Any = None) -> None:
    """viser's producer of one connection's stream, paced by the page (module doc): both
    of a page's streams wait for its credit; the broadcast one (with the replay marker)
    carries the frame marks, so its windows are the ones counted in flight."""
    port = _port(websocket)
    flow = registry.page(port, client_id)
    counted = backlog_done_message is not None
    sock = _PacedSocket(websocket, flow, registry.marks.get(port), counted)
    try:
        await _original_producer(sock, buffer, client_id,  # type: ignore[arg-type]
                                 backlog_done_message=backlog_done_message)
    finally:
        registry.drop(port, client_id)


def acknowledge(port: int, client_id: int, text: str) -> bool:
    """Takes a page's acknowledgement (run on the server's event loop); False when the
    text is not one."""
    try:
        d = json.loads(text) if len(text) < 400 else None
        seq, queued = int(d["seq"]), int(d["q"])  # type: ignore[index]
    except (TypeError, ValueError, KeyError, OverflowError):
        return False
    if not (-1 <= seq < 2**53 and 0 <= queued < 2**31):
        return False
    flow = registry.page(port, client_id)
    now = time.monotonic()
    if not flow.acking:
        flow.last_progress = now
    if not flow.first_ack:
        flow.first_ack = now
    flow.acking = True
    flow.last_ack = now
    if seq > flow.applied_seq:
        flow.last_progress = now
        flow.stalled = False
        flow.applied_seq = seq
        flow.acks.append(time.monotonic())
        flow.total_acks += 1
    flow.applied(seq)
    flow.queued = queued
    if flow.event is not None:
        flow.event.set()
    return True


class PageAcks:
    """The acknowledgement channel of one server's pages: a hidden per-client field and the
    page script; :meth:`install` on every connect."""

    def __init__(self, server: viser.ViserServer):
        self.server = server
        self.port = server.get_port()
        self.marks = FrameMarks(server)
        registry.marks[self.port] = self.marks
        self.refused = 0

    def install(self, client: viser.ClientHandle) -> None:
        from vasim.viewer.audio import run_js

        field = client.gui.add_text("vasim-frame-ack", initial_value="", visible=False)
        cid = client.client_id

        async def on_ack(event: Any) -> None:
            if not acknowledge(self.port, cid, str(field.value)):
                self.refused += 1

        field.on_update(on_ack)
        run_js(client, ACK_JS % {"uuid": field._impl.uuid, "node": MARK_NODE,
                                 "heartbeat_ms": round(HEARTBEAT_S * 1000)})

    def pages(self) -> dict[int, PageFlow]:
        return registry.of_port(self.port)


class RateMeter:
    """Trial seconds per wall second over the last :data:`RATE_WINDOW_S` (the loop's
    realtime factor as the pages see it)."""

    def __init__(self) -> None:
        self.samples: collections.deque[tuple[float, float]] = collections.deque()

    def add(self, t_trial: float, now: float | None = None) -> None:
        now = time.monotonic() if now is None else now
        if self.samples and t_trial < self.samples[-1][1]:
            self.samples.clear()  # a new trial
        self.samples.append((now, float(t_trial)))
        while len(self.samples) > 2 and now - self.samples[0][0] > RATE_WINDOW_S:
            self.samples.popleft()

    def reset(self) -> None:
        self.samples.clear()

    def factor(self) -> float | None:
        """Recent trial s per wall s; None until 1 s of samples."""
        if len(self.samples) < 2:
            return None
        (w0, t0), (w1, t1) = self.samples[0], self.samples[-1]
        return (t1 - t0) / (w1 - w0) if w1 - w0 >= 1.0 else None


class ScenePacer:
    """When a server's frame next carries the unsteered scene (module doc, "Less per frame").

    Example:
        >>> p = ScenePacer()
        >>> p.rate(None), p.rate(60.0), p.rate(6.0), p.rate(0.3)
        (10.0, 10.0, 2.0, 0.2)
        >>> p.due(0.0, None), p.due(0.05, None), p.due(0.1, None)
        (True, False, True)
    """

    def __init__(self, base_hz: float = SCENE_HZ, min_hz: float = MIN_SCENE_HZ,
                 frames_per_scene: int = FRAMES_PER_SCENE):
        if not (0 < min_hz <= base_hz) or frames_per_scene < 1:
            raise ValueError(f"need 0 < min_hz <= base_hz and frames_per_scene >= 1, got "
                             f"{(min_hz, base_hz, frames_per_scene)!r}")
        self.base_hz, self.min_hz = float(base_hz), float(min_hz)
        self.frames_per_scene = int(frames_per_scene)
        self._last = -float("inf")
        self.sent = 0
        """Frames that carried the unsteered scene."""

    def rate(self, page_hz: float | None) -> float:
        """The unsteered scene's rate [Hz] for a server whose slowest page applies
        ``page_hz`` frames per second (None or NaN: no page that acknowledges)."""
        if page_hz is None or not page_hz == page_hz:
            return self.base_hz
        return min(self.base_hz, max(self.min_hz, float(page_hz) / self.frames_per_scene))

    def due(self, now: float, page_hz: float | None) -> bool:
        """True (and counted) when the frame at ``now`` [s] carries the unsteered scene."""
        # 1 ms of slack: a view thread at exactly the scene's rate is not skipped by jitter.
        if now - self._last >= 1.0 / self.rate(page_hz) - 1e-3:
            self._last = now
            self.sent += 1
            return True
        return False

    def reset(self) -> None:
        """The next frame carries the unsteered scene (a new trial)."""
        self._last = -float("inf")


def slowest_page_hz(acks: PageAcks) -> float | None:
    """Update rate of the slowest acknowledging page of ``acks``' server [1/s] (None: no
    page acknowledges). A page acknowledging for less than :data:`RATE_WINDOW_S` is rated
    over the time it has (not as if it had been silent before)."""
    now = time.monotonic()
    rates = []
    for p in acks.pages().values():
        if not p.acking:
            continue
        since = p.first_ack if p.first_ack else now
        span = min(RATE_WINDOW_S, max(now - since, 0.5))
        rates.append(p.update_rate(now) * RATE_WINDOW_S / span)
    return min(rates) if rates else None


def behind_notice(factor: float | None, speed: float, page: PageFlow | None,
                  view_hz: float, lag_s: float | None) -> str:
    """The "running behind" line for one page ('' when all keeps up).

    Example:
        >>> behind_notice(0.8, 1.0, None, 40.0, None)
        '**Running behind: 0.8× real time** (this computer cannot keep up with the simulation)'
    """
    parts = []
    if factor is not None and factor < 0.9 * speed:
        parts.append(f"**Running behind: {factor / speed:.1f}× real time** (this computer "
                     "cannot keep up with the simulation)")
    if page is not None and page.acking:
        rate = page.update_rate()
        if (lag_s is not None and lag_s > 0.5) or rate < 0.5 * view_hz:
            late = f", {lag_s:.1f} s late" if lag_s is not None and lag_s > 0.05 else ""
            parts.append(f"**This page is behind**: it shows {rate:.0f} of {view_hz:.0f} "
                         f"updates/s{late} (it skips to the present)")
    return "  \n".join(parts)


def page_stats(acks: PageAcks, t_now: float) -> dict[str, float]:
    """Per-server page figures: slowest page's update rate [1/s], most windows in flight,
    most queued messages, largest displayed-clock lag [s], stalls."""
    pages = list(acks.pages().values())
    live = [p for p in pages if p.acking]
    lags = []
    for p in live:
        t = acks.marks.trial_time(p.applied_seq)
        if t is not None:
            lags.append(max(0.0, t_now - t))
    return {
        "pages": float(len(live)),
        "page_update_hz_min": min((p.update_rate() for p in live), default=float("nan")),
        "windows_ahead_max": float(max((p.ahead() for p in live), default=0)),
        "windows_ahead_peak": float(max((p.max_ahead for p in live), default=0)),
        "queued_max": float(max((p.queued for p in live), default=0)),
        "clock_lag_s_max": float(max(lags)) if lags else float("nan"),
        "stalls": float(sum(p.stalls for p in pages)),
    }


def install() -> None:
    """Wraps viser's producer (idempotent; called by :func:`isolation.install`)."""
    _infra._message_producer = paced_producer


__all__ = [
    "ACK_JS",
    "FRAMES_PER_SCENE",
    "HEARTBEAT_S",
    "MARK_NODE",
    "MAX_AHEAD",
    "MIN_SCENE_HZ",
    "SCENE_HZ",
    "STALE_S",
    "TRICKLE_S",
    "FrameMarks",
    "PageAcks",
    "PageFlow",
    "RateMeter",
    "ScenePacer",
    "acknowledge",
    "behind_notice",
    "install",
    "paced_producer",
    "page_stats",
    "registry",
    "slowest_page_hz",
]
