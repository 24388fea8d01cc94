"""``TrialStore``: a study's trials in one SQLite file, the ``TrialSink`` and
``TrialSource`` the study layer gives the trial engine (``vasim.trials.sink``).

It is assembled from the parts of this package, one job each: opening, pragmas,
migrations and read-only mode (``connection``), the trial life cycle (``lifecycle``),
subjects, sessions and questionnaires (``sessions``) and the readers (``readers``). The
database layout is documented in ``vasim.study.store.schema``.

Example:
    >>> import tempfile, pathlib
    >>> from vasim.records.samples import SampleBuffer
    >>> from vasim.records.trial_meta import TrialMeta
    >>> with tempfile.TemporaryDirectory() as d, TrialStore(pathlib.Path(d) / "s.db") as st:
    ...     tid = st.begin_trial(TrialMeta(subject="S01", task="trajectory"))
    ...     buf = SampleBuffer()
    ...     buf.append(0, 0.001, (0, 0, 0), (0, 0, 0.01), 0)
    ...     st.finish_trial(tid, buf, summary={"completed": False, "points_reached": 0})
    ...     st.trial(tid)["status"], st.trial(tid)["outcome"], len(st.samples(tid))
    ('completed', 'timed_out', 1)
"""

from __future__ import annotations

import os
import sys

from vasim.study.store.lifecycle import TrialLifecycle
from vasim.study.store.readers import StoreReaders
from vasim.study.store.sessions import SessionWriters


class TrialStore(TrialLifecycle, SessionWriters, StoreReaders):
    """A study's trials in one SQLite file (layout: ``vasim.study.store.schema``).

    Args:
        path: the database file; created (with the schema) if missing or empty. Its folder
            must exist.
        readonly: open for reading only (a ``mode=ro`` connection: no schema creation, no
            migration, no interrupted-trial recovery); for listing, export and reports.

    Raises:
        StoreError: naming the path, if the file is not a SQLite database, not a vasim
            store, written by a newer vasim (schema version), cannot be opened, or (not
            read-only) cannot be written.

    A writable open marks 'interrupted' the trials whose writer died (``recovered``); a
    read-only open only finds them (``stale``) and says so in one line on stderr. A store
    object belongs to the thread that opened it (sqlite3's rule); use one per thread or
    process. ``with TrialStore(p) as st:`` closes it at the end.
    """

    def __init__(self, path: str | os.PathLike[str], *, readonly: bool = False):
        super().__init__(path, readonly=readonly)
        self.stale: list[int] = []
        """Read-only: ids of 'running' trials whose writer has died (left unmarked)."""
        self.recovered: list[int] = []
        """Ids of the trials this open marked 'interrupted' (their writer had died)."""
        if not readonly:
            self.recovered = self.recover_interrupted()
            return
        self.stale = [tid for tid, _ in self.stale_trials()]
        if self.stale:
            # **Decision**: printed, not logged: the notice must reach the person running
            # `vasim study list/export` or `vasim report` whatever the logging setup, and
            # those open the store inside library calls.
            ids = ", ".join(str(t) for t in self.stale)
            print(f"note: {self.path} is open read-only: {len(self.stale)} stale 'running' "
                  f"trial(s) ({ids}) whose writer has ended were not marked interrupted "
                  "(open it writable, e.g. `vasim study resume`, to do so)", file=sys.stderr)

__all__ = ["TrialStore"]
