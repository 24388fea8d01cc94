"""Where vasim finds its data files (``protocols/``: schemas, studies, scenes, robots).

Three kinds of folder hold them, searched in this order for a file given by bare name:

1. ``$VASIM_PROTOCOLS`` (if set): a folder laid out like ``protocols/``;
2. the user's folder ``$XDG_CONFIG_HOME/vasim/protocols`` (``~/.config/vasim/protocols`` when
   ``XDG_CONFIG_HOME`` is unset), if it exists;
3. the shipped files: the ``protocols/`` folder at the top of a source checkout, or the
   ``vasim.protocols`` package data of an installed wheel, found through
   :mod:`importlib.resources`.

**Decision**: the two user folders *overlay* the shipped files name by name (a user's
``studies/vf_learning_curve.toml`` replaces the shipped one, the other shipped files stay
visible) rather than replacing the whole folder, because a user adding one schema should not
have to copy every shipped protocol. **Decision**: the user folder follows the XDG base
directory convention (``~/.config``), because that is where Linux tools keep per-user
configuration and it honours a relocated ``$XDG_CONFIG_HOME``.
"""

from __future__ import annotations

import os
from importlib import resources
from pathlib import Path

from vasim.core.errors import ConfigError

#: The sub-folders of a protocols folder (one per kind of data file).
SUBFOLDERS = ("schemas", "studies", "scenes", "robots")


def _checkout_protocols() -> Path | None:
    """The ``protocols/`` folder of the source checkout vasim is imported from, if any."""
    top = Path(__file__).resolve().parent.parent.parent
    candidate = top / "protocols"
    if (top / "pyproject.toml").is_file() and (candidate / "studies").is_dir():
        return candidate
    return None


def shipped_protocols_dir() -> Path:
    """The folder of the data files shipped with vasim.

    **Decision**: a source checkout's own ``protocols/`` (beside the ``vasim`` package, as in
    ``make install``'s editable install or ``PYTHONPATH=<checkout>``) wins over the
    ``vasim.protocols`` package, because an editable install of *another* checkout in the
    same virtualenv would otherwise serve that checkout's files to this one's code.

    Raises:
        ConfigError: if neither a checkout folder nor the installed package data is found.
    """
    checkout = _checkout_protocols()
    if checkout is not None:
        return checkout
    try:
        root = resources.files("vasim.protocols")
    except ModuleNotFoundError:
        root = None
    if isinstance(root, Path) and root.is_dir():
        return root
    raise ConfigError(
        "protocols folder not found: vasim is neither run from a source checkout holding "
        "protocols/ nor installed with its vasim.protocols package data (set VASIM_PROTOCOLS "
        "to the folder holding schemas/ and studies/)"
    )


def user_protocols_dir() -> Path:
    """The per-user folder searched before the shipped files (it need not exist)."""
    config = os.environ.get("XDG_CONFIG_HOME") or str(Path.home() / ".config")
    return Path(config) / "vasim" / "protocols"


def override_dirs() -> tuple[Path, ...]:
    """The folders searched before the shipped files, first first: ``$VASIM_PROTOCOLS``, then
    the user folder (only if it exists).

    Raises:
        ConfigError: if ``$VASIM_PROTOCOLS`` is set but is not a folder.
    """
    out: list[Path] = []
    env = os.environ.get("VASIM_PROTOCOLS")
    if env:
        p = Path(env).expanduser()
        if not p.is_dir():
            raise ConfigError(
                f"protocols folder not found at {p} (VASIM_PROTOCOLS must name a folder "
                "holding schemas/, studies/, scenes/ or robots/)",
                field="VASIM_PROTOCOLS",
            )
        out.append(p)
    user = user_protocols_dir()
    if user.is_dir():
        out.append(user)
    return tuple(out)


def protocols_dir() -> Path:
    """The shipped ``protocols/`` folder (see :func:`shipped_protocols_dir`)."""
    return shipped_protocols_dir()


def schemas_dir() -> Path:
    """The shipped ``protocols/schemas`` folder (fixture schemas)."""
    return protocols_dir() / "schemas"


def studies_dir() -> Path:
    """The shipped ``protocols/studies`` folder (study protocols)."""
    return protocols_dir() / "studies"


def scenes_dir() -> Path:
    """The shipped ``protocols/scenes`` folder (abdomen scenes)."""
    return protocols_dir() / "scenes"


def search_dirs(folder: Path) -> tuple[Path, ...]:
    """The folders searched for a bare name in ``folder``, first first.

    For a shipped sub-folder (``schemas_dir()``, ``studies_dir()``, ...) these are the
    same-named sub-folders of :func:`override_dirs` that exist, then ``folder``; any other
    folder is searched alone.
    """
    shipped = protocols_dir()
    if folder.parent != shipped or folder.name not in SUBFOLDERS:
        return (folder,)
    overrides = tuple(d / folder.name for d in override_dirs() if (d / folder.name).is_dir())
    return (*overrides, folder)


def available_files(folder: Path) -> tuple[str, ...]:
    """Names (stems) of the TOML files in ``folder`` and its overrides (see
    :func:`search_dirs`), sorted and without duplicates."""
    return tuple(sorted({p.stem for d in search_dirs(folder) for p in d.glob("*.toml")}))


def data_file(ref: str | Path, folder: Path, kind: str) -> Path:
    """The file a reference names: a path (with a folder or a ``.toml`` suffix), or the name
    of a file in ``folder`` or one of its overrides (see :func:`search_dirs`; the first match
    wins).

    Raises:
        ConfigError: if a bare name matches no file (the message lists the available names).
    """
    if isinstance(ref, Path) or "/" in ref or "\\" in ref or ref.endswith(".toml"):
        return Path(ref)
    for d in search_dirs(folder):
        path = d / f"{ref}.toml"
        if path.is_file():
            return path
    raise ConfigError(f"unknown {kind} {ref!r} (available: "
                      f"{', '.join(available_files(folder)) or 'none'})", field=kind)


def read_data_file(path: Path, kind: str) -> str:
    """The text of a data file; a missing or unreadable file is a ConfigError naming it."""
    try:
        return path.read_text(encoding="utf-8")
    except FileNotFoundError:
        raise ConfigError(f"{kind} file not found", file=path) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise ConfigError(f"cannot read the {kind} file: {exc}", file=path) from exc
