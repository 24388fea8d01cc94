"""One array type per argument of a compiled kernel, so that numba compiles each kernel once.

numba compiles a kernel for the types of the arguments it is called with, and a read-only
array is another type than a writable one (as is another dtype or memory layout). A kernel
called from Python once with a robot's read-only limits and once with a writable copy of
them was compiled twice, each time 2-20 s of CPU: numba's cache index after one clean-clone
``make test`` held 21 such extra compilations (issue #31), each paid again by every process
that needed it before another had cached it (the parallel test workers, the CLI
subprocesses the tests start) and by a user's first run of each path.

Each call site of a kernel says what an argument is to the kernel:

* :func:`readonly_c` -- a constant the kernel only reads and the caller keeps (a robot's
  DH table and limits, an organ's faces and masses): the array itself when it already is a
  read-only C-contiguous array of the dtype, else a read-only *view* (nothing is copied
  unless the dtype or layout has to change; the caller's array stays writable);
* :func:`writable_c` -- state the call works on or hands back (a configuration, node
  positions, a target): the array itself when it is a writable C-contiguous array of the
  dtype, else a copy (a read-only input, e.g. a snapshot's frozen array, is copied: these
  are small or rare).

Neither changes a value: the kernel computes the same numbers whichever type it is
compiled for.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, DTypeLike, NDArray


def readonly_c(a: ArrayLike, dtype: DTypeLike = np.float64) -> NDArray[Any]:
    """``a`` as a read-only C-contiguous array of ``dtype`` (a view, never a copy of an
    array that already has the dtype and layout).

    >>> x = np.arange(3.0)
    >>> r = readonly_c(x)
    >>> r.flags.writeable, x.flags.writeable, np.shares_memory(r, x)
    (False, True, True)
    >>> readonly_c(r) is r
    True
    """
    if (type(a) is np.ndarray and a.dtype == dtype and a.flags.c_contiguous
            and not a.flags.writeable):
        return a
    out = np.ascontiguousarray(a, dtype=dtype).view(np.ndarray)
    out.flags.writeable = False
    return out


def writable_c(a: ArrayLike, dtype: DTypeLike = np.float64) -> NDArray[Any]:
    """``a`` as a writable C-contiguous array of ``dtype``: ``a`` itself when it is one,
    else a copy.

    >>> x = np.arange(3.0)
    >>> writable_c(x) is x
    True
    >>> x.flags.writeable = False
    >>> w = writable_c(x)
    >>> w.flags.writeable, np.shares_memory(w, x)
    (True, False)
    """
    if (type(a) is np.ndarray and a.dtype == dtype and a.flags.c_contiguous
            and a.flags.writeable):
        return a
    return np.array(a, dtype=dtype, order="C")


__all__ = ["readonly_c", "writable_c"]
