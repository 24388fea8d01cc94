"""Every input batch a page sends reaches the instrument once, in order, however slowly the
server handles them (issues #26.3, #31).

The page writes each batch into a hidden text field; viser runs a plain ``on_update``
callback later, on its thread pool, and the callback can only read the field's value as it
is *then*. On a loaded host a later batch had already replaced it: one batch was applied
twice, another never (the keyboard trial's moves came out doubled at load 8). Here the
instrument takes 5 ms per batch and the batches arrive back to back, so a callback that
lags behind its message is certain, not a matter of load: each batch must still arrive
exactly once, in the order sent.
"""

from __future__ import annotations

import json
import time
from typing import Any

import msgspec
import viser
from websockets.sync.client import connect

from tests.viewer.test_isolation import SUBPROTOCOL, camera
from vasim.haptics.laparoscopic import Increment
from vasim.viewer.instrument_input import InstrumentInput

N = 60


class SlowInstrument:
    """Takes 5 ms per batch (a loaded host's pose update) and records what it took."""

    def __init__(self) -> None:
        self.took: list[float] = []

    def push(self, inc: Increment) -> bool:
        time.sleep(0.005)
        self.took.append(inc.stick_x_s)
        return True


def test_each_batch_reaches_the_instrument_once_and_in_order() -> None:
    server = viser.ViserServer(host="127.0.0.1", port=0, verbose=False)
    dev = SlowInstrument()
    try:
        def unguarded(fn: Any) -> Any:
            return fn

        channel = InstrumentInput(server, lambda: dev, unguarded)  # type: ignore[arg-type, return-value]
        sent = [round(0.001 * (i + 1), 3) for i in range(N)]
        with connect(f"ws://127.0.0.1:{server.get_port()}/", subprotocols=[SUBPROTOCOL],
                     open_timeout=30) as ws:
            ws.send(msgspec.msgpack.encode(camera()))
            for seq, sx in enumerate(sent, start=1):
                batch = json.dumps({"dx": 0, "dy": 0, "wheel": 0, "sx": sx, "sy": 0,
                                    "ins": 0, "roll": 0, "seq": seq})
                ws.send(msgspec.msgpack.encode({"type": "GuiUpdateMessage",
                                                "uuid": channel.uuid,
                                                "updates": {"value": batch}}))
            t_end = time.monotonic() + 60
            while len(dev.took) < N and time.monotonic() < t_end:
                time.sleep(0.05)
            time.sleep(0.3)  # anything applied twice would come now
        assert dev.took == sent
        assert channel.batches == N and channel.last_seq == N
    finally:
        server.stop()
