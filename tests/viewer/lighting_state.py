"""What a viser server has told its pages about the environment map (for the lighting
tests of issue #26.2)."""

from __future__ import annotations

from typing import Any


def state_messages(server: Any) -> list[Any]:
    """The messages in ``server``'s state for new pages (viser 1.1's broadcast buffer)."""
    buffer = server._websock_server._broadcast_buffer
    with buffer.buffer_lock:
        return list(buffer.message_from_id.values())


def environment_maps(server: Any) -> list[Any]:
    """The ``EnvironmentMapMessage`` objects in ``server``'s state (none when nothing
    configured it, and the page then draws viser's default map)."""
    return [m for m in state_messages(server) if type(m).__name__ == "EnvironmentMapMessage"]
