"""Issue #30 (second hardening round), items 3, 4, 6, 7 and 8: each bad input is refused
with one line naming the file / field / value and what to do (exit code 2), or handled.

Every test here failed before the fix (a silent second session, a traceback, a hang, code
run by patsy, a 0700 folder, an internal path in a message) and passes after it.
"""

from __future__ import annotations

import errno
import os
import shutil
import socket
import sqlite3
import stat
import subprocess
import sys
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from bench.bad_inputs import tcp_listener
from tests.study.tiny_protocols import RETENTION, TINY
from vasim.cli import main
from vasim.core.errors import ConfigError, InputError
from vasim.study.protocol import parse_protocol


def _run(argv: list[str], capsys: pytest.CaptureFixture[str]) -> tuple[int, str, str]:
    code = main(argv)
    out, err = capsys.readouterr()
    return code, out, err


def _one_line_error(err: str) -> str:
    lines = [ln for ln in err.splitlines() if "error:" in ln]
    assert len(lines) == 1, err
    assert "Traceback" not in err
    return lines[0]


# ------------------------------------------------------------------ item 3: --again
def test_a_second_session_of_a_completed_protocol_needs_again(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    proto = tmp_path / "tiny.toml"
    proto.write_text(TINY, encoding="utf-8")
    db = tmp_path / "s.sqlite"
    run = ["study", "run", "--protocol", str(proto), "--db", str(db), "--no-progress"]
    assert _run([*run, "--subject", "D9"], capsys)[0] == 0
    # the same subject again: refused, naming the subject, protocol, session and the flag
    code, _, err = _run([*run, "--subject", "D9"], capsys)
    line = _one_line_error(err)
    assert code == 2
    assert "'D9' already completed protocol 'tiny'" in line and "session 1" in line
    assert "--again" in line
    # --again for a subject without a completed session: refused (the reason would be false)
    code, _, err = _run([*run, "--subject", "D8", "--again", "device failed"], capsys)
    assert code == 2 and "no completed session" in _one_line_error(err)
    # an empty reason: refused
    code, _, err = _run([*run, "--subject", "D9", "--again", " "], capsys)
    assert code == 2 and "reason" in _one_line_error(err)
    # with a reason: a new session, the reason stored with it
    code, out, err = _run([*run, "--subject", "D9", "--again", "device failed"], capsys)
    assert code == 0, err
    con = sqlite3.connect(db)
    rows = con.execute("SELECT id, subject, status, notes FROM sessions ORDER BY id").fetchall()
    con.close()
    assert [(r[0], r[1], r[2]) for r in rows] == [(1, "D9", "completed"), (2, "D9", "completed")]
    assert rows[0][3] is None
    assert rows[1][3] == "again after completed session 1: device failed"
    code, out, _ = _run(["study", "list", "--db", str(db)], capsys)
    assert code == 0 and "device failed" in out


# ------------------------------------------------- items 5 and 8: resume and sittings
@pytest.fixture
def stopped_at_sitting(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    """A store whose session stopped before its day-1 retention sitting."""
    proto = tmp_path / "tret.toml"
    proto.write_text(RETENTION, encoding="utf-8")
    db = tmp_path / "r.sqlite"
    code, _, err = _run(["study", "run", "--protocol", str(proto), "--db", str(db),
                         "--subject", "R1", "--no-progress"], capsys)
    assert code == 0, err
    return db


def _set_ended_at(db: Path, value: str | None) -> None:
    con = sqlite3.connect(db)
    con.execute("UPDATE trials SET ended_at = ?", (value,))
    con.commit()
    con.close()


@pytest.mark.parametrize("value", ["not a date", None, ""])
def test_resume_after_a_hand_edited_ended_at_names_the_trial(
        stopped_at_sitting: Path, capsys: pytest.CaptureFixture[str],
        value: str | None) -> None:
    db = stopped_at_sitting
    _set_ended_at(db, value)
    resume = ["study", "resume", "--db", str(db), "--subject", "R1", "--no-progress"]
    code, _, err = _run(resume, capsys)
    line = _one_line_error(err)
    assert code == 2
    assert f"trial 1 (session 1, the trial before sitting 2) has ended_at = {value!r}" in line
    assert "--simulate-delay" in line
    # a simulated delay does not need the time: the session completes
    code, out, err = _run([*resume, "--simulate-delay"], capsys)
    assert code == 0, err
    assert "2/2 trials completed, status completed" in out


def test_an_early_sitting_stored_in_the_future_says_so(
        stopped_at_sitting: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = stopped_at_sitting
    _set_ended_at(db, "2099-01-01T00:00:00+00:00")   # stored while the clock was fast
    code, _, err = _run(["study", "resume", "--db", str(db), "--subject", "R1",
                         "--no-progress"], capsys)
    line = _one_line_error(err)
    assert code == 2 and "due 2099-01-02T00:00:00+00:00" in line
    assert "stored end is" in line and "in the future" in line and "clock" in line
    # a sitting merely early (stored end in the past) gets no such note
    from vasim.study.sitting_rule import early_sitting

    e = early_sitting(sitting=2, block="r", delay_days=1.0,
                      previous_ended_at="2026-11-27T10:00:00+00:00",
                      now="2026-11-27T12:00:00+00:00")
    assert e is not None and e.future_hint == ""
    f = early_sitting(sitting=2, block="r", delay_days=1.0,
                      previous_ended_at="2026-12-27T10:00:00+00:00",
                      now="2026-11-27T10:00:00+00:00")
    assert f is not None and "30 d 0 h in the future" in f.future_hint


def test_resume_after_the_protocol_file_changed_says_the_stored_one_runs(
        stopped_at_sitting: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    db = stopped_at_sitting
    proto = tmp_path / "tret.toml"
    resume = ["study", "resume", "--db", str(db), "--subject", "R1", "--protocol", str(proto),
              "--simulate-delay", "--no-progress"]
    proto.write_text(RETENTION.replace("max_trial_time_s = 0.05", "max_trial_time_s = 0.06"),
                     encoding="utf-8")
    code, out, err = _run(resume, capsys)
    assert code == 0, err
    assert f"note: {proto} has changed since session 1 started" in err
    assert "resumes with the protocol stored with it" in err
    assert "2/2 trials completed" in out


def test_resume_with_the_unchanged_protocol_file_has_no_note(
        stopped_at_sitting: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = _run(["study", "resume", "--db", str(stopped_at_sitting), "--subject", "R1",
                         "--protocol", str(tmp_path / "tret.toml"), "--simulate-delay",
                         "--no-progress"], capsys)
    assert code == 0, err
    assert "has changed" not in err


# -------------------------------------------------------- item 6: silent wrong values
BASE = 'name = "p"\ndescription = "d"\ntask = "trajectory"\n'


@pytest.mark.parametrize("variants, reps, stages, ok", [
    ("[1, 2]", 1, "[1.0, 0.75, 0.5, 0.25]", False),   # the issue: 4 stages on 2 trials
    ("[1, 2]", 1, "[1.0, 0.5, 0.25]", False),
    ("[1, 2]", 1, "[1.0, 0.5]", True),
    ("[1, 2]", 2, "[1.0, 0.75, 0.5, 0.25]", True),     # 4 trials
    ("[1]", 1, "[0.5]", True),
])
def test_a_gain_schedule_longer_than_its_block_is_refused(variants: str, reps: int,
                                                          stages: str, ok: bool) -> None:
    text = (BASE + f'[[blocks]]\nname = "f"\ncondition = "ff_faded"\nschema = "ff"\n'
            f"variants = {variants}\nrepetitions = {reps}\ngain_schedule = {stages}\n")
    if ok:
        parse_protocol(text, source="p.toml")
        return
    with pytest.raises(ConfigError) as info:
        parse_protocol(text, source="p.toml")
    assert info.value.field == "blocks[0].gain_schedule" and info.value.file == "p.toml"
    assert "would skip stages" in str(info.value)


def test_delay_days_on_the_first_block_is_refused() -> None:
    text = (BASE + '[[blocks]]\nname = "a"\ncondition = "none"\ndelay_days = 3.0\n'
            "counterbalance = false\n")
    with pytest.raises(ConfigError) as info:
        parse_protocol(text, source="p.toml")
    assert info.value.field == "blocks[0].delay_days" and "first block" in str(info.value)
    # on a later block it is a later sitting, as before
    later = text.replace('delay_days = 3.0\n', "") + (
        '[[blocks]]\nname = "b"\ncondition = "none"\ndelay_days = 3.0\n'
        "counterbalance = false\n")
    assert parse_protocol(later, source="p.toml").blocks[1].delay_days == 3.0


def test_effects_with_an_unknown_condition_label_is_refused(
        tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import vasim.study.power.driver as driver

    def no_ray(*_a: object, **_k: object) -> None:
        raise AssertionError("Ray must not start")

    monkeypatch.setattr(driver, "run_power", no_ray)
    eff = tmp_path / "e.toml"
    eff.write_text("[ff]\naccuracy = 0.8\n[f]\naccuracy = 0.7\n", encoding="utf-8")
    code, _, err = _run(["study", "power", "--protocol", "vf_learning_curve", "--subjects",
                         "4", "--cohorts", "1", "--effects", str(eff)], capsys)
    line = _one_line_error(err)
    assert code == 2
    assert f"{eff}: field 'f': got 'f', expected a condition of protocol" in line


@pytest.fixture
def small_db(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> Path:
    proto = tmp_path / "tiny.toml"
    proto.write_text(TINY, encoding="utf-8")
    db = tmp_path / "x.sqlite"
    assert _run(["study", "run", "--protocol", str(proto), "--db", str(db), "--subject", "E1",
                 "--no-progress"], capsys)[0] == 0
    return db


def test_export_tables_empty_is_refused(small_db: Path, tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    for tables in ("", " , "):
        code, _, err = _run(["study", "export", "--db", str(small_db), "--out",
                             str(tmp_path / "ex"), "--tables", tables, "--no-progress"], capsys)
        assert code == 2
        assert "field '--tables': got [], expected one or more of" in _one_line_error(err)
    assert not (tmp_path / "ex").exists()


@pytest.mark.parametrize("mode", [0o755, 0o750, 0o775])
def test_re_export_keeps_the_folder_mode(small_db: Path, tmp_path: Path, mode: int,
                                         capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "ex"
    out.mkdir()
    out.chmod(mode)
    argv = ["study", "export", "--db", str(small_db), "--out", str(out), "--tables",
            "sessions", "--no-progress"]
    for _ in range(2):
        assert _run(argv, capsys)[0] == 0
        assert stat.S_IMODE(out.stat().st_mode) == mode
    # a first export gets what mkdir gives under the umask, not a temporary folder's 0700
    fresh = tmp_path / "fresh"
    old = os.umask(0o022)
    try:
        assert _run([*argv[:5], str(fresh), *argv[6:]], capsys)[0] == 0
    finally:
        os.umask(old)
    assert stat.S_IMODE(fresh.stat().st_mode) == 0o755


def test_export_out_under_a_file_names_the_file(small_db: Path, tmp_path: Path,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    afile = tmp_path / "afile"
    afile.write_text("x")
    code, _, err = _run(["study", "export", "--db", str(small_db), "--out",
                         str(afile / "sub"), "--no-progress"], capsys)
    line = _one_line_error(err)
    assert code == 2 and f"{afile} is a file, not a folder" in line
    code, _, err = _run(["study", "export", "--db", str(small_db), "--out", str(afile),
                         "--no-progress"], capsys)
    assert code == 2 and str(afile) in _one_line_error(err)


@pytest.mark.parametrize("err_no, words", [
    (errno.ENOSPC, "No space left on device (the export needs room"),
    (errno.EACCES, "Permission denied (the export writes a new folder in"),
])
def test_export_file_system_errors_name_the_users_folder(
        small_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch, err_no: int, words: str) -> None:
    import vasim.study.export as export

    def failing(db: object, out_dir: Path, *_a: object) -> None:
        (out_dir / "samples.csv").write_text("partial")
        raise OSError(err_no, os.strerror(err_no), str(out_dir / "samples.csv"))

    monkeypatch.setattr(export, "_export_into", failing)
    out = tmp_path / "ex"
    code, _, err = _run(["study", "export", "--db", str(small_db), "--out", str(out),
                         "--no-progress"], capsys)
    line = _one_line_error(err)
    assert code == 2 and f"error: {out}: " in line and words in line
    assert ".tmp-" not in line
    assert not out.exists() and not list(tmp_path.glob(".ex.tmp-*"))


def test_export_read_only_parent_names_the_users_folder(
        small_db: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
        monkeypatch: pytest.MonkeyPatch) -> None:
    import tempfile

    def refused(prefix: str = "", dir: str | None = None, **_k: object) -> str:
        raise PermissionError(errno.EACCES, "Permission denied", f"{dir}/{prefix}abcd")

    monkeypatch.setattr(tempfile, "mkdtemp", refused)
    out = tmp_path / "ro" / "ex"
    (tmp_path / "ro").mkdir()
    code, _, err = _run(["study", "export", "--db", str(small_db), "--out", str(out),
                         "--no-progress"], capsys)
    line = _one_line_error(err)
    assert code == 2 and f"error: {out}: Permission denied" in line and ".tmp-" not in line
    assert f"new folder in {tmp_path / 'ro'}" in line


_FS_SCRIPT = """
set -e
mount -t tmpfs -o size=64k tmpfs "$SMALL"
mount --bind "$RO" "$RO" && mount -o remount,bind,ro "$RO"
"$PY" -m vasim study export --db "$DB" --out "$SMALL/ex" --no-progress || echo "rc=$?"
"$PY" -m vasim study export --db "$DB" --out "$RO/ex" --no-progress || echo "rc=$?"
"""


def test_a_real_full_disk_and_read_only_folder(small_db: Path, tmp_path: Path) -> None:
    """The real cases in a private mount namespace: a 64 kB tmpfs and a read-only bind
    mount (nothing outside the test changes)."""
    if shutil.which("unshare") is None or subprocess.run(
            ["unshare", "-rm", "true"], capture_output=True, check=False).returncode != 0:
        pytest.skip("needs unshare -rm (user + mount namespaces)")
    small, ro = tmp_path / "small", tmp_path / "ro"
    small.mkdir()
    ro.mkdir()
    env = dict(os.environ, SMALL=str(small), RO=str(ro), DB=str(small_db), PY=sys.executable)
    proc = subprocess.run(["unshare", "-rm", "sh", "-c", _FS_SCRIPT], env=env,
                          capture_output=True, text=True, timeout=900, check=False)
    assert proc.stdout.count("rc=2") == 2, (proc.stdout, proc.stderr[-2000:])
    errs = [ln for ln in proc.stderr.splitlines() if "error:" in ln]
    assert len(errs) == 2 and "Traceback" not in proc.stderr, proc.stderr[-2000:]
    assert f"error: {small / 'ex'}: No space left on device" in errs[0]
    assert f"error: {ro / 'ex'}: Read-only file system" in errs[1]
    assert ".tmp-" not in proc.stderr


# ------------------------------------------------------------ item 7: formula whitelist
@pytest.fixture
def long_csv(tmp_path: Path) -> Path:
    rng = np.random.default_rng(0)
    lines = ["subject,fixture,trial,error"]
    for s in range(8):
        for f in ("ff", "none"):
            for t in range(3):
                e = 1 + 0.3 * (f == "ff") + 0.1 * t + rng.normal(0, 0.2)
                lines.append(f"S{s},{f},{t},{e:.4f}")
    p = tmp_path / "mm.csv"
    p.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return p


@pytest.mark.parametrize("formula", [
    "error ~ I(__import__('os').system('touch PWNED'))",
    "error ~ I(__import__('os'))",
    "error ~ trial + exec('open(\"PWNED\", \"w\")')",
    "error ~ trial.__class__",
    "error ~ C(fixture, eval('1'))",
    "error ~ np.os.system('touch PWNED')",
    "error ~ trial[0]",
    "error ~ Q('__import__')",
    "error ~ trial; import os",
    "error ~ lambda: 0",
])
def test_formula_code_is_refused_before_patsy(long_csv: Path, tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str],
                                              monkeypatch: pytest.MonkeyPatch,
                                              formula: str) -> None:
    monkeypatch.chdir(tmp_path)
    import patsy

    evaluated: list[str] = []
    real_eval = patsy.EvalEnvironment.eval

    def spy(self: object, expr: str, *a: object, **k: object) -> object:
        evaluated.append(expr)       # (before the fix the code then ran: PWNED was made)
        return real_eval(self, expr, *a, **k)  # type: ignore[arg-type]

    monkeypatch.setattr(patsy.EvalEnvironment, "eval", spy)
    code, _, err = _run(["stats", "mixed-model", "--csv", str(long_csv), "--formula", formula,
                         "--groups", "subject"], capsys)
    assert not (tmp_path / "PWNED").exists()
    assert evaluated == []           # patsy never evaluated a term of a refused formula
    line = _one_line_error(err)
    assert code == 2 and "field 'formula'" in line and str(long_csv) in line


def test_whitelisted_formulas_still_fit(long_csv: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    for formula in ("error ~ C(fixture) + trial", "error ~ C(fixture, Treatment('none'))",
                    "error ~ C(fixture, Sum) * trial", "np.log(error) ~ center(trial)",
                    "error ~ I(trial ** 2) + Q('fixture') - 1"):
        code, out, err = _run(["stats", "mixed-model", "--csv", str(long_csv), "--formula",
                               formula, "--groups", "subject", "--json"], capsys)
        assert code == 0, (formula, err)
        assert '"fixed"' in out


def test_factors_must_be_columns_of_the_file_and_formula(
        long_csv: Path, capsys: pytest.CaptureFixture[str]) -> None:
    base = ["stats", "mixed-model", "--csv", str(long_csv), "--formula",
            "error ~ C(fixture) + trial", "--groups", "subject"]
    code, _, err = _run([*base, "--factors", "nope"], capsys)
    line = _one_line_error(err)
    assert code == 2 and "field '--factors': got 'nope', expected a column of the file" in line
    code, _, err = _run([*base, "--factors", "fixture,subject"], capsys)
    assert code == 2 and "a column the formula" in _one_line_error(err)
    assert _run([*base, "--factors", "fixture"], capsys)[0] == 0


_COLS = ["y", "x", "f", "a b"]
_SAFE = st.sampled_from(["x", "f", "C(f)", "np.log(x)", "I(x ** 2)", "Q('a b')", "center(x)",
                         "C(f, Treatment('u'))", "C(f, Sum)", "(x + f)", "1", "0"])
_OPS = st.sampled_from([" + ", " - ", " * ", ":", " / "])


@settings(max_examples=200, deadline=None)
@given(terms=st.lists(_SAFE, min_size=1, max_size=5), ops=st.lists(_OPS, min_size=4,
                                                                    max_size=4),
       junk=st.text(min_size=1, max_size=12))
def test_formula_whitelist_property(terms: list[str], ops: list[str], junk: str) -> None:
    """Formulas of whitelisted pieces pass; the same formula with any other name inserted
    (a random identifier not a column or transform) is refused."""
    from vasim.study.stats.mixed_model import KEYWORDS, TRANSFORMS, check_formula

    rhs = terms[0] + "".join(o + t for o, t in zip(ops, terms[1:], strict=False))
    check_formula(f"y ~ {rhs}", _COLS)
    name = "z" + "".join(c for c in junk if c.isalnum() and c.isascii())
    if name in _COLS or name in TRANSFORMS or name in KEYWORDS:
        return
    with pytest.raises(ConfigError):
        check_formula(f"y ~ {rhs} + {name}", _COLS)
    with pytest.raises(ConfigError):
        check_formula(f"y ~ {rhs} + {name}(x)", _COLS)


# ------------------------------------------------------------- item 4: --address
@pytest.mark.parametrize("address, words", [
    ("", "expected a Ray address"),
    ("127.0.0.1:99999", "expected a port in 1-65535"),
    ("127.0.0.1", "expected a Ray address"),
    ("x" * 10_000 + ":1", "(10,002 characters)"),
    ("bad_host!:6379", "expected an IP address or a host name"),
    ("::1:6379", "expected a Ray address"),
])
def test_bad_address_syntax_is_refused_at_parse(address: str, words: str,
                                                capsys: pytest.CaptureFixture[str]) -> None:
    code, _, err = _run(["study", "power", "--protocol", "vf_learning_curve", "--subjects",
                         "4", "--cohorts", "1", "--address", address], capsys)
    line = _one_line_error(err)
    assert code == 2 and "argument --address" in line and words in line
    assert len(line) < 600


def test_parse_ray_address_forms() -> None:
    from vasim.study.power.driver import parse_ray_address

    assert parse_ray_address("auto") is None
    assert parse_ray_address("ray://head.example.org:10001") == ("head.example.org", 10001)
    assert parse_ray_address("10.0.0.5:6379") == ("10.0.0.5", 6379)
    assert parse_ray_address("[::1]:1") == ("::1", 1)
    for bad in ("999.1.1.1:1", "h:0", "ray://h", "h:6379/x", "[::1]", "h:-1"):
        with pytest.raises(InputError):   # a command-line argument (issue #29)
            parse_ray_address(bad)


def _stop(srv: socket.socket, t: threading.Thread, conns: list[socket.socket]) -> None:
    """Ends a listener: shutdown wakes its blocked accept() (close alone does not)."""
    try:
        srv.shutdown(socket.SHUT_RDWR)
    except OSError:
        pass
    srv.close()
    t.join(5)
    for c in conns:
        c.close()


@pytest.fixture
def silent_server() -> Iterator[int]:
    srv, t, conns = tcp_listener(None)
    yield srv.getsockname()[1]
    _stop(srv, t, conns)


@pytest.fixture
def http_server() -> Iterator[int]:
    srv, t, conns = tcp_listener(b"HTTP/1.1 400 Bad Request\r\n\r\n")
    yield srv.getsockname()[1]
    _stop(srv, t, conns)


def test_unreachable_addresses_fail_within_seconds(silent_server: int, http_server: int,
                                                   monkeypatch: pytest.MonkeyPatch) -> None:
    from vasim.study.power.driver import ADDRESS_CHECK_S, init_ray

    monkeypatch.setenv("RAY_CLIENT_MODE", "")   # Ray's client sets it: undone after the test
    monkeypatch.delenv("RAY_CLIENT_MODE")

    free = socket.socket()
    free.bind(("127.0.0.1", 0))
    closed_port = free.getsockname()[1]
    free.close()
    cases = [(f"127.0.0.1:{closed_port}", "Connection refused"),
             (f"[::1]:{closed_port}", "cannot reach the Ray cluster"),
             (f"127.0.0.1:{silent_server}", f"no answer within {ADDRESS_CHECK_S:g} s"),
             (f"127.0.0.1:{http_server}", "not a Ray head"),        # HTTP/1.1, not gRPC
             ("no-such-host.invalid:6379", "cannot reach the Ray cluster")]
    for address, words in cases:
        t0 = time.monotonic()
        with pytest.raises(ConfigError) as info:
            init_ray(address, None)
        took = time.monotonic() - t0
        assert info.value.field == "--address" and words in str(info.value), (address, info)
        assert took < 30, (address, took)   # seconds, not Ray's minutes of retrying


def test_init_in_thread_times_out_and_passes_errors() -> None:
    from vasim.study.power.ray_join import _init_in_thread

    release = threading.Event()      # the hung "join" ends with the test (no thread left)
    try:
        with pytest.raises(ConfigError, match=r"did not answer within 0\.5 s"):
            _init_in_thread(lambda: release.wait(30), 0.5, "the Ray cluster 'x'")
    finally:
        release.set()

    def boom() -> None:
        raise ConnectionError("no")

    with pytest.raises(ConnectionError):
        _init_in_thread(boom, 5.0, "x")


_SETTINGS_FRAME = bytes([0, 0, 0, 4, 0, 0, 0, 0, 0])


@pytest.mark.parametrize("sig", ["SIGTERM", "SIGINT"])
def test_a_join_that_hangs_stops_on_sigterm_and_ctrl_c(sig: str) -> None:
    """A server that answers the HTTP/2 preface but is no Ray head: Ray's client retries
    for minutes; SIGTERM / SIGINT end the command within seconds (exit 130)."""
    import signal

    srv, t, conns = tcp_listener(_SETTINGS_FRAME)
    port = srv.getsockname()[1]
    try:
        proc = subprocess.Popen(
            [sys.executable, "-m", "vasim", "study", "power", "--protocol",
             "vf_learning_curve", "--subjects", "4", "--cohorts", "1", "--address",
             f"127.0.0.1:{port}"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
            # Ctrl-C as at a terminal: a shell's background job (how CI or a developer may
            # start pytest) inherits SIGINT ignored, and Python then keeps it ignored
            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
        end = time.monotonic() + 240
        while not conns and time.monotonic() < end and proc.poll() is None:
            time.sleep(0.2)        # the address check connected: Ray is being joined next
        assert proc.poll() is None, proc.communicate()
        time.sleep(3.0)
        t0 = time.monotonic()
        proc.send_signal(getattr(signal, sig))
        _, err = proc.communicate(timeout=120)
        took = time.monotonic() - t0
    finally:
        _stop(srv, t, conns)
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, err[-2000:]
    assert "interrupted" in err and "Traceback" not in err
    assert took < 30, took


@pytest.mark.parametrize("command", [
    ["study", "export", "--db", "x.sqlite"],
    ["study", "power", "--protocol", "vf_learning_curve", "--subjects", "4", "--cohorts", "1"],
    ["report", "--db", "x.sqlite"],
])
def test_every_out_naming_a_file_is_refused_at_parse(
        command: list[str], tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    """Issue #30 item 8: `--out afile` said only "afile: File exists"."""
    afile = tmp_path / "afile"
    afile.write_text("x")
    for out in (afile, afile / "sub" / "deeper"):
        code, _, err = _run([*command, "--out", str(out)], capsys)
        line = _one_line_error(err)
        assert code == 2 and "argument --out" in line
        assert f"{afile} is a file, not a folder" in line
