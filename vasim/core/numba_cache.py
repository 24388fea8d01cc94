"""Where numba keeps vasim's compiled kernels, so a read-only install still runs.

The physics, contact and MRCP kernels are compiled with ``@njit(cache=True)``. numba caches
them in ``__pycache__`` beside the source, or, when that folder is read-only, in the
user-wide cache (``$XDG_CACHE_HOME/numba`` or ``~/.cache/numba``); when neither is writable
(a shared install with a read-only home, a container) it refuses to *import* the module:
``RuntimeError: cannot cache function ...: no locator available``, so every command failed,
``--version`` included.

:func:`configure_numba_cache` runs once when ``vasim`` is imported, before numba is: if
numba would find no writable place, it points ``NUMBA_CACHE_DIR`` at the first writable
folder of ``$XDG_CACHE_HOME/vasim/numba``, ``~/.cache/vasim/numba`` and
``<tempdir>/vasim-numba-<uid>`` and says so in one line on stderr when it had to use the
temporary folder (kernels are then recompiled after a reboot).

**Decision**: a user-set ``NUMBA_CACHE_DIR`` is respected when it is writable, or when
numba can fall back on its in-tree or user-wide cache. A user-set folder that is not
writable while the install and home are read-only too (issue #30 item 5: "RuntimeError:
cannot cache function" at import) is replaced by the first writable folder above, with one
line on stderr naming the user's folder and the one used. If no folder at all is writable
the import goes on and numba's own error names the kernel (nothing vasim could do would
cache; compiling without a cache needs the source changed).
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

_PACKAGE = Path(__file__).resolve().parent.parent
"""The installed ``vasim`` package folder (its sub-packages hold the kernels)."""


def writable_dir(path: Path) -> bool:
    """True if ``path`` exists or can be created and a file can be written in it (the same
    test numba's cache locators make)."""
    try:
        path.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryFile(dir=path):
            pass
    except OSError:
        return False
    return True


def _user_cache_root() -> Path:
    xdg = os.environ.get("XDG_CACHE_HOME")
    return Path(xdg) if xdg else Path.home() / ".cache"


def configure_numba_cache() -> Path | None:
    """Sets ``NUMBA_CACHE_DIR`` when numba would find no writable cache folder.

    Returns:
        The folder chosen, or None when nothing had to change (numba's in-tree or user-wide
        cache works, or ``NUMBA_CACHE_DIR`` is already set to a writable folder).
    """
    user_set = os.environ.get("NUMBA_CACHE_DIR")
    if user_set and writable_dir(Path(user_set)):
        return None
    if writable_dir(_PACKAGE / "abdomen" / "__pycache__"):
        return None
    try:
        root = _user_cache_root()
    except RuntimeError:  # no home directory at all
        root = None
    if root is not None and writable_dir(root / "numba"):
        return None
    candidates = [] if root is None else [root / "vasim" / "numba"]
    temp = Path(tempfile.gettempdir()) / f"vasim-numba-{os.getuid()}"
    for folder in [*candidates, temp]:
        if writable_dir(folder):
            os.environ["NUMBA_CACHE_DIR"] = str(folder)
            if user_set:
                print(f"vasim: NUMBA_CACHE_DIR={user_set} is not a writable folder (and the "
                      f"install and home folders are read-only); compiled kernels are cached "
                      f"in {folder}", file=sys.stderr)
            elif folder == temp:
                print(f"vasim: the install and home folders are read-only; compiled kernels "
                      f"are cached in {folder}", file=sys.stderr)
            return folder
    return None


__all__ = ["configure_numba_cache", "writable_dir"]
