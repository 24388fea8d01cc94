"""Optional features and the pip extra each needs (issue #27 item 1).

The core install (``pip install vasim``) runs the simulator, trials, studies, reports and
MRCP. Two features need libraries that are large and serve nothing else, so they are extras:

==============  ==========================  ============================================
extra           brings                      for
==============  ==========================  ============================================
``cluster``     ``ray[client]``             ``vasim study power --address`` (a Ray
                                            cluster); without it power planning runs on
                                            a local process pool
``parquet``     ``pyarrow``                 ``vasim study export --format parquet``
``openhaptics`` ``pyopenhaptics``           a real Phantom Omni / Touch
==============  ==========================  ============================================

:func:`require` imports a module of an extra or raises :class:`MissingExtraError`, whose
message is one line naming the extra to install (the CLI prints it and exits with 2).
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from vasim.core.errors import VasimError

EXTRAS: dict[str, str] = {"ray": "cluster", "pyarrow": "parquet",
                          "pyopenhaptics": "openhaptics"}
"""Top-level module -> the extra that installs it."""


class MissingExtraError(VasimError, ImportError):
    """A feature needs an optional extra that is not installed.

    Args:
        module: the module that could not be imported. purpose: what needed it.
    """

    def __init__(self, module: str, purpose: str):
        top = module.split(".")[0]
        self.module = module
        self.extra = EXTRAS.get(top, top)
        super().__init__(f"{purpose} needs the '{self.extra}' extra ({top} is not "
                         f"installed): pip install 'vasim[{self.extra}]'")


def require(module: str, purpose: str) -> ModuleType:
    """Imports ``module`` of an optional extra.

    Args:
        module: e.g. ``"ray"`` or ``"pyarrow.parquet"``. purpose: what needs it, the start
            of the error message (e.g. ``"Parquet export"``).

    Raises:
        MissingExtraError: the module (or its package) is not installed.

    >>> require("json", "a doctest").__name__
    'json'
    >>> print(MissingExtraError("pyarrow.parquet", "export"))
    export needs the 'parquet' extra (pyarrow is not installed): pip install 'vasim[parquet]'
    """
    try:
        return importlib.import_module(module)
    except ImportError:
        # Only the absence of the extra's own package is "missing extra"; a broken
        # installation (a module inside it failing to import) stays the real error.
        if installed(module):
            raise
        raise MissingExtraError(module, purpose) from None


def installed(module: str) -> bool:
    """True when ``module``'s top-level package can be imported (without importing it).

    >>> installed("json"), installed("ray_not_installed_xyz")
    (True, False)
    """
    try:
        return importlib.util.find_spec(module.split(".")[0]) is not None
    except (ImportError, ValueError):
        return False


__all__ = ["EXTRAS", "MissingExtraError", "installed", "require"]
