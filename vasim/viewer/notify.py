"""Errors of viewer callbacks, shown to every connected page (shared by both viewer apps).

A viser callback that raises would only reach the server's log; the pages would show
nothing. :class:`ErrorReporter` wraps callbacks so that an error is logged, kept in
``errors`` and shown as a red notification on every connected client, and never raised.
"""

from __future__ import annotations

import functools
import logging
from collections.abc import Callable
from typing import Any

from vasim.core.errors import VasimError

log = logging.getLogger(__name__)


class ErrorReporter:
    """Mixin for the viewer apps: needs ``self.server`` (a viser server or None) and
    ``self.errors`` (a list); ``notify_title`` names the notifications."""

    notify_title = "vasim"
    server: Any
    errors: list[str]

    def _report(self, message: str) -> None:
        self.errors.append(message)
        server = self.server
        if server is None:
            return
        for client in server.get_clients().values():
            try:
                client.add_notification(self.notify_title, message, color="red",
                                        auto_close_seconds=8.0)
            except Exception:  # a closing connection must not mask the original error
                log.debug("notification to client %s failed", client.client_id,
                          exc_info=True)

    def _guard(self, fn: Callable[..., Any]) -> Callable[..., Any]:
        """Wraps a callback: an exception is logged and notified, never raised."""

        @functools.wraps(fn)
        def wrapped(*args: Any, **kwargs: Any) -> Any:
            try:
                return fn(*args, **kwargs)
            except VasimError as exc:
                log.warning("%s viewer: %s", self.notify_title, exc)
                self._report(str(exc))
            except Exception as exc:
                log.exception("%s viewer callback %s failed", self.notify_title,
                              getattr(fn, "__name__", fn))
                self._report(f"internal error: {type(exc).__name__}: {exc}")
            return None

        return wrapped
