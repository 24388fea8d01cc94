"""Recording and the recording's files: what a replay of a real-time trial needs.

With ``record=True`` the loop keeps every raw device reading (``StreamRecorder``) and the
physics keeps a :class:`PhysicsLog`: the tool pose each physics step used and, per control
step, which snapshot the runner took. Stored trials keep two files next to the database:
the device stream (``stream_path``) and ``<db stem>_trial<id>_realtime.npz`` (physics log +
loop settings, :func:`realtime_path`); the trial names them (:func:`recorded_files`).
"""

from __future__ import annotations

import json
import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
from numpy.typing import NDArray

from vasim.abdomen.contact import ToolPose
from vasim.core.atomic import atomic_file
from vasim.core.errors import DeviceError
from vasim.haptics.devices.replay import DeviceStream, stream_path
from vasim.trials.sink import TrialSource

REALTIME_FORMAT = "vasim.realtime_recording"
REALTIME_VERSION = 1


def realtime_path(db_path: str | Path, trial_id: int) -> Path:
    """Where the physics log and loop settings of a stored real-time trial live.

    >>> realtime_path("/data/study.sqlite", 7).as_posix()
    '/data/study_trial000007_realtime.npz'
    """
    db = Path(db_path)
    return db.with_name(f"{db.stem}_trial{int(trial_id):06d}_realtime.npz")



class PhysicsLog:
    """What the physics did in a run, enough to re-run it exactly.

    Attributes (lists while recording; ``arrays()`` packs them):
        poses: per physics step s = 1, 2, ..., the tool pose it used, as 6 floats
            (tip, fulcrum) [m], or None (no tool).
        applied: (k, s) pairs: control step k took snapshot s.
    """

    def __init__(self, poses: list[tuple[float, ...] | None] | None = None,
                 applied: list[tuple[int, int]] | None = None):
        self.poses: list[tuple[float, ...] | None] = poses if poses is not None else []
        self.applied: list[tuple[int, int]] = applied if applied is not None else []

    @property
    def n_steps(self) -> int:
        return len(self.poses)

    def add_step(self, pose: ToolPose | None) -> None:
        self.poses.append(None if pose is None else
                          (*np.asarray(pose.tip, dtype=np.float64).tolist(),
                           *np.asarray(pose.fulcrum, dtype=np.float64).tolist()))

    def pose(self, s: int) -> ToolPose | None:
        """The tool pose physics step s (1-based) used."""
        p = self.poses[s - 1]
        return None if p is None else ToolPose(fulcrum=np.array(p[3:6]), tip=np.array(p[0:3]))

    def arrays(self) -> dict[str, NDArray[Any]]:
        """``pose`` (n, 6) float64 (NaN rows: no tool) and ``applied`` (m, 2) int64."""
        pose = np.full((len(self.poses), 6), np.nan)
        for i, p in enumerate(self.poses):
            if p is not None:
                pose[i] = p
        applied = np.array(self.applied, dtype=np.int64).reshape(-1, 2)
        return {"pose": pose, "applied": applied}

    @classmethod
    def from_arrays(cls, pose: NDArray[Any], applied: NDArray[Any]) -> PhysicsLog:
        poses: list[tuple[float, ...] | None] = [
            None if np.isnan(row).all() else tuple(float(v) for v in row)
            for row in np.asarray(pose, dtype=np.float64).reshape(-1, 6)]
        pairs = [(int(k), int(s)) for k, s in np.asarray(applied, dtype=np.int64).reshape(-1, 2)]
        return cls(poses, pairs)



@dataclass(frozen=True, eq=False)
class RealtimeRecording:
    """What a replay needs: the device stream, the physics log (None without physics
    thread or inline physics) and the loop's settings (``meta``)."""

    stream: DeviceStream
    physics: PhysicsLog | None
    meta: dict[str, Any]

    def save(self, db_path: str | Path, trial_id: int) -> tuple[Path, Path]:
        """Writes ``stream_path`` and ``realtime_path`` next to the database."""
        p_dev = self.stream.save(stream_path(db_path, trial_id))
        arrays = (self.physics.arrays() if self.physics is not None
                  else {"pose": np.zeros((0, 6)), "applied": np.zeros((0, 2), np.int64)})
        p_rt = realtime_path(db_path, trial_id)
        with atomic_file(p_rt) as fh:  # complete or absent, like every output
            np.savez_compressed(fh, format=np.array(REALTIME_FORMAT),
                                version=np.int64(REALTIME_VERSION),
                                meta=np.array(json.dumps(
                                    {**self.meta, "has_physics": self.physics is not None})),
                                **arrays)
        return p_dev, p_rt

    @classmethod
    def load(cls, db_path: str | Path, trial_id: int) -> RealtimeRecording:
        """Reads what ``save`` wrote.

        Raises:
            DeviceError: a file is missing or not a recording of this format.
        """
        p_rt = realtime_path(db_path, trial_id)
        p_dev = stream_path(db_path, trial_id)
        for p in (p_dev, p_rt):
            if not p.exists():
                raise DeviceError(f"trial {trial_id} has no real-time recording: {p} is "
                                  "missing (only trials run with --realtime are recorded)")
        stream = DeviceStream.load(p_dev)
        try:
            with np.load(p_rt, allow_pickle=False) as z:
                if str(z["format"]) != REALTIME_FORMAT:
                    raise DeviceError(f"{p_rt}: not a vasim real-time recording")
                if int(z["version"]) != REALTIME_VERSION:
                    raise DeviceError(f"{p_rt}: recording version {int(z['version'])} is not "
                                      f"supported (expected {REALTIME_VERSION})")
                meta = json.loads(str(z["meta"]))
                plog = (PhysicsLog.from_arrays(z["pose"], z["applied"])
                        if meta.get("has_physics") else None)
        except (OSError, KeyError, ValueError, EOFError, zipfile.BadZipFile) as exc:
            raise DeviceError(f"{p_rt}: cannot read the recording (truncated or not a "
                              f"recording): {exc}") from exc
        return cls(stream, plog, meta)


# ---------------------------------------------------------------------------------------


def recorded_files(store: TrialSource, row: dict[str, Any]) -> dict[str, str] | None:
    """The recording files a stored trial names: ``timing["recording"]`` of a completed
    trial, the ``recording`` event of an interrupted one; None when it names none.

    **Decision**: a replay needs the trial to say it was recorded, not only files next to
    the database (a database re-created under the same name must not pick up another run's
    recording); the files are looked up by the database's current name, so a database
    renamed or copied together with its recordings still replays.
    """
    timing = row.get("timing") or {}
    if timing.get("recording"):
        return dict(timing["recording"])
    ev = store.events(int(row["id"]))
    for detail in ev.loc[ev["kind"] == "recording", "detail"][::-1]:
        try:
            files = json.loads(detail)
        except (TypeError, ValueError):
            continue
        if files:
            return dict(files)
    return None


__all__ = ["REALTIME_FORMAT", "REALTIME_VERSION", "PhysicsLog", "RealtimeRecording",
           "realtime_path", "recorded_files"]
