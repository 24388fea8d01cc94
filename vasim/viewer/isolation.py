"""Per-client isolation of the viser pages: every client message is untrusted (issue #30.2).

A page is a websocket client of a viser server; what it sends reaches viser's handlers and,
through them, vasim's callbacks and state (a client's camera, GUI values). Two wrappers of
viser's infrastructure, installed once by :func:`install` (from
:func:`vasim.viewer.access.guarded_server`, before any server is bound):

* **Validated before use.** viser's per-connection receive loop
  (``viser.infra._infra._message_consumer``) is replaced by :func:`_guarded_consumer`,
  which decodes each message and passes it on only if :func:`message_refusal` finds
  nothing wrong: every number finite; a ``ViewerCameraMessage`` a camera (finite,
  |coordinate| <= 1e6 m, a unit-ish quaternion, 0 < fov < pi, 0 < near < far, look_at away
  from position, a non-zero up direction, image size in 0..100,000); a ``GuiUpdateMessage``
  changing only ``value`` (viser would otherwise let any client set any property of an
  input -- its label, visibility, options -- and broadcast it to every other page); no
  share-tunnel request (a client could otherwise make the server publish itself through
  viser's share service) and no file upload (no vasim page has an upload input). A refused
  message is dropped and logged (logger ``vasim.viewer.isolation``, WARNING); a client
  that sends :data:`STRIKES` refused messages within :data:`STRIKE_WINDOW_S` is
  disconnected (close code 1008, policy violation) and logged. **Decision**: an honest
  viser 1.1.1 client never sends any of these, so a handful of strikes is a conservative
  limit; dropping one message (not the connection) keeps a glitching page usable.
* **Loop-safe wake-ups.** viser's message buffers call ``asyncio.Event.set()`` on every
  ``push`` -- from whichever thread writes a handle (vasim's view thread). ``Event.set``
  walks the deque of waiting futures, which the event loop mutates concurrently: with
  ~150 clients waiting this raised "deque mutated during iteration" (issue #30.5). The
  buffers' events are replaced by :class:`LoopSafeEvent`, whose ``set()`` from another
  thread is handed to the owning loop with ``call_soon_threadsafe``: every asyncio object
  is touched only from the thread that owns its loop. (Handle setters themselves are
  thread-safe in viser: they push under the buffer's lock.)

Both wrap private API of the pinned ``viser==1.1.1`` (``tests/viewer/test_isolation.py``
checks they are in place and effective) and fork nothing.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import logging
import math
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import viser.infra._infra as _infra
import websockets.exceptions
from viser import _messages
from viser.infra._async_message_buffer import AsyncMessageBuffer

log = logging.getLogger(__name__)

STRIKES = 5
"""Refused messages within :data:`STRIKE_WINDOW_S` after which a client is disconnected."""
STRIKE_WINDOW_S = 60.0
MAX_COORD_M = 1e6
"""Largest camera coordinate accepted [m] (the abdomen spans ~0.5 m)."""
MAX_IMAGE_PX = 100_000
_MAX_DEPTH = 16
_MAX_ITEMS = 200_000

_REFUSED_TYPES: dict[type, str] = {
    _messages.ShareUrlRequest: "share-tunnel requests are not served",
    _messages.ShareUrlDisconnect: "share-tunnel requests are not served",
    _messages.FileTransferStartUpload: "no page of vasim takes file uploads",
    _messages.FileTransferPart: "no page of vasim takes file uploads",
}


class LoopSafeEvent(asyncio.Event):
    """An ``asyncio.Event`` whose ``set()`` may be called from any thread: off the owning
    loop's thread it is scheduled on that loop (``call_soon_threadsafe``)."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__()
        self._owner = loop

    def set(self) -> None:
        if asyncio._get_running_loop() is self._owner:
            super().set()
            return
        try:
            self._owner.call_soon_threadsafe(super().set)
        except RuntimeError:  # the loop is closed (teardown): nobody left to wake
            pass


@dataclasses.dataclass
class _LoopSafeBuffer(AsyncMessageBuffer):
    """viser's message buffer with :class:`LoopSafeEvent` wake-ups."""

    def __post_init__(self) -> None:
        self.message_event = LoopSafeEvent(self.event_loop)
        self.flush_event = LoopSafeEvent(self.event_loop)


# -- validation ---------------------------------------------------------------------------


def _finite_everywhere(value: Any, depth: int = 0, budget: list[int] | None = None) -> bool:
    """True when no float inside ``value`` (nested lists, tuples, dicts) is NaN or inf."""
    budget = [_MAX_ITEMS] if budget is None else budget
    budget[0] -= 1
    if budget[0] < 0 or depth > _MAX_DEPTH:
        return False
    if isinstance(value, float):
        return math.isfinite(value)
    if isinstance(value, np.ndarray):
        return value.dtype.kind not in "fc" or bool(np.isfinite(value).all())
    if isinstance(value, list | tuple):
        return all(_finite_everywhere(v, depth + 1, budget) for v in value)
    if isinstance(value, dict):
        return all(_finite_everywhere(v, depth + 1, budget) for v in value.values())
    return True


def _vector(value: Any, n: int) -> np.ndarray | None:
    """``value`` as n finite real numbers, or None."""
    if not isinstance(value, list | tuple) or len(value) != n:
        return None
    if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        return None
    out = np.asarray(value, dtype=np.float64)
    return out if bool(np.isfinite(out).all()) else None


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    v = float(value)
    return v if math.isfinite(v) else None


def camera_refusal(m: _messages.ViewerCameraMessage) -> str | None:
    """Why a client's camera report is unusable, or None."""
    pos, look, up = _vector(m.position, 3), _vector(m.look_at, 3), _vector(m.up_direction, 3)
    wxyz = _vector(m.wxyz, 4)
    if pos is None or look is None or up is None or wxyz is None:
        return "camera pose not finite numbers"
    if max(float(np.abs(pos).max()), float(np.abs(look).max())) > MAX_COORD_M:
        return f"camera further than {MAX_COORD_M:g} m"
    if not 0.5 < float(np.linalg.norm(wxyz)) < 2.0:
        return "camera orientation is not a unit quaternion"
    if float(np.linalg.norm(look - pos)) < 1e-9 or float(np.linalg.norm(up)) < 1e-9:
        return "camera looks at its own position or has no up direction"
    fov, near, far = _number(m.fov), _number(m.near), _number(m.far)
    if fov is None or not 0.0 < fov < math.pi:
        return "camera field of view outside (0, pi)"
    if near is None or far is None or not 0.0 < near < far:
        return "camera clipping planes not 0 < near < far"
    for px in (m.image_width, m.image_height):
        if isinstance(px, bool) or not isinstance(px, int) or not 0 <= px <= MAX_IMAGE_PX:
            return "camera image size out of range"
    return None


def message_refusal(message: Any) -> str | None:
    """Why a message from a page must not be used, or None to pass it to viser.

    Example:
        >>> from viser import _messages as m
        >>> message_refusal(m.GuiUpdateMessage("id", {"visible": False}))
        'GUI update of properties other than value: visible'
    """
    kind = type(message)
    if kind in _REFUSED_TYPES:
        return _REFUSED_TYPES[kind]
    if not _finite_everywhere(getattr(message, "__dict__", {})):
        return "non-finite or too deeply nested numbers"
    if isinstance(message, _messages.ViewerCameraMessage):
        return camera_refusal(message)
    if isinstance(message, _messages.GuiUpdateMessage):
        if not isinstance(message.updates, dict) or set(message.updates) != {"value"}:
            keys = sorted(map(str, message.updates)) if isinstance(message.updates, dict) \
                else [type(message.updates).__name__]
            return f"GUI update of properties other than value: {', '.join(keys)[:80]}"
    return None


class Strikes:
    """Refused messages of one connection in a sliding window."""

    def __init__(self, limit: int = STRIKES, window_s: float = STRIKE_WINDOW_S):
        self.limit, self.window_s = limit, window_s
        self.times: collections.deque[float] = collections.deque()

    def hit(self, now: float | None = None) -> bool:
        """Counts one refusal; True when the client has now used up its strikes."""
        now = time.monotonic() if now is None else now
        self.times.append(now)
        while self.times and now - self.times[0] > self.window_s:
            self.times.popleft()
        return len(self.times) >= self.limit


refused_total = 0
"""Messages refused since start (all servers; for tests and benches)."""
disconnected_total = 0
"""Clients disconnected for refused messages since start."""
_count_lock = threading.Lock()


def _peer(websocket: Any) -> str:
    try:
        a = websocket.remote_address
        return f"{a[0]}:{a[1]}"
    except Exception:
        return "?"


async def _guarded_consumer(websocket: Any, handle_message: Callable[[Any], None],
                            message_class: type) -> None:
    """viser's receive loop, with every message validated before it is handled."""
    global refused_total, disconnected_total
    strikes = Strikes()
    port = getattr(getattr(websocket, "local_address", None), "__getitem__", lambda i: "?")(1)
    while True:
        raw = await websocket.recv()
        reason: str | None
        message: Any = None
        if not isinstance(raw, bytes):
            reason = "text frame (viser speaks binary)"
        else:
            try:
                message = message_class.deserialize(raw)  # type: ignore[attr-defined]
            except Exception as exc:
                reason = f"undecodable message ({type(exc).__name__})"
            else:
                try:
                    reason = message_refusal(message)
                except Exception as exc:  # a shape the checks did not foresee
                    reason = f"unreadable {type(message).__name__} ({type(exc).__name__})"
        if reason is None:
            handle_message(message)
            continue
        with _count_lock:
            refused_total += 1
        name = type(message).__name__ if message is not None else "message"
        log.warning("vasim viewer (port %s): dropped %s from %s: %s", port, name,
                    _peer(websocket), reason)
        if strikes.hit():
            with _count_lock:
                disconnected_total += 1
            log.warning("vasim viewer (port %s): disconnected %s after %d refused messages "
                        "within %.0f s", port, _peer(websocket), strikes.limit,
                        strikes.window_s)
            await websocket.close(1008, "vasim: too many invalid messages")
            raise websockets.exceptions.ConnectionClosedOK(None, None)


_installed = False
_install_lock = threading.Lock()


def install() -> None:
    """Installs both wrappers into viser (idempotent; before servers are bound)."""
    global _installed
    with _install_lock:
        if _installed:
            return
        from vasim.viewer import flow

        flow.install()
        _infra._message_consumer = _guarded_consumer
        _infra.AsyncMessageBuffer = _LoopSafeBuffer  # type: ignore[misc]
        _installed = True


def installed() -> bool:
    """True when :func:`install` has put both wrappers in place."""
    return (_infra._message_consumer is _guarded_consumer
            and _infra.AsyncMessageBuffer is _LoopSafeBuffer)


__all__ = ["STRIKES", "STRIKE_WINDOW_S", "LoopSafeEvent", "Strikes", "camera_refusal",
           "install", "installed", "message_refusal"]
