"""Record a device stream and play it back exactly: the same trial, re-run deterministically.

:class:`StreamRecorder` stores every sample the servo loop read (``ServoLoop(record=True)``
fills one: ``loop.recording``), with its tick index, *before* the guard (a replay must
reproduce the bad samples too). :class:`ReplayDevice` returns recorded sample k at its
k-th ``read()``: a plant that is deterministic given its inputs then produces bit-identical
outputs (same samples -> same forces, same trial samples). Forces written to a replay
device are kept (``forces``) but move nothing.

Storage (**decision**): one numpy ``.npz`` file per recorded run, written next to the study
database by the store later (``stream_path(db, trial_id)`` names it
``<db stem>_trial<id>_device.npz`` in the database's folder) — the SQLite file keeps rows
and summaries, the bulky 1 kHz streams stay in compressed arrays. Format version 1:

==============  ==========  ======================================================
key             dtype       content
==============  ==========  ======================================================
``format``      str         ``"vasim.device_stream"``
``version``     int64       1
``meta``        str         JSON: ``device`` name, ``rate_hz``, ``limits``
                            (``DeviceLimits.to_dict()``), ``n`` samples
``tick``        int64 (n,)  servo tick index of each read
``t``           f8 (n,)     device time of the sample [s]
``position``    f8 (n, 3)   stylus position [m], device frame
``orientation`` f8 (n, 4)   stylus quaternion (w, x, y, z)
``buttons``     int64 (n,)  button bitmask
``valid``       bool (n,)   the device's valid flag
==============  ==========  ======================================================

Floats are stored as float64, unchanged: a saved and loaded stream is bit-identical.

Example:
    >>> import numpy as np
    >>> from vasim.haptics.device import OMNI_LIMITS, DeviceSample
    >>> rec = StreamRecorder("emulator", OMNI_LIMITS, rate_hz=1000.0)
    >>> for k in range(3):
    ...     rec.append(k, DeviceSample(t=k * 1e-3, position=np.full(3, k * 1e-4)))
    >>> dev = ReplayDevice(rec.stream())
    >>> dev.start()
    >>> [float(dev.read().position[0]) for _ in range(3)]
    [0.0, 0.0001, 0.0002]
    >>> dev.exhausted
    True
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import NDArray

from vasim.core.atomic import atomic_file
from vasim.core.errors import DeviceError
from vasim.haptics.device import DeviceLimits, DeviceSample, FloatArray, as_force

FORMAT = "vasim.device_stream"
VERSION = 1
_WIDTH = 11  # tick, t, position(3), orientation(4), buttons, valid


@dataclass(frozen=True, eq=False)
class DeviceStream:
    """A recorded device stream (module docstring for the fields)."""

    device: str
    rate_hz: float
    limits: DeviceLimits
    tick: NDArray[np.int64]
    t: FloatArray
    position: FloatArray
    orientation: FloatArray
    buttons: NDArray[np.int64]
    valid: NDArray[np.bool_]

    def __len__(self) -> int:
        return int(self.tick.size)

    def sample(self, i: int) -> DeviceSample:
        """The i-th recorded sample (fresh arrays)."""
        return DeviceSample(t=float(self.t[i]), position=self.position[i].copy(),
                            orientation=self.orientation[i].copy(),
                            buttons=int(self.buttons[i]), valid=bool(self.valid[i]))

    def save(self, path: str | Path) -> Path:
        """Writes the stream to ``path`` (.npz, compressed; the suffix is added if missing)
        atomically: a killed process leaves the previous file or the new one, never a
        truncated one. Returns the path written."""
        path = Path(path)
        if path.suffix != ".npz":
            path = path.with_name(path.name + ".npz")
        meta = {"device": self.device, "rate_hz": self.rate_hz,
                "limits": self.limits.to_dict(), "n": len(self)}
        with atomic_file(path) as fh:
            np.savez_compressed(fh, format=np.array(FORMAT), version=np.int64(VERSION),
                                meta=np.array(json.dumps(meta)), tick=self.tick, t=self.t,
                                position=self.position, orientation=self.orientation,
                                buttons=self.buttons, valid=self.valid)
        return path

    @classmethod
    def load(cls, path: str | Path) -> DeviceStream:
        """Reads a stream ``save`` wrote.

        Raises:
            DeviceError: if the file is missing, not a device stream, or of another version.
        """
        path = Path(path)
        try:
            with np.load(path, allow_pickle=False) as z:
                if str(z["format"]) != FORMAT:
                    raise DeviceError(f"{path}: not a vasim device stream "
                                      f"(format {str(z['format'])!r})")
                if int(z["version"]) != VERSION:
                    raise DeviceError(f"{path}: device stream version {int(z['version'])} is "
                                      f"not supported (expected {VERSION})")
                meta = json.loads(str(z["meta"]))
                return cls(device=str(meta["device"]), rate_hz=float(meta["rate_hz"]),
                           limits=DeviceLimits.from_dict(meta["limits"]),
                           tick=z["tick"].astype(np.int64), t=z["t"].astype(np.float64),
                           position=z["position"].astype(np.float64),
                           orientation=z["orientation"].astype(np.float64),
                           buttons=z["buttons"].astype(np.int64),
                           valid=z["valid"].astype(bool))
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise DeviceError(f"{path}: cannot read the device stream (truncated or not a "
                              f"stream): {exc}") from exc


def stream_path(db_path: str | Path, trial_id: int) -> Path:
    """Where the device stream of a trial lives: next to the study database.

    >>> stream_path("/data/study.sqlite", 7).as_posix()
    '/data/study_trial000007_device.npz'
    """
    db = Path(db_path)
    return db.with_name(f"{db.stem}_trial{int(trial_id):06d}_device.npz")


class StreamRecorder:
    """Appends every device sample with its tick index (preallocated chunks).

    Args:
        device_name: name of the recorded device.
        limits: its limits (a replay device reports the same).
        rate_hz: the servo rate of the recording [Hz].
        chunk: rows per chunk.
    """

    def __init__(self, device_name: str, limits: DeviceLimits, rate_hz: float,
                 chunk: int = 65_536):
        self.device_name = device_name
        self.limits = limits
        self.rate_hz = float(rate_hz)
        self._chunk = int(chunk)
        self._full: list[NDArray[np.float64]] = []
        self._cur = np.empty((self._chunk, _WIDTH))
        self._i = 0

    def append(self, tick: int, sample: DeviceSample) -> None:
        """Stores one sample read at servo tick ``tick``."""
        if self._i == self._chunk:
            self._full.append(self._cur)
            self._cur = np.empty((self._chunk, _WIDTH))
            self._i = 0
        row = self._cur[self._i]
        row[0] = tick
        row[1] = sample.t
        row[2:5] = sample.position
        row[5:9] = sample.orientation
        row[9] = sample.buttons
        row[10] = 1.0 if sample.valid else 0.0
        self._i += 1

    def __len__(self) -> int:
        return len(self._full) * self._chunk + self._i

    def stream(self) -> DeviceStream:
        """The samples recorded so far as a :class:`DeviceStream`."""
        a = np.concatenate([*self._full, self._cur[:self._i]])
        return DeviceStream(device=self.device_name, rate_hz=self.rate_hz, limits=self.limits,
                            tick=a[:, 0].astype(np.int64), t=a[:, 1].copy(),
                            position=a[:, 2:5].copy(), orientation=a[:, 5:9].copy(),
                            buttons=a[:, 9].astype(np.int64), valid=a[:, 10] != 0.0)

    def save(self, path: str | Path) -> Path:
        """``stream().save(path)``."""
        return self.stream().save(path)


class ReplayDevice:
    """Plays a recorded stream back, one sample per ``read()``.

    Args:
        stream: a ``DeviceStream`` or the path of a saved one.
        name: device name (default ``replay:<recorded device>``).

    Reading past the end raises ``DeviceError`` (the servo loop then stops cleanly).
    """

    def __init__(self, stream: DeviceStream | str | Path, *, name: str | None = None):
        self.stream = stream if isinstance(stream, DeviceStream) else DeviceStream.load(stream)
        self.name = name if name is not None else f"replay:{self.stream.device}"
        self.forces: list[FloatArray] = []
        self._i = 0
        self._started = False

    @property
    def limits(self) -> DeviceLimits:
        return self.stream.limits

    @property
    def exhausted(self) -> bool:
        """True once every sample was read."""
        return self._i >= len(self.stream)

    def start(self) -> None:
        self._started = True

    def stop(self) -> None:
        self._started = False

    def rewind(self) -> None:
        """Back to the first sample (forgets the written forces)."""
        self._i = 0
        self.forces = []

    def read(self) -> DeviceSample:
        if not self._started:
            raise DeviceError(f"{self.name}: read() before start()")
        if self._i >= len(self.stream):
            raise DeviceError(f"{self.name}: end of the recording ({len(self.stream)} samples)")
        s = self.stream.sample(self._i)
        self._i += 1
        return s

    def write_force(self, force: FloatArray) -> None:
        self.forces.append(as_force(force))


__all__ = ["FORMAT", "VERSION", "DeviceStream", "ReplayDevice", "StreamRecorder", "stream_path"]
