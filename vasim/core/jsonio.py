"""Strict JSON out of numpy-laden values: NaN and ±inf become ``null``.

Python's ``json`` writes ``NaN`` and ``Infinity`` by default, which no JSON parser outside
Python accepts (``JSON.parse``, jq in strict mode, pandas with a strict engine).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from typing import Any

import numpy as np


def plain(v: Any) -> Any:
    """``v`` with numpy arrays and scalars turned into Python ones and every non-finite
    float into None.

    Example:
        >>> import numpy as np
        >>> plain({"ntt": float("inf"), "q": np.array([1.0, np.nan]), "n": np.int64(3)})
        {'ntt': None, 'q': [1.0, None], 'n': 3}
    """
    if isinstance(v, Mapping):
        return {str(k): plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    if isinstance(v, np.ndarray):
        return [plain(x) for x in v.tolist()]
    if isinstance(v, np.generic):
        v = v.item()
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def dumps(v: Any, **kwargs: Any) -> str:
    """Strict JSON text of ``v`` (see :func:`plain`).

    Example:
        >>> dumps({"ntt": float("inf")})
        '{"ntt": null}'
    """
    return json.dumps(plain(v), allow_nan=False, **kwargs)
