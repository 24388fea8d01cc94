"""The durable trial store: one SQLite file per study (spec/study.md §2).

One module per job:

* ``schema``: the database layout (documented there in full), DDL, versions, migrations;
* ``packing``: how a trial's samples are stored (compressed columns, the precision kept);
* ``vocabulary``: the values stored fields take (statuses, outcomes, groups, levels) and
  ``Demographics``;
* ``liveness``: whether the process that writes a 'running' trial still runs (psutil);
* ``connection``: opening a database (pragmas, schema check, migration, read-only mode);
* ``lifecycle``: the trial life cycle writers (begin, finish, keep/mark interrupted,
  recover);
* ``sessions``: subjects, sessions, demographics and answers writers (``SessionMeta``);
* ``readers``: everything read back as pandas frames;
* ``trial_store``: ``TrialStore``, all of the above in one object (a ``TrialSink``).

``from vasim.study.store import TrialStore, SessionMeta, Demographics, ...`` is the public
surface; the names below are re-exported explicitly.
"""

from __future__ import annotations

from vasim.records.trial_meta import SUBJECT_CODE_PATTERN as SUBJECT_CODE_PATTERN
from vasim.records.trial_meta import TrialMeta as TrialMeta
from vasim.records.trial_meta import validate_subject_code as validate_subject_code
from vasim.study.store.schema import ANSWER_COLUMNS as ANSWER_COLUMNS
from vasim.study.store.schema import APPLICATION_ID as APPLICATION_ID
from vasim.study.store.schema import DEMOGRAPHIC_COLUMNS as DEMOGRAPHIC_COLUMNS
from vasim.study.store.schema import EVENT_COLUMNS as EVENT_COLUMNS
from vasim.study.store.schema import SCHEDULE_COLUMNS as SCHEDULE_COLUMNS
from vasim.study.store.schema import SCHEMA_VERSION as SCHEMA_VERSION
from vasim.study.store.schema import SESSION_COLUMNS as SESSION_COLUMNS
from vasim.study.store.schema import TRIAL_COLUMNS as TRIAL_COLUMNS
from vasim.study.store.sessions import SessionMeta as SessionMeta
from vasim.study.store.trial_store import TrialStore as TrialStore
from vasim.study.store.vocabulary import DEMOGRAPHIC_FIELDS as DEMOGRAPHIC_FIELDS
from vasim.study.store.vocabulary import GROUPS as GROUPS
from vasim.study.store.vocabulary import LAPAROSCOPY_LEVELS as LAPAROSCOPY_LEVELS
from vasim.study.store.vocabulary import ROBOTIC_LEVELS as ROBOTIC_LEVELS
from vasim.study.store.vocabulary import SESSION_STATUSES as SESSION_STATUSES
from vasim.study.store.vocabulary import SIMULATOR_LEVELS as SIMULATOR_LEVELS
from vasim.study.store.vocabulary import SPECIALISATIONS as SPECIALISATIONS
from vasim.study.store.vocabulary import TRIAL_OUTCOMES as TRIAL_OUTCOMES
from vasim.study.store.vocabulary import TRIAL_STATUSES as TRIAL_STATUSES
from vasim.study.store.vocabulary import Demographics as Demographics
from vasim.study.store.vocabulary import SessionStatus as SessionStatus
from vasim.study.store.vocabulary import TrialOutcome as TrialOutcome
from vasim.study.store.vocabulary import TrialStatus as TrialStatus
from vasim.study.store.vocabulary import validate_label as validate_label

__all__ = [
    "ANSWER_COLUMNS",
    "APPLICATION_ID",
    "DEMOGRAPHIC_COLUMNS",
    "DEMOGRAPHIC_FIELDS",
    "EVENT_COLUMNS",
    "GROUPS",
    "LAPAROSCOPY_LEVELS",
    "ROBOTIC_LEVELS",
    "SCHEDULE_COLUMNS",
    "SCHEMA_VERSION",
    "SESSION_COLUMNS",
    "SESSION_STATUSES",
    "SIMULATOR_LEVELS",
    "SPECIALISATIONS",
    "SUBJECT_CODE_PATTERN",
    "TRIAL_COLUMNS",
    "TRIAL_OUTCOMES",
    "TRIAL_STATUSES",
    "Demographics",
    "SessionMeta",
    "SessionStatus",
    "TrialMeta",
    "TrialOutcome",
    "TrialStatus",
    "TrialStore",
    "validate_label",
    "validate_subject_code",
]
