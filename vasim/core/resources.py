"""Where vasim finds its data files (``protocols/``)."""

from __future__ import annotations

import os
from pathlib import Path

from vasim.core.errors import ConfigError


def protocols_dir() -> Path:
    """Returns the ``protocols/`` folder.

    ``$VASIM_PROTOCOLS`` wins; otherwise the folder beside the package (a clone installed with
    ``pip install -e .``, which is what ``make`` does).
    """
    env = os.environ.get("VASIM_PROTOCOLS")
    if env:
        p = Path(env)
    else:
        p = Path(__file__).resolve().parent.parent.parent / "protocols"
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


def scenes_dir() -> Path:
    return protocols_dir() / "scenes"


def available_files(folder: Path) -> tuple[str, ...]:
    """Names (stems) of the TOML files in ``folder``, sorted."""
    return tuple(sorted(p.stem for p in folder.glob("*.toml")))


def data_file(ref: str | Path, folder: Path, kind: str) -> Path:
    """The file a reference names: a path (with a folder or a ``.toml`` suffix), or the name
    of a file shipped in ``folder``.

    Raises:
        ConfigError: if a bare name matches no shipped file (the message lists them).
    """
    if isinstance(ref, Path) or "/" in ref or "\\" in ref or ref.endswith(".toml"):
        return Path(ref)
    path = folder / f"{ref}.toml"
    if not path.is_file():
        raise ConfigError(f"unknown {kind} {ref!r} (available: "
                          f"{', '.join(available_files(folder)) or 'none'})", field=kind)
    return path


def read_data_file(path: Path, kind: str) -> str:
    """The text of a data file; a missing or unreadable file is a ConfigError naming it."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{kind} file not found", file=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the {kind} file: {exc}", file=path) from exc
