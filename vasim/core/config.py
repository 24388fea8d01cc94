"""The one toolkit every TOML loader and config object validates with (schemas, protocols,
scenes, robots, the frozen config dataclasses of every layer).

Every check raises :class:`vasim.core.errors.ConfigError` (or, with ``error=``, an
:class:`~vasim.core.errors.InputError`) with the same words::

    protocols/schemas/ff.toml: field 'fixtures.ff.max_force_n': got 1000.0, expected a
    number in [0, 3.3] N (the Phantom Omni's peak force, 3.3 N (Geomagic spec))

that is ``<file>: field '<dotted.path>': got <value>, expected <what>``. Unknown keys read
``got unknown field (value ...), expected one of a, b, c``. Values are echoed with ``repr``
truncated to :data:`vasim.core.bounds.MAX_MESSAGE_CHARS` characters.

**Decision**: a small module of plain functions over the existing frozen dataclasses rather
than msgspec/pydantic models, because the dataclasses (and their ``__post_init__`` checks)
are the public types every layer already uses, and a second model layer would duplicate
them; the functions are what the five former toolkits had in common, worded once.

**Validating a config field** (issue #29 item 3: one route). Every field check goes through
a helper here: the scalar checks (:func:`check_number`, :func:`check_int`,
:func:`check_bool`, :func:`check_str`, :func:`check_choice`), vectors and arrays
(:func:`check_vec3`, :func:`check_array`), nested objects (:func:`check_type`), tables
(:func:`check_table`, :func:`check_keys`, :func:`check_required`,
:func:`check_array_of_tables`), paths (:func:`check_file`, :func:`check_dir`,
:func:`check_dir_path`, :func:`check_not_dir`) and, for any other rule (a relation between
fields), :func:`expect` ``(ok, value, expected, field=...)``. A number's plausible range is
a :class:`~vasim.core.bounds.Bound` of :mod:`vasim.core.bounds` (the bounds table). A
``__post_init__`` calls helpers rather than spelling ``if ...: raise ConfigError(...)``;
:func:`fail` builds the error for the few raises no helper expresses, :func:`rewrap` puts a
nested object's error under its parent's field and file. The TOML of every file is parsed
by :func:`parse_toml` (nothing else imports ``tomllib``).

**Config or input** (``error=``): a field of a config file or config object raises
:class:`~vasim.core.errors.ConfigError` (the default); a command-line argument or a value of
an input data file (answers) raises :class:`~vasim.core.errors.InputError`: every helper
takes ``error=InputError``; path helpers default to it. Both are a
:class:`~vasim.core.errors.FieldError`, which the command line prints as one line (exit 2).

**Decision**: a UTF-8 byte-order mark at the start of a TOML text is stripped (editors on
Windows write one; ``tomllib`` would report "invalid statement at line 1").

**Decision** (issue #30 item 5): :func:`parse_toml` is the one place TOML is parsed, and it
refuses arrays and inline tables nested more than :data:`MAX_TOML_NESTING` levels deep before
``tomllib`` sees them (``tomllib`` recurses once per level and raised ``RecursionError`` at
about 500 levels in every loader: schemas, protocols, scenes, robots, ``--effects``, answer
files). No shipped or sensible file nests more than 4 levels; a ``RecursionError`` that
still escapes ``tomllib`` is reported the same way.
"""

from __future__ import annotations

import math
import tomllib
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any, TypeVar

import numpy as np
from numpy.typing import NDArray

from vasim.core.bounds import MAX_MESSAGE_CHARS, Bound
from vasim.core.errors import ConfigError, FieldError, InputError

BOM = "\ufeff"

T = TypeVar("T")

MAX_TOML_NESTING = 64
"""Deepest nesting of arrays / inline tables :func:`parse_toml` accepts (shipped files: 4)."""


def show(value: object, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``repr(value)`` cut to ``limit`` characters (with the full length noted)."""
    try:
        text = repr(value)
    except Exception:  # a broken __repr__ must not hide the real error
        text = f"<{type(value).__name__}>"
    if len(text) > limit:
        size = len(value) if isinstance(value, str | bytes | list | tuple | dict) else len(text)
        unit = "characters" if isinstance(value, str | bytes) else "items" if isinstance(
            value, list | tuple | dict) else "characters shown"
        text = f"{text[:limit]}... ({size:,} {unit})"
    return text


def fail(value: object, expected: str, *, field: str | None = None,
         file: str | Path | None = None, error: type[FieldError] = ConfigError,
         ) -> FieldError:
    """The standard error: ``got <value>, expected <expected>`` at ``file``/``field``
    (a :class:`ConfigError`, or ``error``: :class:`InputError` for a command-line argument
    or an input data value)."""
    return error(f"got {show(value)}, expected {expected}", file=file, field=field)


def expect(ok: object, value: object, expected: str, *, field: str | None = None,
            file: str | Path | None = None, error: type[FieldError] = ConfigError) -> None:
    """Raises :func:`fail` ``(value, expected)`` unless ``ok``: the one-line form of a check
    no other helper covers (a relation between fields: ``lower < upper``, a count that must
    match another field's).

    >>> expect(1 < 2, 1, "less than 2", field="lo")
    >>> expect(3 < 2, 3, "less than upper (2)", field="lo")
    Traceback (most recent call last):
    ...
    vasim.core.errors.ConfigError: field 'lo': got 3, expected less than upper (2)
    """
    if not ok:
        raise fail(value, expected, field=field, file=file, error=error)


def join(*parts: str | None) -> str:
    """Dotted path of the non-empty parts (``join("fixtures", "ff", "k")``)."""
    return ".".join(p for p in parts if p)


def rewrap(exc: FieldError, prefix: str | None = None, file: str | Path | None = None, *,
           error: type[FieldError] | None = None) -> FieldError:
    """``exc`` with its field under ``prefix`` and ``file`` named (unless it names one), of
    the same class (or ``error``: an :class:`InputError` when a config check was applied to
    input data)."""
    return (error or type(exc))(exc.reason, file=exc.file or file,
                                field=join(prefix, exc.field) or None)


# -- TOML --------------------------------------------------------------------------------
def parse_toml(text: object, *, file: str | Path | None = None, kind: str = "TOML",
               ) -> dict[str, Any]:
    """Parses TOML text (a leading BOM is stripped); errors name ``file``.

    Raises:
        ConfigError: not a string, or invalid TOML (tomllib's message, with line/column).
    """
    if not isinstance(text, str):
        raise ConfigError(f"{kind} text must be a string, got {type(text).__name__}", file=file)
    if text.startswith(BOM):
        text = text[len(BOM):]
    depth, line = toml_nesting(text)
    if depth > MAX_TOML_NESTING:
        raise ConfigError(f"invalid {kind}: arrays or inline tables nested {depth} levels deep "
                          f"at line {line}, expected at most {MAX_TOML_NESTING}", file=file)
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(f"invalid TOML: {exc}", file=file) from exc
    except RecursionError:
        raise ConfigError(f"invalid {kind}: nested too deeply for the TOML reader, expected "
                          f"at most {MAX_TOML_NESTING} levels of arrays or inline tables",
                          file=file) from None


def toml_nesting(text: str) -> tuple[int, int]:
    r"""The deepest nesting of ``[``/``{`` in value position of a TOML text and the line
    (1-based) where it is first reached; brackets inside strings and comments are skipped,
    and table headers (``[a]``, ``[[a]]`` at the start of a line) count nothing. A linear
    scan without recursion: it only decides whether ``tomllib`` may be trusted with the
    text (an unbalanced text is left to ``tomllib``'s own error).

    >>> toml_nesting('a = [[1, 2], {b = "[[["}]  # [[[\n[[t]]\nc = 1')
    (2, 1)
    """
    depth = best = 0
    line = best_line = 1
    i, n = 0, len(text)
    at_line_start = True
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            at_line_start = True
            i += 1
            continue
        if c in " \t\r":
            i += 1
            continue
        if c == "#":
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        if c == "[" and at_line_start and depth == 0:   # a table header: skip the line's key
            j = text.find("\n", i)
            i = n if j < 0 else j
            continue
        at_line_start = False
        if c in "\"'":
            triple = text.startswith(c * 3, i)
            quote = c * 3 if triple else c
            j = i + len(quote)
            while j < n:
                if c == '"' and text[j] == "\\":
                    j += 2
                    continue
                if text.startswith(quote, j):
                    break
                if not triple and text[j] == "\n":
                    break
                j += 1
            line += text.count("\n", i, j)
            i = j + len(quote)
            continue
        if c in "[{":
            depth += 1
            if depth > best:
                best, best_line = depth, line
        elif c in "]}":
            depth = max(0, depth - 1)
        i += 1
    return best, best_line


def check_table(value: object, field: str | None = None, *, file: str | Path | None = None,
                what: str = "a table", error: type[FieldError] = ConfigError,
                ) -> dict[str, Any]:
    """A TOML table (``dict``), returned as a new dict."""
    if not isinstance(value, Mapping):
        raise fail(value, what, field=field, file=file, error=error)
    return dict(value)


def check_keys(table: object, known: Sequence[str], path: str | None = None, *,
               file: str | Path | None = None, required: Sequence[str] = ()) -> dict[str, Any]:
    """A table whose keys are all in ``known`` and include every ``required`` key.

    Returns:
        a copy of the table.
    """
    t = check_table(table, path or None, file=file)
    for key, value in t.items():
        if key not in known:
            raise ConfigError(f"got unknown field (value {show(value)}), expected one of "
                              f"{', '.join(known)}", file=file, field=join(path, str(key)))
    return check_required(t, required, path, file=file)


def check_required(table: dict[str, Any], required: Sequence[str], path: str | None = None,
                   *, file: str | Path | None = None) -> dict[str, Any]:
    """``table`` if it has every ``required`` key (``got nothing (missing required field),
    expected a value`` at ``path.key`` otherwise)."""
    for key in required:
        if key not in table:
            raise ConfigError("got nothing (missing required field), expected a value", file=file,
                              field=join(path, key))
    return table


def check_array_of_tables(value: object, field: str, *, file: str | Path | None = None,
                          ) -> list[dict[str, Any]]:
    """An array of tables (``[[field]]``)."""
    if not isinstance(value, list) or not all(isinstance(x, Mapping) for x in value):
        raise fail(value, f"an array of tables ([[{field}]])", field=field, file=file)
    return [dict(x) for x in value]


# -- scalars -----------------------------------------------------------------------------
def is_int(value: object) -> bool:
    """An integer (Python or numpy), not a bool."""
    return isinstance(value, int | np.integer) and not isinstance(value, bool)


def is_number(value: object) -> bool:
    """A real number (int, float, numpy), not a bool."""
    return isinstance(value, int | float | np.integer | np.floating) and not isinstance(
        value, bool)


def _fmt(x: float) -> str:
    return f"{x:g}" if isinstance(x, float) else str(x)


def describe_range(*, bound: Bound | None = None, gt: float | None = None,
                   ge: float | None = None, lt: float | None = None, le: float | None = None,
                   ) -> str:
    """The text after "a number" for these limits (``in (0, 3.3] N (reason)``)."""
    lo, lo_open, hi, hi_open = -math.inf, True, math.inf, True
    if bound is not None:
        lo, lo_open, hi, hi_open = bound.low, False, bound.high, False
    if ge is not None and ge >= lo:
        lo, lo_open = ge, False
    if gt is not None and gt >= lo:
        lo, lo_open = gt, True
    if le is not None and le <= hi:
        hi, hi_open = le, False
    if lt is not None and lt <= hi:
        hi, hi_open = lt, True
    unit = f" {bound.unit}" if bound is not None and bound.unit else ""
    reason = f" ({bound.reason})" if bound is not None else ""
    if math.isinf(lo) and math.isinf(hi):
        return f"{reason}".strip()
    if math.isinf(hi):
        return f"{'>' if lo_open else '>='} {_fmt(lo)}{unit}{reason}"
    if math.isinf(lo):
        return f"{'<' if hi_open else '<='} {_fmt(hi)}{unit}{reason}"
    return (f"in {'(' if lo_open else '['}{_fmt(lo)}, {_fmt(hi)}{')' if hi_open else ']'}"
            f"{unit}{reason}")


def check_number(value: object, field: str | None = None, *, bound: Bound | None = None,
                 gt: float | None = None, ge: float | None = None, lt: float | None = None,
                 le: float | None = None, file: str | Path | None = None,
                 error: type[FieldError] = ConfigError) -> float:
    """A finite real number within ``bound`` and the strict/loose limits; returned as float.

    Raises:
        ConfigError: ``got <value>, expected a finite number in [lo, hi] unit (reason)``.
    """
    rng = describe_range(bound=bound, gt=gt, ge=ge, lt=lt, le=le)
    expected = f"a finite number {rng}".rstrip()
    if not is_number(value):
        raise fail(value, expected, field=field, file=file, error=error)
    try:
        x = float(value)  # type: ignore[arg-type]  # is_number proved it a real number
    except OverflowError:  # an int beyond the float range
        raise fail(value, expected, field=field, file=file, error=error) from None
    if not math.isfinite(x):
        raise fail(value, expected, field=field, file=file, error=error)
    ok = ((bound is None or bound.low <= x <= bound.high)
          and (gt is None or x > gt) and (ge is None or x >= ge)
          and (lt is None or x < lt) and (le is None or x <= le))
    if not ok:
        raise fail(value, expected, field=field, file=file, error=error)
    return x


def check_int(value: object, field: str | None = None, *, bound: Bound | None = None,
              lo: int | None = None, hi: int | None = None,
              file: str | Path | None = None, error: type[FieldError] = ConfigError) -> int:
    """An integer (not a bool) within ``bound`` and [lo, hi]; returned as int."""
    rng = describe_range(bound=bound, ge=lo, le=hi)
    expected = f"an integer {rng}".rstrip()
    if not is_int(value):
        raise fail(value, expected, field=field, file=file, error=error)
    v = int(value)  # type: ignore[call-overload]  # is_int proved it an integer
    if ((bound is not None and not bound.low <= v <= bound.high)
            or (lo is not None and v < lo) or (hi is not None and v > hi)):
        raise fail(value, expected, field=field, file=file, error=error)
    return v


def check_bool(value: object, field: str | None = None, *,
               file: str | Path | None = None, error: type[FieldError] = ConfigError) -> bool:
    """``true`` or ``false``."""
    if not isinstance(value, bool):
        raise fail(value, "true or false", field=field, file=file, error=error)
    return value


def check_str(value: object, field: str | None = None, *, one_line: bool = True,
              empty: bool = False, max_length: int | None = None,
              file: str | Path | None = None, what: str | None = None,
              error: type[FieldError] = ConfigError) -> str:
    """A string (one line unless ``one_line=False``; not empty unless ``empty``); ``what``
    words the expectation (default: ``a one-line string (not empty)``)."""
    if what is None:
        what = "a one-line string" if one_line else "a string"
        if not empty:
            what += " (not empty)"
        if max_length is not None:
            what += f" of at most {max_length} characters"
    if (not isinstance(value, str) or (not empty and not value)
            or (one_line and "\n" in value)
            or (max_length is not None and len(value) > max_length)):
        raise fail(value, what, field=field, file=file, error=error)
    return value


def check_choice(value: object, field: str | None, choices: Sequence[Any], *,
                 file: str | Path | None = None, error: type[FieldError] = ConfigError) -> Any:
    """One of ``choices``."""
    try:
        ok = value in choices
    except TypeError:  # unhashable against a set-like
        ok = False
    if not ok or isinstance(value, bool) != any(isinstance(c, bool) for c in choices):
        raise fail(value, f"one of {', '.join(map(repr, choices))}", field=field, file=file,
                   error=error)
    return value


def check_vec3(value: object, field: str | None = None, *, bound: Bound | None = None,
               nonzero: bool = False, file: str | Path | None = None,
               error: type[FieldError] = ConfigError) -> tuple[float, float, float]:
    """Three finite numbers (each within ``bound``), as a tuple of floats."""
    rng = describe_range(bound=bound)
    what = f"3 finite numbers {rng}".rstrip()
    if isinstance(value, str | bytes) or not isinstance(value, Sequence | np.ndarray):
        raise fail(value, what, field=field, file=file, error=error)
    items = list(value)
    if len(items) != 3:
        raise fail(value, what, field=field, file=file, error=error)
    out = []
    for c in items:
        try:
            out.append(check_number(c, field, bound=bound, file=file, error=error))
        except FieldError:
            raise fail(value, what, field=field, file=file, error=error) from None
    if nonzero and not any(out):
        raise fail(value, "a non-zero vector", field=field, file=file, error=error)
    return (out[0], out[1], out[2])


def check_str_tuple(value: object, field: str, *, unique: bool = True, empty: bool = False,
                    file: str | Path | None = None) -> tuple[str, ...]:
    """A tuple of one-line non-empty strings (unique unless told)."""
    if not isinstance(value, tuple):
        raise fail(value, "an array of strings", field=field, file=file)
    if not empty and not value:
        raise fail(value, "a non-empty array", field=field, file=file)
    for i, x in enumerate(value):
        check_str(x, f"{field}[{i}]", file=file)
    if unique and len(set(value)) != len(value):
        dup = next(x for x in value if value.count(x) > 1)
        raise fail(value, f"no repeated value ({dup!r} is there twice)", field=field,
                   file=file)
    return value


# -- types, arrays, paths ------------------------------------------------------------------
def check_type(value: T, field: str | None, types: type | tuple[type, ...], what: str, *,
               file: str | Path | None = None, error: type[FieldError] = ConfigError) -> T:
    """``value`` if it is an instance of ``types`` (``what`` names them in the error:
    ``"an OrganParams"``); a bool is not accepted as an int or float unless ``types``
    names ``bool``."""
    kinds = types if isinstance(types, tuple) else (types,)
    if not isinstance(value, kinds) or (isinstance(value, bool) and bool not in kinds):
        raise fail(value, what, field=field, file=file, error=error)
    return value


def check_array(value: object, field: str | None = None, *,
                shape: tuple[int | None, ...] | None = None, finite: bool = True,
                what: str | None = None, file: str | Path | None = None,
                error: type[FieldError] = ConfigError) -> NDArray[np.float64]:
    """A float64 array of ``shape`` (``None`` in it: any length on that axis), finite unless
    told; the error reads ``expected an array of shape (n, 3) of finite numbers`` (or
    ``what``).

    >>> check_array([1, 2, 3], "p", shape=(3,)).tolist()
    [1.0, 2.0, 3.0]
    >>> check_array([1, 2], "p", shape=(3,))
    Traceback (most recent call last):
    ...
    vasim.core.errors.ConfigError: field 'p': got [1, 2], expected an array of shape (3,) of \
finite numbers
    """
    if what is None:
        dims = "" if shape is None else (
            "(" + ", ".join("n" if d is None else str(d) for d in shape)
            + ("," if len(shape) == 1 else "") + ")")
        what = ("an array" + (f" of shape {dims}" if dims else "")
                + (" of finite numbers" if finite else " of numbers"))
    try:
        arr = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise fail(value, what, field=field, file=file, error=error) from None
    if shape is not None and (arr.ndim != len(shape) or any(
            d is not None and n != d for n, d in zip(arr.shape, shape, strict=True))):
        raise fail(value, what, field=field, file=file, error=error)
    if finite and not np.all(np.isfinite(arr)):
        raise fail(value, what, field=field, file=file, error=error)
    return arr


MAX_PATH_CHARS = 200
"""Longest echo of a path in an error message (a longer one keeps its end: the file name)."""


def show_path(path: str | Path) -> str:
    """``repr`` of a path, cut at the front to :data:`MAX_PATH_CHARS` characters (the end
    names the file).

    >>> show_path("/data/" + "x" * 300 + "/kidney.obj")[-12:]
    "/kidney.obj'"
    """
    text = repr(str(path))
    return text if len(text) <= MAX_PATH_CHARS else "..." + text[-MAX_PATH_CHARS:]


def check_file(path: str | Path, field: str | None = None, *, what: str = "an existing file",
               error: type[FieldError] = InputError) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it is an existing file (an
    :class:`InputError` by default: a path is what a user typed)."""
    p = Path(path)
    if not p.is_file():
        raise _path_error(p, "a folder" if p.is_dir() else "no such file", what, field, error)
    return p


def _path_error(p: Path, state: str, what: str, field: str | None,
                error: type[FieldError]) -> FieldError:
    return error(f"got {show_path(p)} ({state}), expected {what}", field=field)


def check_dir(path: str | Path, field: str | None = None, *,
              what: str = "an existing folder", error: type[FieldError] = InputError) -> Path:
    """``path`` as a :class:`~pathlib.Path` if it is an existing folder."""
    p = Path(path)
    if not p.is_dir():
        raise _path_error(p, "a file" if p.exists() else "no such folder", what, field, error)
    return p


def check_dir_path(path: str | Path, field: str | None = None, *,
                   what: str = "a folder (existing or new)",
                   error: type[FieldError] = InputError) -> Path:
    """``path`` as a :class:`~pathlib.Path` unless it exists and is not a folder (an output
    folder that may or may not exist yet)."""
    p = Path(path)
    if p.exists() and not p.is_dir():
        raise _path_error(p, "exists and is not a folder", what, field, error)
    return p


def check_not_dir(path: str | Path, field: str | None = None, *, what: str = "a file path",
                  error: type[FieldError] = InputError) -> Path:
    """``path`` as a :class:`~pathlib.Path` unless it is an existing folder (an output file
    that may or may not exist yet)."""
    p = Path(path)
    if p.is_dir():
        raise _path_error(p, "a folder", what, field, error)
    return p


__all__ = [
    "BOM",
    "MAX_TOML_NESTING",
    "check_array",
    "check_array_of_tables",
    "check_bool",
    "check_choice",
    "check_dir",
    "check_dir_path",
    "check_file",
    "check_int",
    "check_keys",
    "check_not_dir",
    "check_number",
    "check_required",
    "check_str",
    "check_str_tuple",
    "check_table",
    "check_type",
    "check_vec3",
    "describe_range",
    "expect",
    "fail",
    "is_int",
    "is_number",
    "join",
    "parse_toml",
    "rewrap",
    "show",
    "show_path",
    "toml_nesting",
]
