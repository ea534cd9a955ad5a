"""A damaged result store: one clear line from every command, the daemon keeps what can be read and runs on."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from service.cli import main
from service.persistence.store import DB_NAME, Store
from tests.service.conftest import appliance_doc

PAGE = 4096


def fill(state: Path, n: int = 30) -> None:
    """n measurements with a 1,000-sample trace each, all still in the outbox."""
    with Store(state) as s:
        for i in range(n):
            t = np.linspace(0.0, 5.0, 1000)
            s.record(status="ok", trigger="button", device_id="test-rig", software_version="t", started_at=1e9 + i,
                     finished_at=1e9 + i + 1, result={"J": 0.01 + i * 1e-5, "flags": []},
                     build_payload=lambda u, q: {"uuid": u, "seq": q, "J": 0.01, "timestamp": 1e9 + q},
                     trace_t=t, trace_angle=np.sin(t * (i + 1)), enqueue={"mqtt": ("result",)})


def damaged_copy(src: Path, dest: Path, page: int) -> Path:
    dest.mkdir(parents=True)
    shutil.copy(src / DB_NAME, dest / DB_NAME)
    with open(dest / DB_NAME, "r+b") as f:
        f.seek(page * PAGE)
        f.write(b"\xff" * PAGE)
    return dest


def first_damage(tmp_path: Path, breaks) -> Path:
    """A copy of a 30-measurement store with one page overwritten, the last page (from the end) for
    which ``breaks(store_dir)`` is true: the damage a reading command meets."""
    good = tmp_path / "good"
    fill(good)
    pages = (good / DB_NAME).stat().st_size // PAGE
    for page in range(pages - 1, 0, -1):
        d = damaged_copy(good, tmp_path / f"damaged-{page}", page)
        if breaks(d):
            return d
        shutil.rmtree(d)
    raise AssertionError("no page whose damage shows")


def _fails(fn) -> bool:
    try:
        fn()
    except Exception:
        return True
    return False


def starting_reads_fail(d: Path) -> bool:
    def reads():
        with Store(d) as s:
            s.latest("ok")
            s.outbox_count()
    return _fails(reads)


def trace_read_fails(d: Path) -> bool:
    def reads():
        with Store(d) as s:
            for m in s.list(None):
                s.get(m.uuid, trace=True)
    return not starting_reads_fail(d) and _fails(reads)


def test_the_daemon_moves_a_damaged_store_aside_keeps_what_it_can_read_and_runs(tmp_path, appliance_factory, caplog):
    state = first_damage(tmp_path, starting_reads_fail)
    app = appliance_factory(appliance_doc(state))  # started: no traceback, no restart loop
    aside = list(state.glob(f"{DB_NAME}.damaged-*"))
    assert [p.name for p in aside if not p.name.endswith(("-wal", "-shm"))], "the damaged file was not kept"
    assert "moved to" in caplog.text and "readable:" in caplog.text
    salvaged = app.app.store.list(None)
    assert len(salvaged) >= 20 and app.app.store.outbox_count() == len(salvaged)
    app.press()
    app.wait_done(1)
    newest = app.app.store.latest("ok")
    assert newest.seq > max(m.seq for m in salvaged)  # a number is never reused
    assert app.stop() == 0


def test_reading_commands_on_a_damaged_store_print_one_line_and_exit_2(tmp_path, capsys):
    state = first_damage(tmp_path, trace_read_fails)
    with Store(state) as s:
        broken = next(m for m in s.list(None) if _fails(lambda: s.get(m.uuid, trace=True)))
    assert main(["export", "--state-dir", str(state), "--trace", broken.uuid, "--out", str(tmp_path / "t.csv")]) == 2
    err = capsys.readouterr().err
    assert len(err.strip().splitlines()) == 1 and "damaged" in err and "moi store check" in err

    assert main(["store", "check", "--state-dir", str(state)]) == 2
    out = capsys.readouterr().out
    assert "damaged" in out and "readable: 30 measurements" in out and "trace not readable" in out

    assert main(["store", "salvage", "--state-dir", str(state), "--out", str(tmp_path / "new")]) == 0
    with Store(tmp_path / "new") as s:
        assert s.count() == 30 and s.outbox_count() == 30
        assert s.get(broken.uuid, trace=True).trace_t is None  # kept, without the trace it lost
    assert main(["store", "check", "--state-dir", str(tmp_path / "new")]) == 0


def test_an_intact_store_checks_ok(tmp_path, capsys):
    fill(tmp_path / "s", 3)
    assert main(["store", "check", "--state-dir", str(tmp_path / "s")]) == 0
    assert "intact" in capsys.readouterr().out


@pytest.fixture
def read_only_store(tmp_path):
    """A store this process may only read: mode 0555/0444, or for root (whom modes do not stop) the
    immutable attribute; skipped where neither is possible."""
    import os
    import subprocess

    d = tmp_path / "ro"
    fill(d, 3)
    paths = [d / DB_NAME, d]
    if os.geteuid() != 0:
        (d / DB_NAME).chmod(0o444)
        d.chmod(0o555)
        yield d
        d.chmod(0o755)
        return
    if subprocess.run(["chattr", "+i", *map(str, paths)], capture_output=True).returncode != 0:
        pytest.skip("cannot make the store read-only here (chattr +i refused)")
    try:
        yield d
    finally:
        subprocess.run(["chattr", "-i", *map(str, paths)], capture_output=True)


def test_reading_commands_work_on_a_read_only_store(read_only_store, tmp_path, capsys):
    assert main(["results", "--state-dir", str(read_only_store)]) == 0
    assert len([line for line in capsys.readouterr().out.splitlines() if "button" in line]) == 3
    assert main(["export", "--state-dir", str(read_only_store), "--format", "json",
                 "--out", str(tmp_path / "all.json")]) == 0
    assert main(["store", "check", "--state-dir", str(read_only_store)]) == 0


def test_a_text_that_no_longer_decodes_is_damage():
    """The store writes only UTF-8: a text column that does not decode (the tail of a row, after its trace's blobs,
    on an overwritten overflow page) is the file's damage, said with what to do, not an unexplained error."""
    import sqlite3

    from service.persistence.connection import is_damage

    assert is_damage(sqlite3.OperationalError("Could not decode to UTF-8 column 'part_id' with text '\ufffd\ufffd'"))
    assert not is_damage(sqlite3.OperationalError("no such column: operator"))
