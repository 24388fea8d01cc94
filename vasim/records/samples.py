"""The per-trial sample buffer the 1 kHz loop writes into (spec/study.md §2).

``SampleBuffer`` is a columnar, preallocated, growable buffer: one numpy array per
column, whose capacity doubles when full, so that ``append`` never allocates in the
steady state (amortised O(1), ~1-2 µs per sample on the reference machine; see
``tests/study/test_store.py::test_append_is_fast``).

Columns (one row per logged step k; vectors in the world frame of the scene):

==============  ========  ======  ==================================================
column          dtype     shape   meaning
==============  ========  ======  ==================================================
``k``           int64     (n,)    step index of the logging loop
``t``           float64   (n,)    time since trial start [s]
``x``           float64   (n,3)   tool centre point x(k) [m]
``g``           float64   (n,3)   current goal point g(k) [m] (after the step-k
                                  goal-advance check, see ``vasim.records.point_metrics``)
``goal_index``  int32     (n,)    index i of the goal point, ``N`` once all N points
                                  are reached
``force``       float64   (n,3)   force rendered to the operator [N] (0 if none)
``ms``          float64   (n,3)   motion-scaling factors per axis (1 if none)
``zoom``        float64   (n,)    Mag camera magnification (1 if none)
``audio_pitch``  float64  (n,)    AG pitch (0 if none)
``audio_period`` float64  (n,)    AG beep period [s] (0 if none)
``audio_volume`` float64  (n,)    AG volume in [0, 1] (0 if none)
``contact``     int8      (n,)    tissue-contact flag (0/1; 0 until contact exists)
``f_contact``   float64   (n,3)   tissue contact force on the tool tip [N] (0 when no
                                  tissue model fills it)
``tau_contact`` float64   (n,3)   tissue contact torque on the tool [N m] (0 if none)
``delicate``    int8      (n,)    contact with a delicate structure (0/1; 0 if none)
``clutch``      int8      (n,)    clutch engaged: master decoupled from the tool (0/1)
``in_view``     int8      (n,)    tool tip inside the endoscope camera's field of view:
                                  1 yes, 0 no, -1 not determined (the default)
``gain``        float64   (n,)    fixture gain G in force at the step (1 = the schema
                                  as written; ``vasim.fixtures.gain``); store v5
==============  ========  ======  ==================================================

The last five columns came with schema version 2 of the store; their defaults (no contact
force, no delicate contact, no clutch, ``in_view = -1``) let producers that do not know them
(the abdomen physics fills the contact columns, the trial runner fills ``in_view``) keep
working unchanged, and say honestly that nothing was measured.

The active fixtures are a trial-level string (``active_fixtures``, e.g. ``"VG+FF"`` or
``""`` for a VF-free trial): they do not change within a trial.

The flat (tabular) names used by ``to_frame`` and by the store's ``samples`` table are
``FRAME_COLUMNS``: ``x`` becomes ``x_x, x_y, x_z``, ``g`` becomes ``g_x, ...``, ``force``
becomes ``f_x, f_y, f_z``, ``ms`` becomes ``ms_x, ms_y, ms_z``, ``f_contact`` becomes
``fc_x, fc_y, fc_z`` and ``tau_contact`` becomes ``tc_x, tc_y, tc_z``.

One writer only: the buffer is not thread-safe. Readers should take ``view()`` or
``to_frame()`` after the trial (or hand over a copy).
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike, NDArray

# (name, dtype, width; 1 = scalar column, 3 = vector column, flat names of the parts)
_AXES = ("x", "y", "z")
COLUMN_SPECS: tuple[tuple[str, type, tuple[str, ...]], ...] = (
    ("k", np.int64, ("k",)),
    ("t", np.float64, ("t",)),
    ("x", np.float64, tuple(f"x_{a}" for a in _AXES)),
    ("g", np.float64, tuple(f"g_{a}" for a in _AXES)),
    ("goal_index", np.int32, ("goal_index",)),
    ("force", np.float64, tuple(f"f_{a}" for a in _AXES)),
    ("ms", np.float64, tuple(f"ms_{a}" for a in _AXES)),
    ("zoom", np.float64, ("zoom",)),
    ("audio_pitch", np.float64, ("audio_pitch",)),
    ("audio_period", np.float64, ("audio_period",)),
    ("audio_volume", np.float64, ("audio_volume",)),
    ("contact", np.int8, ("contact",)),
    ("f_contact", np.float64, tuple(f"fc_{a}" for a in _AXES)),
    ("tau_contact", np.float64, tuple(f"tc_{a}" for a in _AXES)),
    ("delicate", np.int8, ("delicate",)),
    ("clutch", np.int8, ("clutch",)),
    ("in_view", np.int8, ("in_view",)),
    ("gain", np.float64, ("gain",)),
)
"""Every buffer column: name, numpy dtype, and its flat (frame / SQL) column names."""

COLUMNS: tuple[str, ...] = tuple(name for name, _, _ in COLUMN_SPECS)
"""Buffer column names, in storage order."""

FRAME_COLUMNS: tuple[str, ...] = tuple(flat for _, _, parts in COLUMN_SPECS for flat in parts)
"""Flat column names of ``to_frame()`` and of the store's ``samples`` table, in order."""

FRAME_DTYPES: dict[str, type] = {
    flat: dtype for _, dtype, parts in COLUMN_SPECS for flat in parts
}
"""numpy dtype of each flat column."""

OPTIONAL_COLUMNS: tuple[str, ...] = ("f_contact", "tau_contact", "delicate", "clutch",
                                     "in_view", "gain")
"""Buffer columns added with store schema version 2 (``gain``: version 5); ``from_columns``
fills them with their defaults when a source (e.g. an older export) lacks them."""

IN_VIEW_UNKNOWN = -1
"""``in_view`` value of a sample whose visibility was not determined."""

_DEFAULT_FILL = {"force": 0.0, "ms": 1.0, "zoom": 1.0, "audio_pitch": 0.0,
                 "audio_period": 0.0, "audio_volume": 0.0, "contact": 0, "f_contact": 0.0,
                 "tau_contact": 0.0, "delicate": 0, "clutch": 0, "in_view": IN_VIEW_UNKNOWN,
                 "gain": 1.0}
"""The value of a column nobody wrote."""


class SampleBuffer:
    """Preallocated columnar buffer of one trial's samples.

    Args:
        capacity: initial number of rows (grows by doubling; a 60 s trial at 1 kHz is
            60,000 rows, so ``65536`` avoids every reallocation for such a trial).
        active_fixtures: trial-level string naming the active fixture(s), ``""`` for none.

    Example:
        >>> buf = SampleBuffer(capacity=2, active_fixtures="VG")
        >>> for k in range(3):
        ...     buf.append(k, k * 1e-3, (0.0, 0.0, k * 1e-3), (0.0, 0.0, 0.01), 0)
        >>> len(buf), buf.capacity
        (3, 4)
        >>> buf.view()["x"][:, 2].tolist()
        [0.0, 0.001, 0.002]
    """

    __slots__ = (
        "_arrays",
        "_cap",
        "_clutch",
        "_contact",
        "_delicate",
        "_f",
        "_fc",
        "_g",
        "_gain",
        "_gi",
        "_in_view",
        "_k",
        "_ms",
        "_n",
        "_period",
        "_pitch",
        "_t",
        "_tc",
        "_volume",
        "_x",
        "_zoom",
        "active_fixtures",
    )

    def __init__(self, capacity: int = 4096, *, active_fixtures: str = ""):
        capacity = int(capacity)
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity!r}")
        if not isinstance(active_fixtures, str):
            raise ValueError(f"active_fixtures must be a string, got {active_fixtures!r}")
        self.active_fixtures = active_fixtures
        self._n = 0
        self._allocate(capacity, copy_from=None)

    # ------------------------------------------------------------------ storage
    def _allocate(self, capacity: int, copy_from: dict[str, NDArray[Any]] | None) -> None:
        arrays: dict[str, NDArray[Any]] = {}
        for name, dtype, parts in COLUMN_SPECS:
            shape: tuple[int, ...] = (capacity,) if len(parts) == 1 else (capacity, len(parts))
            # Optional columns start at their defaults: ``append`` writes them only when a
            # producer gives a value (the 1 kHz loop then pays nothing for them).
            a: NDArray[Any] = (np.full(shape, _DEFAULT_FILL[name], dtype=dtype)
                               if name in OPTIONAL_COLUMNS
                 else np.empty(shape, dtype=dtype))
            if copy_from is not None:
                a[: self._n] = copy_from[name][: self._n]
            arrays[name] = a
        self._arrays = arrays
        self._cap = capacity
        # bound attributes: one attribute lookup per column in the hot path
        self._k = arrays["k"]
        self._t = arrays["t"]
        self._x = arrays["x"]
        self._g = arrays["g"]
        self._gi = arrays["goal_index"]
        self._f = arrays["force"]
        self._ms = arrays["ms"]
        self._zoom = arrays["zoom"]
        self._pitch = arrays["audio_pitch"]
        self._period = arrays["audio_period"]
        self._volume = arrays["audio_volume"]
        self._contact = arrays["contact"]
        self._fc = arrays["f_contact"]
        self._tc = arrays["tau_contact"]
        self._delicate = arrays["delicate"]
        self._clutch = arrays["clutch"]
        self._in_view = arrays["in_view"]
        self._gain = arrays["gain"]

    def reserve(self, capacity: int) -> None:
        """Grows the buffer to hold at least ``capacity`` rows (call before a trial)."""
        if capacity > self._cap:
            self._allocate(int(capacity), copy_from=self._arrays)

    def _grow(self, needed: int) -> None:
        cap = self._cap
        while cap < needed:
            cap *= 2
        self._allocate(cap, copy_from=self._arrays)

    @property
    def capacity(self) -> int:
        """Rows the buffer holds before it next doubles."""
        return self._cap

    def __len__(self) -> int:
        return self._n

    def clear(self) -> None:
        """Forgets every row (keeps the capacity); arrays from earlier ``view(copy=False)``
        calls may then be overwritten."""
        for name in OPTIONAL_COLUMNS:  # back to the defaults append relies on
            self._arrays[name][: self._n] = _DEFAULT_FILL[name]
        self._n = 0

    # ------------------------------------------------------------------ writing
    def append(
        self,
        k: int,
        t: float,
        x: Sequence[float] | NDArray[np.float64],
        g: Sequence[float] | NDArray[np.float64],
        goal_index: int,
        force: Sequence[float] | NDArray[np.float64] | None = None,
        ms: Sequence[float] | NDArray[np.float64] | None = None,
        zoom: float = 1.0,
        pitch: float = 0.0,
        period: float = 0.0,
        volume: float = 0.0,
        contact: int = 0,
        f_contact: Sequence[float] | NDArray[np.float64] | None = None,
        tau_contact: Sequence[float] | NDArray[np.float64] | None = None,
        delicate: int = 0,
        clutch: int = 0,
        in_view: int = IN_VIEW_UNKNOWN,
        gain: float = 1.0,
    ) -> None:
        """Appends one sample (the hot path of the logging loop; no per-call allocation).

        **Decision** (issue #29 item 5): the eighteen columns stay parameters, not a frozen
        dataclass: the caller would build one object per sample, and that alone cost 54 %
        of an append (12.6 -> 19.4 us a sample with a seven-field dataclass of the cues,
        20,000 samples, median of 7, on the shared CI machine). ``extend`` mirrors these
        parameters column for column (as arrays), so that the two stay one list.

        Args:
            k: step index. t: time since trial start [s].
            x: (3,) TCP position [m]. g: (3,) goal point [m]. goal_index: goal point index.
            force: (3,) rendered force [N], ``None`` = zeros.
            ms: (3,) motion-scaling factors, ``None`` = ones.
            zoom: Mag magnification. pitch, period [s], volume: AG audio outputs.
            contact: tissue-contact flag (0/1).
            f_contact: (3,) tissue contact force [N], ``None`` = zeros.
            tau_contact: (3,) tissue contact torque [N m], ``None`` = zeros.
            delicate: contact with a delicate structure (0/1). clutch: clutch engaged (0/1).
            in_view: tool tip in the camera's field of view (1/0; -1 = not determined).
            gain: the fixture gain in force (1 = the schema as written).
        """
        i = self._n
        if i == self._cap:
            self._grow(i + 1)
        self._k[i] = k
        self._t[i] = t
        self._x[i] = x
        self._g[i] = g
        self._gi[i] = goal_index
        self._f[i] = 0.0 if force is None else force
        self._ms[i] = 1.0 if ms is None else ms
        self._zoom[i] = zoom
        self._pitch[i] = pitch
        self._period[i] = period
        self._volume[i] = volume
        self._contact[i] = contact
        # optional columns hold their defaults already (see _allocate and clear)
        if f_contact is not None:
            self._fc[i] = f_contact
        if tau_contact is not None:
            self._tc[i] = tau_contact
        if delicate:
            self._delicate[i] = delicate
        if clutch:
            self._clutch[i] = clutch
        if in_view != IN_VIEW_UNKNOWN:
            self._in_view[i] = in_view
        if gain != 1.0:
            self._gain[i] = gain
        self._n = i + 1

    def extend(
        self,
        k: ArrayLike,
        t: ArrayLike,
        x: ArrayLike,
        g: ArrayLike,
        goal_index: ArrayLike,
        force: ArrayLike | None = None,
        ms: ArrayLike | None = None,
        zoom: ArrayLike | None = None,
        audio_pitch: ArrayLike | None = None,
        audio_period: ArrayLike | None = None,
        audio_volume: ArrayLike | None = None,
        contact: ArrayLike | None = None,
        f_contact: ArrayLike | None = None,
        tau_contact: ArrayLike | None = None,
        delicate: ArrayLike | None = None,
        clutch: ArrayLike | None = None,
        in_view: ArrayLike | None = None,
        gain: ArrayLike | None = None,
    ) -> None:
        """Appends m samples at once (replays, simulated cohorts, tests).

        Args are the columns of ``append`` as arrays: scalars ``(m,)``, vectors ``(m, 3)``.
        A column left ``None`` takes its default (force 0, ms 1, zoom 1, audio 0,
        contact 0, contact force and torque 0, delicate 0, clutch 0, in_view -1, gain 1). Scalars
        broadcast.

        Raises:
            ValueError: if the columns do not share one length m or a vector is not (m, 3).
        """
        given = {"k": k, "t": t, "x": x, "g": g, "goal_index": goal_index, "force": force,
                 "ms": ms, "zoom": zoom, "audio_pitch": audio_pitch,
                 "audio_period": audio_period, "audio_volume": audio_volume,
                 "contact": contact, "f_contact": f_contact, "tau_contact": tau_contact,
                 "delicate": delicate, "clutch": clutch, "in_view": in_view,
                 "gain": gain}
        m = int(np.shape(k)[0]) if np.ndim(k) else 1
        cols: dict[str, NDArray[Any]] = {}
        for name, dtype, parts in COLUMN_SPECS:
            v = given[name]
            if v is None:
                v = _DEFAULT_FILL[name]
            shape = (m,) if len(parts) == 1 else (m, len(parts))
            a: NDArray[Any] = np.asarray(v, dtype=dtype)
            try:
                a = np.broadcast_to(a, shape)
            except ValueError:
                raise ValueError(
                    f"column {name!r} has shape {np.shape(v)}, expected {shape} "
                    f"(m = {m} from column 'k')"
                ) from None
            cols[name] = a
        n0 = self._n
        if n0 + m > self._cap:
            self._grow(n0 + m)
        for name, a in cols.items():
            self._arrays[name][n0 : n0 + m] = a
        self._n = n0 + m

    def set_column(self, name: str, values: ArrayLike) -> None:
        """Overwrites one column of every filled row (a producer that computes a column after
        the loop, e.g. the trial runner's ``in_view`` for a fixed camera).

        Args:
            name: a ``COLUMNS`` name. values: ``(n,)`` or ``(n, 3)`` like the column; scalars
                broadcast.

        Raises:
            ValueError: unknown column or a shape that does not broadcast to the column.
        """
        if name not in self._arrays:
            raise ValueError(f"unknown sample column {name!r} (known: {', '.join(COLUMNS)})")
        target = self._arrays[name][: self._n]
        try:
            target[...] = np.broadcast_to(np.asarray(values, dtype=target.dtype), target.shape)
        except ValueError:
            raise ValueError(f"column {name!r} has shape {target.shape}, got values of shape "
                             f"{np.shape(values)}") from None

    # ------------------------------------------------------------------ reading
    def view(self, copy: bool = False) -> dict[str, NDArray[Any]]:
        """Returns the filled part of every column, keyed by ``COLUMNS`` names.

        Args:
            copy: return independent copies; otherwise read-only views into the buffer
                (they stay valid, and unchanged, while appending continues; ``clear()``
                lets later appends overwrite them).

        Returns:
            dict: ``k (n,)``, ``t (n,)``, ``x (n, 3)``, ``g (n, 3)``, ``goal_index (n,)``,
            ``force (n, 3)``, ``ms (n, 3)``, ``zoom``, ``audio_pitch``, ``audio_period``,
            ``audio_volume`` ``(n,)``, ``contact (n,)``, ``f_contact (n, 3)``,
            ``tau_contact (n, 3)``, ``delicate``, ``clutch``, ``in_view``, ``gain`` ``(n,)``.
        """
        n = self._n
        out: dict[str, NDArray[Any]] = {}
        for name, a in self._arrays.items():
            v = a[:n]
            if copy:
                v = v.copy()
            else:
                v = v.view()
                v.flags.writeable = False
            out[name] = v
        return out

    def columns(self) -> dict[str, NDArray[Any]]:
        """Returns the filled part as flat 1-D columns keyed by ``FRAME_COLUMNS`` (views)."""
        n = self._n
        out: dict[str, NDArray[Any]] = {}
        for name, _, parts in COLUMN_SPECS:
            a = self._arrays[name][:n]
            if len(parts) == 1:
                out[parts[0]] = a
            else:
                for j, flat in enumerate(parts):
                    out[flat] = a[:, j]
        return out

    def to_frame(self) -> pd.DataFrame:
        """Returns a copy as a DataFrame with the flat ``FRAME_COLUMNS``, in order."""
        return pd.DataFrame({c: np.array(v) for c, v in self.columns().items()},
                            columns=list(FRAME_COLUMNS))

    def rows(self) -> Iterator[tuple[Any, ...]]:
        """Yields one tuple of Python scalars per sample, in ``FRAME_COLUMNS`` order.

        Rows for a tabular consumer (the store of schema version 5 and older handed them to
        ``executemany``; version 6 packs ``columns()`` instead); it converts column by column
        (``tolist``), which is far faster than converting row by row.
        """
        cols = [v.tolist() for v in self.columns().values()]
        return zip(*cols, strict=True)

    @classmethod
    def from_columns(
        cls, columns: Mapping[str, ArrayLike], *, active_fixtures: str = ""
    ) -> SampleBuffer:
        """Builds a buffer from flat columns (``FRAME_COLUMNS`` keys), e.g. a DataFrame.

        The ``OPTIONAL_COLUMNS`` may be absent (they take their defaults).

        Raises:
            ValueError: if a column is missing.
        """
        missing = [flat for name, _, parts in COLUMN_SPECS if name not in OPTIONAL_COLUMNS
                   for flat in parts if flat not in columns]
        if missing:
            raise ValueError(f"missing sample columns: {missing}")
        n = len(np.asarray(columns["k"]))
        buf = cls(capacity=max(n, 1), active_fixtures=active_fixtures)
        vec: dict[str, Any] = {}
        for name, _, parts in COLUMN_SPECS:
            if any(p not in columns for p in parts):
                vec[name] = None  # an optional column: its default
            elif len(parts) == 1:
                vec[name] = np.asarray(columns[parts[0]])
            else:
                vec[name] = np.column_stack([np.asarray(columns[p]) for p in parts]) if n else (
                    np.empty((0, len(parts))))
        buf.extend(**vec)
        return buf

    def __repr__(self) -> str:
        return (f"SampleBuffer(n={self._n}, capacity={self._cap}, "
                f"active_fixtures={self.active_fixtures!r})")
