"""Where vasim finds its data files (``protocols/``)."""

from __future__ import annotations

import os
from pathlib import Path

from vasim.errors import ConfigError


def protocols_dir() -> Path:
    """Returns the ``protocols/`` folder.

    ``$VASIM_PROTOCOLS`` wins; otherwise the folder beside the package (a clone installed with
    ``pip install -e .``, which is what ``make`` does).
    """
    env = os.environ.get("VASIM_PROTOCOLS")
    if env:
        p = Path(env)
    else:
        p = Path(__file__).resolve().parent.parent / "protocols"
    if not p.is_dir():
        raise ConfigError(
            f"protocols folder not found at {p} (set VASIM_PROTOCOLS to the folder holding "
            "schemas/ and studies/)"
        )
    return p


def schemas_dir() -> Path:
    return protocols_dir() / "schemas"


def studies_dir() -> Path:
    return protocols_dir() / "studies"
