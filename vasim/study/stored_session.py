"""A session's stored record, read back from the store: the part of a session both the
session runner (:mod:`vasim.study.session`) and the proficiency gates
(:mod:`vasim.study.gates`) read.

**Decision** (issue #29 item 4): this is its own module, below both, so that the gates
read a session without importing :mod:`vasim.study.session` (which runs the gates): the
former ``gates`` <-> ``session`` module cycle, hidden by function-level imports, is gone.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import pandas as pd

from vasim.study.protocol import Protocol, ScheduledTrial, parse_protocol
from vasim.study.store import TrialStore


@dataclass(frozen=True)
class StoredSession:
    """A session's row and schedule as stored.

    Attributes:
        id: session id. subject: subject code. protocol: the protocol parsed from the text
        stored with the session. seed: randomisation seed. status: running | completed |
        aborted. config: the stored run settings (``SessionSettings.to_record``).
        schedule: the stored schedule. completed: trial id of the completed trial of each
        scheduled index (None if none).
    """

    id: int
    subject: str
    protocol: Protocol
    seed: int
    status: str
    config: Mapping[str, Any]
    schedule: tuple[ScheduledTrial, ...]
    completed: tuple[int | None, ...]


def read_session(store: TrialStore, session_id: int) -> StoredSession:
    """Reads a session's record back from the store (protocol from its stored text).

    Raises:
        StoreError: unknown session.
    """
    row = store.session(session_id)
    protocol = parse_protocol(row["protocol_toml"],
                              source=f"{store.path} session {row['id']} (stored protocol)")
    sched = store.schedule(session_id)
    schedule = tuple(ScheduledTrial.from_row(r) for r in sched.to_dict("records"))
    completed = tuple(None if pd.isna(v) else int(v) for v in sched["trial_id"])
    return StoredSession(id=int(row["id"]), subject=row["subject"], protocol=protocol,
                         seed=int(row["seed"]), status=row["status"],
                         config=row["config"] or {}, schedule=schedule, completed=completed)
