"""Outputs that are either complete or absent: files and folders written atomically.

A process killed while writing an export, a report or a recording must never leave a
truncated file beside a manifest that vouches for it. Two tools:

* :func:`atomic_file` — one file: written under a temporary name in the same folder,
  flushed and ``fsync``-ed, then renamed over the target (``os.replace`` is atomic on POSIX
  and Windows), and the folder entry synced.
* :func:`atomic_folder` — a set of files (an export, a report): written into a temporary
  sibling folder, then swapped with the target folder in one step. On Linux the swap is
  ``renameat2(RENAME_EXCHANGE)``, so at every instant the target path holds either the old
  complete set or the new complete set; elsewhere two renames leave a window of microseconds
  in which the target is absent (never mixed). The old set is deleted after the swap;
  leftovers of a killed run (``.<name>.tmp-*`` / ``.<name>.old-*``) are removed by the next
  run.

**Decision**: files in the target folder that the writer does not own (its ``owned`` test
says which are its own) are carried into the new folder before the swap — hard-linked,
which is instant and takes no space, or copied where links are impossible — so swapping
the folder never deletes anything a user put there.

**Decisions** (issue #30 items 6 and 8): the new folder gets the permission bits of the
folder it replaces (a first export: those ``mkdir`` gives under the umask), not the 0700 of
a temporary folder; and a file-system error while writing (a full disk, a read-only
folder, a path under a file) is re-raised as an ``OSError`` naming the user's folder, not
the internal ``.<name>.tmp-*`` one, with what to check.
"""

from __future__ import annotations

import contextlib
import ctypes
import ctypes.util
import os
import shutil
import sys
import tempfile
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import IO, Any

from vasim.core.config import check_dir_path
from vasim.core.errors import ConfigError

_RENAME_EXCHANGE = 2
"""``renameat2`` flag: swap two existing paths atomically (Linux >= 3.15)."""
_AT_FDCWD = -100


def _fsync_dir(folder: Path) -> None:
    if sys.platform.startswith("win"):
        return
    fd = os.open(folder, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextlib.contextmanager
def atomic_file(path: str | os.PathLike[str], mode: str = "wb",
                **open_kwargs: Any) -> Iterator[IO[Any]]:
    """Opens a temporary file that replaces ``path`` when the block ends without error.

    Example:
        >>> import tempfile, pathlib
        >>> d = pathlib.Path(tempfile.mkdtemp())
        >>> with atomic_file(d / "a.txt", "w") as fh:
        ...     _ = fh.write("complete")
        >>> (d / "a.txt").read_text()
        'complete'
    """
    target = Path(path)
    if "w" not in mode and "x" not in mode:
        raise ValueError(f"atomic_file writes a new file: mode {mode!r} has no 'w'")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.tmp-", dir=target.parent)
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        with open(tmp, mode.replace("x", "w"), **open_kwargs) as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, target)
        _fsync_dir(target.parent)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def _libc_renameat2() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6", use_errno=True)
        fn = libc.renameat2
    except (OSError, AttributeError):
        return None
    fn.argtypes = [ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p,
                   ctypes.c_uint]
    fn.restype = ctypes.c_int
    return fn  # a ctypes function pointer


def exchange(a: Path, b: Path) -> bool:
    """Swaps two existing paths in one atomic step; False where the system cannot."""
    fn = _libc_renameat2()
    if fn is None:
        return False
    if fn(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE) == 0:
        return True
    err = ctypes.get_errno()
    if err in (22, 38, 95):  # EINVAL, ENOSYS, EOPNOTSUPP: the file system cannot
        return False
    raise OSError(err, os.strerror(err), str(a))


def _remove_leftovers(target: Path) -> None:
    for stale in target.parent.glob(f".{target.name}.*-*"):
        if stale.is_dir() and (".tmp-" in stale.name or ".old-" in stale.name):
            shutil.rmtree(stale, ignore_errors=True)


@contextlib.contextmanager
def atomic_folder(target: str | os.PathLike[str], *,
                  owned: Callable[[Path], bool], what: str = "output") -> Iterator[Path]:
    """Yields an empty temporary folder that becomes ``target`` when the block succeeds.

    Args:
        target: the folder to (re)write.
        owned: tells whether a path inside an existing ``target`` (relative to it) was
            written by this writer (replaced); any other file is carried over.
        what: what is written, for messages (``"export"``, ``"report"``).

    Raises:
        ConfigError: ``target`` is a file.
    """
    out = Path(target)
    check_dir_path(out, "--out", what=f"the {what} folder (a folder, not a file)",
                   error=ConfigError)
    blocker = next((a for a in out.parents if a.exists() and not a.is_dir()), None)
    if blocker is not None:
        raise ConfigError(f"the {what} folder {out} cannot be made: {blocker} is a file, not "
                          "a folder; name a folder", field="--out")
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        _remove_leftovers(out)
        foreign = [] if not out.is_dir() else sorted(
            p.relative_to(out) for p in out.rglob("*")
            if (p.is_file() or p.is_symlink()) and not owned(p.relative_to(out)))
        tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.tmp-", dir=out.parent))
    except OSError as exc:
        raise _named(exc, out, what) from exc
    try:
        os.chmod(tmp, _folder_mode(out))
    except OSError:
        pass    # a file system without modes: the temporary folder's are kept
    try:
        yield tmp
        for rel in foreign:  # the user's files survive the swap
            dst = tmp / rel
            if dst.exists():
                raise ConfigError(f"the {what} would overwrite {out / rel}, which it did not "
                                  "write; move that file away", field="--out")
            dst.parent.mkdir(parents=True, exist_ok=True)
            try:
                os.link(out / rel, dst, follow_symlinks=False)
            except OSError:
                shutil.copy2(out / rel, dst, follow_symlinks=False)
        for p in sorted(tmp.rglob("*"), reverse=True):
            if p.is_file():
                with open(p, "rb") as fh:
                    os.fsync(fh.fileno())
        _fsync_dir(tmp)
        if out.is_dir():
            if exchange(tmp, out):
                shutil.rmtree(tmp, ignore_errors=True)  # now the old set
            else:
                old = out.parent / f".{out.name}.old-{os.getpid()}"
                os.replace(out, old)
                os.replace(tmp, out)
                shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(tmp, out)
        _fsync_dir(out.parent)
    except OSError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise _named(exc, out, what) from exc
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise


def _folder_mode(out: Path) -> int:
    """The permission bits the written folder gets: the existing folder's, else those of
    a new folder under the current umask."""
    if out.is_dir():
        return out.stat().st_mode & 0o7777
    mask = os.umask(0)
    os.umask(mask)
    return 0o777 & ~mask


def _named(exc: OSError, out: Path, what: str) -> OSError:
    """``exc`` re-worded for the user: the path is their folder ``out`` (not the internal
    temporary one), with a hint for a full disk or a folder without write permission."""
    import errno

    reason = exc.strerror or str(exc)
    if exc.errno == errno.ENOSPC or exc.errno == errno.EDQUOT:
        reason += f" (the {what} needs room for a complete new copy beside the old one)"
    elif exc.errno in (errno.EACCES, errno.EPERM, errno.EROFS):
        reason += (f" (the {what} writes a new folder in {out.parent} and swaps it in: that "
                   "folder must be writable)")
    new = OSError(exc.errno, reason, str(out))
    return new


__all__ = ["atomic_file", "atomic_folder", "exchange"]
