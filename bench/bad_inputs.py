"""A catalogue of bad inputs for every loader, and how each one ends.

Every numeric field of every shipped file (schemas, protocols, scenes, robots) is set, one
at a time, to each extreme value (±1e308, ±1e-308, NaN, ±inf, huge integers, -0.0, ...);
meshes get non-finite, huge and oversized vertices; the command line gets huge counts,
long subject codes and impossible addresses; the issue's named cases are run as such. Each
input ends in one of:

* ``clean error``: a :class:`vasim.core.errors.ConfigError` naming the file (or an argparse
  error, exit 2, for the command line);
* ``finite result``: the loader returned an object whose numbers are all finite;
* ``other``: any other exception, or a result holding a non-finite number (a crash
  waiting to happen downstream).

``python -m bench bad_inputs`` (or ``python bench/bad_inputs.py``) prints the table
``category, tried, clean error, finite result, other``; ``tests/test_bad_inputs.py`` runs a
subset and asserts that ``other`` is 0.
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import io
import math
import os
import sys
import tempfile
import tomllib
from collections import Counter
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np

EXTREMES: tuple[Any, ...] = (1e308, -1e308, 1e-308, -1e-308, math.nan, math.inf, -math.inf,
                             10**30, -(10**30), 2**63, -0.0, 0, -1, 1e20)
"""The values every numeric field is set to."""

SMOKE = os.environ.get("VASIM_BENCH_SMOKE") == "1"
"""``python -m bench --smoke``: every run cut to seconds (it checks the bench runs; its
figures mean nothing)."""

Outcome = str  # "clean error" | "finite result" | "other"
Case = tuple[str, str, Callable[[], Any]]
"""(category, description, thunk running the loader)."""


# -- TOML writing (a minimal dumper for the shipped layouts) --------------------------------
def _scalar(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return '"' + v.replace("\\", "\\\\").replace('"', '\\"').replace("\n", "\\n") + '"'
    if isinstance(v, list):
        return "[" + ", ".join(_scalar(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{_key(k)} = {_scalar(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def _key(k: str) -> str:
    return k if k.replace("_", "").replace("-", "").isalnum() else _scalar(k)


def _is_aot(v: Any) -> bool:
    return isinstance(v, list) and bool(v) and all(isinstance(x, dict) for x in v)


def dumps(data: dict[str, Any], prefix: str = "") -> str:
    """TOML text of ``data`` (tables and arrays of tables as headers)."""
    lines = [f"{_key(k)} = {_scalar(v)}" for k, v in data.items()
             if not isinstance(v, dict) and not _is_aot(v)]
    out = "\n".join(lines) + ("\n" if lines else "")
    for k, v in data.items():
        path = f"{prefix}.{_key(k)}" if prefix else _key(k)
        if isinstance(v, dict):
            out += f"\n[{path}]\n" + dumps(v, path)
        elif _is_aot(v):
            for item in v:
                out += f"\n[[{path}]]\n" + dumps(item, path)
    return out


# -- numeric leaves ---------------------------------------------------------------------
def numeric_paths(data: Any, path: tuple[Any, ...] = ()) -> Iterator[tuple[Any, ...]]:
    """Paths (keys and indices) of every number (not bool) in parsed TOML."""
    if isinstance(data, dict):
        for k, v in data.items():
            yield from numeric_paths(v, (*path, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from numeric_paths(v, (*path, i))
    elif isinstance(data, int | float) and not isinstance(data, bool):
        yield path


def with_value(data: dict[str, Any], path: tuple[Any, ...], value: Any) -> dict[str, Any]:
    """A deep copy of ``data`` with the leaf at ``path`` set to ``value``."""
    out = copy.deepcopy(data)
    node: Any = out
    for k in path[:-1]:
        node = node[k]
    node[path[-1]] = value
    return out


def all_finite(obj: Any, _depth: int = 0) -> bool:
    """Whether every number reachable in ``obj`` (dataclasses, tuples, arrays) is finite."""
    if _depth > 12:
        return True
    if isinstance(obj, bool) or obj is None or isinstance(obj, str):
        return True
    if isinstance(obj, int):
        return abs(obj) < 2**63
    if isinstance(obj, float):
        return math.isfinite(obj)
    if isinstance(obj, np.ndarray):
        return obj.dtype.kind not in "fc" or bool(np.all(np.isfinite(obj)))
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        return all(all_finite(getattr(obj, f.name), _depth + 1) for f in dataclasses.fields(obj))
    if isinstance(obj, tuple | list):
        return all(all_finite(x, _depth + 1) for x in obj)
    if isinstance(obj, dict):
        return all(all_finite(x, _depth + 1) for x in obj.values())
    return True


def classify(thunk: Callable[[], Any], source: str | None = None) -> Outcome:
    """Runs ``thunk``: a ConfigError (naming ``source``, if given) is a clean error."""
    from vasim.core.errors import ConfigError

    try:
        result = thunk()
    except ConfigError as exc:
        return "clean error" if source is None or source in str(exc) else "other"
    except SystemExit as exc:  # argparse
        return "clean error" if exc.code == 2 else "other"
    except Exception:
        return "other"
    return "finite result" if all_finite(result) else "other"


# -- the catalogue ----------------------------------------------------------------------
def _shipped() -> list[tuple[str, Path, Callable[[str, str], Any]]]:
    from vasim.abdomen.scene import parse_scene
    from vasim.core.resources import protocols_dir
    from vasim.fixtures.schema import parse_schema
    from vasim.mrcp.dh import parse_robot
    from vasim.study.protocol import parse_protocol

    root = protocols_dir()
    loaders: dict[str, Callable[[str, str], Any]] = {
        "schemas": lambda text, src: parse_schema(text, source=src),
        "studies": lambda text, src: parse_protocol(text, source=src),
        "scenes": lambda text, src: parse_scene(text, source=src),
        "robots": lambda text, src: parse_robot(text, file=src),
    }
    out = []
    for folder, load in loaders.items():
        for p in sorted((root / folder).glob("*.toml")):
            out.append((folder, p, load))
    return out


def field_cases(stride: int = 1, extremes: tuple[Any, ...] = EXTREMES) -> Iterator[Case]:
    """Every ``stride``-th numeric field of every shipped file, set to each extreme."""
    for folder, path, load in _shipped():
        data = tomllib.loads(path.read_text(encoding="utf-8"))
        src = str(path)
        for k, leaf in enumerate(numeric_paths(data)):
            if k % stride:
                continue
            for value in extremes:
                text = dumps(with_value(data, leaf, value))
                yield (folder, f"{path.name}:{'.'.join(map(str, leaf))}={value!r}",
                       lambda text=text, src=src, load=load: load(text, src))
        # a BOM at the start is accepted
        text = "\ufeff" + path.read_text(encoding="utf-8")
        yield (folder, f"{path.name} with a UTF-8 BOM",
               lambda text=text, src=src, load=load: load(text, src))


def _obj(vertices: np.ndarray, faces: np.ndarray) -> str:
    v = "\n".join("v " + " ".join(repr(float(c)) for c in row) for row in vertices)
    f = "\n".join("f " + " ".join(str(int(i) + 1) for i in row) for row in faces)
    return v + "\n" + f + "\n"


def mesh_cases(tmp: Path) -> Iterator[Case]:
    """User meshes: non-finite, huge, oversized and out-of-unit vertices."""
    import trimesh

    from vasim.abdomen.meshes import load_user_mesh

    ball = trimesh.creation.icosphere(subdivisions=2, radius=0.03)
    variants: dict[str, np.ndarray] = {}
    for value in (math.nan, math.inf, 1e200, 1e20, 1e308, -1e308):
        v = ball.vertices.copy()
        v[0, 0] = value
        variants[f"vertex0.x={value!r}"] = v
    variants["0.9 m organ"] = ball.vertices * 15.0
    variants["1e20 m organ"] = ball.vertices * 1e20 / 0.06
    variants["1e-308 m organ"] = ball.vertices * 1e-308
    variants["organ at 1 m"] = ball.vertices + 1.0
    variants["a 6 cm ball (fine)"] = ball.vertices
    for name, v in variants.items():
        p = tmp / f"mesh_{len(list(tmp.iterdir()))}.obj"
        p.write_text(_obj(v, ball.faces))
        yield ("meshes", name, lambda p=p: load_user_mesh(p, field="organs.x.mesh"))


def cli_cases() -> Iterator[Case]:
    """Command-line numbers, codes and addresses, parsed only (nothing runs)."""
    from vasim.cli import build_parser

    bad = ["1000000000", "-1", "1e308", "nan", "inf", str(10**30), "-0.0", "0"]
    argvs: list[list[str]] = []
    for v in bad:
        argvs += [["study", "simulate", "--protocol", "p", "--db", "x", "--subjects", v],
                  ["study", "simulate", "--protocol", "p", "--db", "x", "--workers", v],
                  ["study", "simulate", "--protocol", "p", "--db", "x", "--seed", v],
                  ["study", "run", "--protocol", "p", "--db", "x", "--subject", "S1",
                   "--max-time", v],
                  ["trial", "--variant", v], ["serve", "--port", v], ["serve", "--duration", v]]
    for code in ("A" * 100_000, "Jane Doe", "", "S\n1"):
        argvs.append(["study", "run", "--protocol", "p", "--db", "x", "--subject", code])
    for host in ("999.1.1.1", "1.2.3", "bad_host!", "x" * 300, "::1", "localhost"):
        argvs.append(["serve", "--host", host])
    for argv in argvs:
        def run(argv: list[str] = argv) -> Any:
            with contextlib.redirect_stderr(io.StringIO()):
                ns = build_parser().parse_args(argv)
            return {k: v for k, v in vars(ns).items() if not callable(v)}

        yield ("cli", " ".join(a[:40] for a in argv), run)


def issue_cases() -> Iterator[Case]:
    """The cases issue #16 lists, by name."""
    from vasim.abdomen.scene import parse_scene
    from vasim.fixtures.schema import parse_schema
    from vasim.study.protocol import parse_protocol

    head = 'name = "x"\ndescription = "d"\n'
    for body in ("max_force_n = 1000", "[fixtures.ff]\nmax_force_n = 1000",
                 "[fixtures.ff]\nk = 1e6", "max_force_n = 1e300"):
        yield ("issue", f"schema {body!r}",
               lambda b=body: parse_schema(head + b, source="protocols/schemas/ff.toml"))
    proto = ('name = "p"\ndescription = "d"\ntask = "trajectory"\nreach_radius_m = {r}\n'
             '[[blocks]]\nname = "b"\ncondition = "none"\n')
    for r in ("0.5", "1e300"):
        yield ("issue", f"protocol reach_radius_m = {r}",
               lambda r=r: parse_protocol(proto.format(r=r), source="p.toml"))
    yield ("issue", "scene mass = 1e-300",
           lambda: parse_scene('name = "s"\n[organs.liver]\nmass = 1e-300\n', source="s.toml"))


# -- issue #30: the second hardening round, replayed end to end ----------------------------
ROUND_OUTCOMES: tuple[str, ...] = ("refused", "handled", "traceback", "hang", "wrong")
"""How a round case ends: ``refused`` (exit 2, or a ConfigError, with one line saying what
is wrong, checked for the words that make it clear), ``handled`` (exit 0 and the result
checked: the right session stored, the folder's mode kept, ...), ``traceback``, ``hang``
(no end within the case's time limit), ``wrong`` (anything else: a silent exit 0 where a
refusal was due, an unclear message, a failed check)."""


@dataclasses.dataclass
class RoundCase:
    """One input of the round: ``argv`` for ``vasim`` (run in a forked process), or ``call``
    (a function run there); ``expect`` is ``"refused"`` or ``"handled"``; ``words`` must all
    be in the refusal (or, handled, in stdout + stderr); ``check`` (handled) must return
    True; ``signal_after`` sends ``signal`` that many seconds after ``ready()`` is true
    (a hang ended by Ctrl-C / SIGTERM: handled when it exits 130)."""

    item: str
    what: str
    argv: list[str] | None = None
    call: Callable[[], Any] | None = None
    expect: str = "refused"
    words: tuple[str, ...] = ()
    check: Callable[[], bool] | None = None
    timeout: float = 240.0
    signal: int | None = None
    signal_after: float = 3.0
    ready: Callable[[], bool] | None = None


def _child(case: RoundCase, conn: Any) -> None:
    """Runs one case in the forked process; sends (exit code, stdout, stderr)."""
    import traceback

    from vasim.core.errors import ConfigError

    out, err = io.StringIO(), io.StringIO()
    code: int | None
    try:
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            if case.argv is not None:
                from vasim.cli import main as vasim_main

                code = vasim_main(case.argv)
            else:
                assert case.call is not None
                try:
                    result = case.call()
                    if isinstance(result, int) and not isinstance(result, bool):
                        code = result          # an exit code (a call that runs vasim)
                    else:
                        code = 0 if result is not False else 1
                        if result not in (None, True, False):
                            print(repr(result))
                except ConfigError as exc:
                    print(f"error: {exc}", file=sys.stderr)
                    code = 2
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else 1
    except BaseException:
        err.write(traceback.format_exc())
        code = 1
    conn.send((code, out.getvalue(), err.getvalue()))
    conn.close()


def run_round_case(case: RoundCase) -> tuple[str, str]:
    """Runs ``case`` in a forked process with its time limit; returns (outcome, detail)."""
    import multiprocessing as mp
    import os
    import time

    ctx = mp.get_context("fork")
    parent, child = ctx.Pipe(duplex=False)
    proc = ctx.Process(target=_child, args=(case, child), daemon=True)
    t0 = time.monotonic()
    proc.start()
    child.close()
    if case.signal is not None:
        while case.ready is not None and not case.ready() and proc.is_alive() \
                and time.monotonic() - t0 < case.timeout:
            time.sleep(0.1)
        time.sleep(case.signal_after)
        if proc.is_alive() and proc.pid is not None:
            os.kill(proc.pid, case.signal)
            t0 = time.monotonic()      # from now on: how long it takes to stop
    got = parent.poll(case.timeout if case.signal is None else 60.0)
    if not got:
        proc.kill()
        proc.join()
        return "hang", f"no end within {case.timeout:g} s"
    try:
        code, out, err = parent.recv()
    except EOFError:
        proc.join()
        return "traceback", f"the process died (exit {proc.exitcode})"
    proc.join(10)
    took = time.monotonic() - t0
    if "Traceback" in err:
        return "traceback", err.strip().splitlines()[-1][:200]
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    if case.signal is not None:
        ok = code == 130 and "interrupted" in err
        return ("handled" if ok else "wrong"), f"exit {code} {took:.1f} s after the signal"
    if case.expect == "refused":
        if code == 2 and len(lines) == 1 and all(w in lines[0] for w in case.words) and (
                case.check is None or case.check()):
            return "refused", lines[0][:300]
        return "wrong", f"exit {code}: {(lines or err.splitlines() or ['(nothing)'])[-1][:300]}"
    text = out + err
    if code == 0 and all(w in text for w in case.words) and (case.check is None
                                                             or case.check()):
        return "handled", (err.strip().splitlines() or out.strip().splitlines() or [""])[-1][
            :300]
    return "wrong", f"exit {code}: {(err.strip().splitlines() or ['check failed'])[-1][:300]}"


TINY = """name = "tiny"
description = "two short trials"
task = "trajectory"
reach_radius_m = 0.005
max_trial_time_s = 0.05

[[blocks]]
name = "b"
condition = "none"
variants = [0]
repetitions = 2
probe = true
counterbalance = false
"""
RETENTION = """name = "tret"
description = "one trial, then a retention probe a day later"
task = "trajectory"
reach_radius_m = 0.005
max_trial_time_s = 0.05

[[blocks]]
name = "a"
condition = "ff"
variants = [0]
counterbalance = false

[[blocks]]
name = "r"
condition = "none"
phase = "retention"
delay_days = 1.0
variants = [0]
probe = true
counterbalance = false
"""


"""``TINY``: two VF-free trials in one block; ``RETENTION``: one FF trial, then a VF-free
retention probe a day later; both with a 0.05 s trial time limit, so whole sessions run in
seconds (this round's cases and the tests': ``tests/study/tiny_protocols.py``)."""


def protocols_folder(folder: Path, **texts: str) -> Path:
    """``folder`` holding the shipped protocols and ``texts`` (file stem -> TOML text): what
    ``vasim.study.protocol.loader.studies_dir`` returns where a test or a case offers extra
    protocols as shipped ones (the viewer offers only shipped protocols). Returns it."""
    import shutil

    from vasim.core.resources import studies_dir

    folder.mkdir(parents=True, exist_ok=True)
    for f in studies_dir().glob("*.toml"):
        shutil.copy(f, folder / f.name)
    for stem, text in texts.items():
        (folder / f"{stem}.toml").write_text(text, encoding="utf-8")
    return folder


def tcp_listener(reply: bytes | None) -> tuple[Any, Any, list[Any]]:
    """A local TCP server on a free port (this round's and ``tests/study/test_harden.py``'s):
    ``reply`` is sent after the client's first bytes (None: nothing, the connection stays
    open). Returns the listening socket, its accept thread and the accepted connections."""
    import socket
    import threading

    srv = socket.socket()
    srv.bind(("127.0.0.1", 0))
    srv.listen(16)
    conns: list[Any] = []

    def serve() -> None:
        while True:
            try:
                c, _ = srv.accept()
            except OSError:
                return
            conns.append(c)
            if reply is not None:
                with contextlib.suppress(OSError):
                    c.recv(64)
                    c.sendall(reply)

    t = threading.Thread(target=serve, daemon=True)
    t.start()
    return srv, t, conns


def _server(reply: bytes | None) -> tuple[int, list[Any]]:
    """:func:`tcp_listener`'s port and connections (it runs until the round's process ends)."""
    srv, _, conns = tcp_listener(reply)
    return int(srv.getsockname()[1]), conns


def _page_start(protocol: Path, db: Path, subject: str, again: str | None) -> None:
    """The experimenter page's Start of a protocol session (its controller, as the page's
    buttons drive it; run in the case's own process): ``protocol`` is offered as a shipped
    protocol, ``again`` is typed in "Again, because" first (None: left empty). A refusal
    raises ConfigError (the case's one line)."""
    import vasim.study.protocol.loader as loader
    from vasim.viewer.app_options import TrialOptions
    from vasim.viewer.controller import Command, TrainingController, TrainingSettings

    folder = protocols_folder(protocol.parent / "studies",
                              **{protocol.stem: protocol.read_text(encoding="utf-8")})
    loader.studies_dir = lambda: folder            # type: ignore[assignment]  # this process
    ctl = TrainingController(TrainingSettings(
        scene="none", db=db, speed=25.0,
        trials=TrialOptions(countdown_s=0.0, pause_s=0.05)))
    try:
        for cmd in (Command("mode", "protocol"), Command("subject", subject),
                    Command("protocol", protocol.stem)):
            ctl.handle(cmd)
        if again is not None:
            ctl.handle(Command("again", again))
        ctl.handle(Command("start"))
        print(f"session {ctl.panel.session_id} started for {subject}")
    finally:
        ctl.close()


def round_cases(tmp: Path, smoke: bool = False) -> Iterator[RoundCase]:
    """The cases of issue #30 items 3-8 (``smoke``: one or two per item, no Ray, no
    session runs beyond the setup)."""
    import os
    import shutil
    import signal
    import sqlite3
    import stat

    from vasim.cli import main as vasim_main

    def quiet(argv: list[str]) -> int:
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(
                io.StringIO()):
            return vasim_main(argv)

    tiny, ret = tmp / "tiny.toml", tmp / "tret.toml"
    tiny.write_text(TINY, encoding="utf-8")
    ret.write_text(RETENTION, encoding="utf-8")
    db, rdb = tmp / "x.sqlite", tmp / "r.sqlite"
    assert quiet(["study", "run", "--protocol", str(tiny), "--db", str(db), "--subject", "D9",
                  "--no-progress"]) == 0
    assert quiet(["study", "run", "--protocol", str(ret), "--db", str(rdb), "--subject", "R1",
                  "--no-progress"]) == 0
    run = ["study", "run", "--protocol", str(tiny), "--db", str(db), "--no-progress"]
    vdb = tmp / "v.sqlite"          # the page's cases: D9's one completed session
    shutil.copy(db, vdb)

    def notes_of(path: Path) -> list[Any]:
        con = sqlite3.connect(path)
        try:
            return [r[0] for r in con.execute("SELECT notes FROM sessions ORDER BY id")]
        finally:
            con.close()

    # item 3: a finished subject gets a second session
    yield RoundCase("3", "study run twice for D9", [*run, "--subject", "D9"],
                    words=("already completed protocol 'tiny'", "--again"))
    if not smoke:
        yield RoundCase("3", "--again for a subject without a completed session",
                        [*run, "--subject", "D8", "--again", "x"],
                        words=("no completed session",))
        yield RoundCase("3", "study run --again REASON", [*run, "--subject", "D9", "--again",
                                                         "device failed"], expect="handled",
                        check=lambda: notes_of(db)[-1].endswith("device failed"))

    # item 3 on the experimenter's page (the controller the page's Start button drives)
    yield RoundCase("3", "page: Start for D9 (completed)",
                    call=lambda: _page_start(tiny, vdb, "D9", None),
                    words=("already completed protocol 'tiny'", "Again, because"))
    if not smoke:
        yield RoundCase("3", "page: Start with 'Again, because' for D9",
                        call=lambda: _page_start(tiny, vdb, "D9", "device failed"),
                        expect="handled",
                        check=lambda: notes_of(vdb)[-1] == "again after completed session 1:"
                                                           " device failed")
        yield RoundCase("3", "page: a reason while D9's session is open",
                        call=lambda: _page_start(tiny, vdb, "D9", "once more"),
                        words=("open session 2", "Start resumes it"),
                        check=lambda: len(notes_of(vdb)) == 2)
        yield RoundCase("3", "page: a reason for D8 (no completed session)",
                        call=lambda: _page_start(tiny, vdb, "D8", "x"),
                        words=("no completed session",), check=lambda: len(notes_of(vdb)) == 2)

    # item 4: study power --address
    power = ["study", "power", "--protocol", "vf_learning_curve", "--subjects", "4",
             "--cohorts", "1", "--address"]
    bad_addresses = ["127.0.0.1:99999", "", "x" * 10_000 + ":1"]
    if not smoke:
        bad_addresses += ["127.0.0.1:1", "[::1]:1", "no-such-host.invalid:6379"]
    for a in bad_addresses:
        yield RoundCase("4", f"--address {a[:30]!r}", [*power, a], timeout=120,
                        words=("--address",))
    if not smoke:
        silent, _ = _server(None)
        http1, _ = _server(b"HTTP/1.1 400 Bad Request\r\n\r\n")
        yield RoundCase("4", "--address of a server that never answers",
                        [*power, f"127.0.0.1:{silent}"], timeout=120,
                        words=("no answer within",))
        yield RoundCase("4", "--address of an HTTP/1.1 server", [*power, f"127.0.0.1:{http1}"],
                        timeout=120, words=("not a Ray head",))
        for sig in (signal.SIGTERM, signal.SIGINT):
            port, conns = _server(bytes([0, 0, 0, 4, 0, 0, 0, 0, 0]))
            yield RoundCase("4", f"a gRPC server that is no Ray head, then {sig.name}",
                            [*power, f"127.0.0.1:{port}"], expect="handled", signal=sig,
                            ready=lambda conns=conns: len(conns) > 0, timeout=240)

    # item 5: tracebacks
    from vasim.study.power.design import parse_effects

    deep = "x = " + "[" * 50_000 + "]" * 50_000 + "\n"
    loaders: list[tuple[str, Callable[[], Any]]] = [
        (name, lambda load=load, name=name: load(deep, f"{name}.toml"))
        for name, load in _deep_loaders(tmp)]
    loaders.append(("effects", lambda: parse_effects(deep, file="effects.toml")))
    for name, thunk in loaders[:2] if smoke else loaders:
        yield RoundCase("5", f"{name}: 50,000 nested brackets", call=thunk,
                        words=("nested 50000 levels deep",))
    yield RoundCase("5", "trial --replay 99999999999999999999999",
                    ["trial", "--replay", "99999999999999999999999", "--db", str(db)],
                    words=("argument --replay",))

    def huge_batch() -> bool:
        from vasim.viewer.instrument_input import parse_batch

        return parse_batch('{"dx": %s}' % ("9" * 400)) is None

    yield RoundCase("5", "a 400-digit integer in the trainee's input", call=huge_batch,
                    expect="handled")

    def numba_ro() -> bool:
        import tempfile

        from vasim.core import numba_cache

        blocker = tmp / "ro.file"
        blocker.write_text("not a folder")
        os.environ["NUMBA_CACHE_DIR"] = str(blocker / "mine")
        os.environ["XDG_CACHE_HOME"] = str(blocker / "cache")
        numba_cache._PACKAGE = blocker / "vasim"
        tempfile.tempdir = str(tmp)
        chosen = numba_cache.configure_numba_cache()
        return chosen is not None and numba_cache.writable_dir(chosen)

    yield RoundCase("5", "NUMBA_CACHE_DIR=<read-only> on a read-only install", call=numba_ro,
                    expect="handled", words=("is not a writable folder",))
    resume = ["study", "resume", "--subject", "R1", "--no-progress"]
    for value in ([None] if smoke else ["not a date", None]):
        edited = tmp / f"r-{value}.sqlite"
        edited.write_bytes(rdb.read_bytes())
        con = sqlite3.connect(edited)
        con.execute("UPDATE trials SET ended_at = ?", (value,))
        con.commit()
        con.close()
        yield RoundCase("5", f"resume after ended_at = {value!r}",
                        [*resume, "--db", str(edited)],
                        words=(f"has ended_at = {value!r}", "--simulate-delay"))

    # item 6: silent wrong
    from vasim.study.protocol import parse_protocol

    head = 'name = "p"\ndescription = "d"\ntask = "trajectory"\n'
    yield RoundCase("6", "gain_schedule of 4 stages on 2 trials", call=lambda: parse_protocol(
        head + '[[blocks]]\nname = "f"\ncondition = "ff_faded"\nschema = "ff"\n'
        'variants = [1, 2]\ngain_schedule = [1.0, 0.75, 0.5, 0.25]\n', source="p.toml"),
        words=("blocks[0].gain_schedule", "would skip stages"))
    yield RoundCase("6", "delay_days on the first block", call=lambda: parse_protocol(
        head + '[[blocks]]\nname = "a"\ncondition = "none"\ndelay_days = 3.0\n'
        "counterbalance = false\n", source="p.toml"), words=("blocks[0].delay_days",))
    eff = tmp / "effects.toml"
    eff.write_text("[f]\naccuracy = 0.8\n", encoding="utf-8")
    if not smoke:
        yield RoundCase("6", "--effects with an unknown label",
                        ["study", "power", "--protocol", "vf_learning_curve", "--subjects",
                         "4", "--cohorts", "1", "--effects", str(eff)],
                        words=("field 'f'", "a condition of protocol"))
    export = ["study", "export", "--db", str(db), "--no-progress", "--out"]
    folder = tmp / "ex755"
    folder.mkdir()
    folder.chmod(0o755)
    yield RoundCase("6", "re-export into a 755 folder",
                    [*export, str(folder), "--tables", "sessions"], expect="handled",
                    check=lambda: stat.S_IMODE(folder.stat().st_mode) == 0o755)
    yield RoundCase("6", "export --tables ''", [*export, str(tmp / "e1"), "--tables", ""],
                    words=("--tables",))
    csv = tmp / "mm.csv"
    rng = np.random.default_rng(0)
    rows = ["subject,fixture,trial,error"] + [
        f"S{s},{f},{t},{1 + 0.3 * (f == 'ff') + 0.1 * t + rng.normal(0, 0.2):.4f}"
        for s in range(8) for f in ("ff", "none") for t in range(3)]
    csv.write_text("\n".join(rows) + "\n", encoding="utf-8")
    mm = ["stats", "mixed-model", "--csv", str(csv), "--groups", "subject", "--formula"]
    yield RoundCase("6", "--factors nope", [*mm, "error ~ C(fixture) + trial", "--factors",
                                            "nope"], words=("--factors", "'nope'"))

    # item 7: code in a formula
    pwned = tmp / "PWNED"
    for formula in ([f"error ~ I(__import__('os').system('touch {pwned}'))"] + (
            [] if smoke else ["error ~ I(__import__('os'))", "error ~ trial.__class__",
                              "error ~ np.os.system('id')"])):
        yield RoundCase("7", f"--formula {formula[:40]!r}", [*mm, formula],
                        words=("field 'formula'",), check=lambda: not pwned.exists())

    # item 8: unclear messages
    afile = tmp / "afile"
    afile.write_text("x")
    yield RoundCase("8", "--out under a file", [*export, str(afile / "sub")],
                    words=(f"{afile} is a file",))
    if not smoke:
        yield RoundCase("8", "--out naming a file", [*export, str(afile)], words=(str(afile),))

        def full_disk() -> Any:
            import errno

            import vasim.study.export as ex

            def fail(db: Any, out_dir: Path, *_a: Any) -> None:
                raise OSError(errno.ENOSPC, "No space left on device", str(out_dir / "x"))

            ex._export_into = fail  # type: ignore[assignment]  # the forked case's own copy
            return vasim_main([*export, str(tmp / "full")])

        yield RoundCase("8", "a full disk", call=full_disk,
                        words=(f"{tmp / 'full'}: No space left on device",))

        def read_only() -> Any:
            import errno
            import tempfile

            def refuse(prefix: str = "", dir: Any = None, **_k: Any) -> str:
                raise PermissionError(errno.EACCES, "Permission denied", f"{dir}/{prefix}x")

            tempfile.mkdtemp = refuse  # type: ignore[assignment]  # the forked case's own
            return vasim_main([*export, str(tmp / "ro" / "ex")])

        yield RoundCase("8", "a read-only output folder", call=read_only,
                        words=(f"{tmp / 'ro' / 'ex'}: Permission denied",))
    future = tmp / "future.sqlite"
    future.write_bytes(rdb.read_bytes())
    con = sqlite3.connect(future)
    con.execute("UPDATE trials SET ended_at = '2099-01-01T00:00:00+00:00'")
    con.commit()
    con.close()
    yield RoundCase("8", "a sitting stored while the clock was fast",
                    [*resume, "--db", str(future)], words=("in the future", "clock"))
    if not smoke:
        changed = tmp / "changed.sqlite"
        changed.write_bytes(rdb.read_bytes())
        edited = tmp / "tret_edited.toml"
        edited.write_text(RETENTION.replace("0.05", "0.06").replace('"tret"', '"tret"'),
                          encoding="utf-8")
        yield RoundCase("8", "resume after the protocol file changed",
                        [*resume, "--db", str(changed), "--protocol", str(edited),
                         "--simulate-delay"], expect="handled",
                        words=("has changed since session 1 started",
                               "resumes with the protocol stored with it"))


def _deep_loaders(tmp: Path) -> list[tuple[str, Callable[[str, str], Any]]]:
    from vasim.abdomen.scene import parse_scene
    from vasim.fixtures.schema import parse_schema
    from vasim.mrcp.dh import parse_robot
    from vasim.study.protocol import parse_protocol
    from vasim.study.session import load_answers_file

    def answers(text: str, src: str) -> Any:
        p = tmp / "answers.toml"
        p.write_text(text, encoding="utf-8")
        return load_answers_file(p)

    return [("protocol", lambda t, s: parse_protocol(t, source=s)),
            ("schema", lambda t, s: parse_schema(t, source=s)),
            ("scene", lambda t, s: parse_scene(t, source=s)),
            ("robot", lambda t, s: parse_robot(t, file=s)),
            ("answers", answers)]


def run_round(smoke: bool = False, show: bool = True) -> tuple[dict[str, Counter[str]],
                                                                list[str]]:
    """Runs the issue #30 round; returns outcome counts per item and one line per case."""
    from vasim.core.progress import progress_bar

    counts: dict[str, Counter[str]] = {}
    lines: list[str] = []
    with tempfile.TemporaryDirectory() as d:
        cases = list(round_cases(Path(d), smoke=smoke))
        bar = progress_bar(len(cases), "issue #30 round", "case", enabled=show)
        for case in cases:
            outcome, detail = run_round_case(case)
            counts.setdefault(case.item, Counter())[outcome] += 1
            lines.append(f"[{case.item}] {outcome:<9} {case.what}: {detail}")
            bar.update(1)
        bar.close()
    return counts, lines


def round_table(counts: dict[str, Counter[str]]) -> str:
    """The round's table: per item, how many cases ended in each outcome."""
    head = f"{'item':<6} {'tried':>5} " + " ".join(f"{o:>9}" for o in ROUND_OUTCOMES)
    rows = [head]
    total: Counter[str] = Counter()
    for item in sorted(counts):
        c = counts[item]
        total.update(c)
        rows.append(f"#30.{item:<2} {sum(c.values()):>5} "
                    + " ".join(f"{c[o]:>9}" for o in ROUND_OUTCOMES))
    rows.append(f"{'total':<6} {sum(total.values()):>5} "
                + " ".join(f"{total[o]:>9}" for o in ROUND_OUTCOMES))
    return "\n".join(rows)


def run_catalogue(stride: int = 1, extremes: tuple[Any, ...] = EXTREMES,
                  ) -> tuple[dict[str, Counter[str]], list[str]]:
    """Runs every case; returns outcome counts per category and the 'other' cases."""
    counts: dict[str, Counter[str]] = {}
    others: list[str] = []
    with tempfile.TemporaryDirectory() as d:
        groups = [field_cases(stride, extremes), mesh_cases(Path(d)), cli_cases(),
                  issue_cases()]
        for group in groups:
            for category, what, thunk in group:
                src = None if category in ("cli", "issue", "meshes") else what.split(":")[0]
                outcome = classify(thunk, src.split(" ")[0] if src else None)
                counts.setdefault(category, Counter())[outcome] += 1
                if outcome == "other":
                    others.append(f"{category}: {what}")
    return counts, others


def table(counts: dict[str, Counter[str]]) -> str:
    """The printed table."""
    rows = [f"{'category':<10} {'tried':>6} {'clean error':>12} {'finite result':>14} "
            f"{'other (crash)':>14}"]
    total: Counter[str] = Counter()
    for cat, c in counts.items():
        total.update(c)
        rows.append(f"{cat:<10} {sum(c.values()):>6} {c['clean error']:>12} "
                    f"{c['finite result']:>14} {c['other']:>14}")
    rows.append(f"{'total':<10} {sum(total.values()):>6} {total['clean error']:>12} "
                f"{total['finite result']:>14} {total['other']:>14}")
    return "\n".join(rows)


def main(argv: list[str] | None = None) -> None:
    """``python -m bench bad_inputs`` / ``python bench/bad_inputs.py [--smoke]``: the
    catalogue of extreme values (``--smoke``: every 9th field) and the issue #30 round
    (``--smoke``: a few cases per item, no Ray)."""
    import time

    args = sys.argv[1:] if argv is None else argv
    smoke = "--smoke" in args or SMOKE
    t0 = time.perf_counter()
    counts, others = run_catalogue(stride=9 if smoke else 1)
    print(table(counts))
    print(f"({time.perf_counter() - t0:.1f} s)")
    for o in others[:50]:
        print("other:", o)
    t0 = time.perf_counter()
    rcounts, lines = run_round(smoke=smoke, show=sys.stderr.isatty())
    print()
    print("issue #30 round (each case in its own process; outcomes: refused with a one-line "
          "message, handled, traceback, hang, wrong)")
    print(round_table(rcounts))
    print(f"({time.perf_counter() - t0:.1f} s)")
    for line in lines:
        print(line)


if __name__ == "__main__":
    main()
    sys.exit(0)
