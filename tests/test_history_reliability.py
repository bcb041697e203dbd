"""The history under kill -9, concurrent processes, damaged files and read-only places.

Real processes (``history_child.py``), real SQLite files and a real
PostgreSQL server; nothing is mocked.
"""

import dataclasses
import json
import os
import pwd
import random
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pg_server
import pytest
from history_child import MACHINE, index_of, run_for

from imu_square.errors import HistoryError
from imu_square.monitor.history import schema
from imu_square.monitor.history.store import open_history

CHILD = Path(__file__).with_name("history_child.py")
# SIGKILLs per backend: at least 50 on SQLite (issue 11); a killed PostgreSQL
# client is rolled back by the server, and each kill costs a psycopg import.
KILLS = {"sqlite": 50, "postgresql": 25}


@pytest.fixture(params=["sqlite", "postgresql"])
def location(request, tmp_path):
    return pg_server.location_for(request.param, tmp_path)


def _child(*args, env=None):
    return subprocess.Popen(
        [sys.executable, str(CHILD), *map(str, args)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        env=env,
    )


def _committed(text):
    """index -> run id from a child's ``committed i:id ...`` lines (whole lines only)."""
    out = {}
    for line in text.splitlines(keepends=True):
        if line.startswith("committed ") and line.endswith("\n"):
            for pair in line.split()[1:]:
                index, run_id = pair.split(":")
                out[int(index)] = int(run_id)
    return out


@pytest.mark.slow
def test_kill_9_in_the_middle_of_writes_loses_no_committed_run(location):
    rng = random.Random(11)
    kills = KILLS["postgresql" if location.startswith("postgresql:") else "sqlite"]
    reported, batches, last_begin = {}, {}, {}
    for k in range(kills):
        first, batch = k * 10_000, rng.randint(1, 4)
        batches[first] = batch
        child = _child("writer", location, first, batch)
        assert child.stdout.readline() == "ready\n", child.stderr.read()
        time.sleep(rng.uniform(0.0, 0.08))  # a random point of the write loop
        child.kill()
        child.wait()
        assert child.returncode == -9, child.stderr.read()
        out = child.stdout.read()
        reported |= _committed(out)
        lines = out.splitlines()
        if lines and lines[-1].startswith("begin "):  # killed after BEGIN, before the report
            last_begin[first] = int(lines[-1].split()[1])
        child.stdout.close()
        child.stderr.close()

    with open_history(location) as h:  # quick_check on open
        if h.backend == "sqlite":
            assert h._db.query("PRAGMA integrity_check") == [("ok",)]
        stored = {index_of(r): r for r in h.runs(MACHINE)}
        verdicts = {e.run_id: e for e in h.evaluations(MACHINE)}
    # Every run reported as committed is there, with its id.
    assert {i: stored[i].id for i in reported if i in stored} == reported
    # No partial row: every stored run is whole, with the verdict of its transaction.
    for i, row in stored.items():
        assert row == dataclasses.replace(run_for(i), id=row.id)
        assert verdicts[row.id].statistics == {"i": i}
    assert len(verdicts) == len(stored)
    # Each child's transactions landed whole and in order: a prefix of whole batches.
    for first, batch in batches.items():
        mine = sorted(i - first for i in stored if first <= i < first + 10_000)
        assert mine == list(range(len(mine))) and len(mine) % batch == 0
    # Where the kills fell: inside a transaction (rolled back), or after its COMMIT
    # before the report (kept), or between transactions.
    inside = sum(1 for i in last_begin.values() if i not in stored)
    after_commit = len(last_begin) - inside
    assert len(reported) >= kills and inside >= 1
    print(
        f"\nkill -9 x{kills} ({location.split('?')[0]}): {len(reported)} runs reported "
        f"committed, {len(stored)} stored and verified; kills inside a transaction {inside}, "
        f"after a commit before its report {after_commit}, between transactions "
        f"{kills - len(last_begin)}"
    )


def test_processes_writing_at_once_all_land_and_one_recording_stays_one_row(location, tmp_path):
    go = tmp_path / "go"
    env = {**os.environ, "GO": str(go)}
    count, shared = 40, 999_999
    procs = [_child("race", location, k * 1000, count, shared, env=env) for k in range(3)]
    for p in procs:
        assert p.stdout.readline() == "ready\n", p.stderr.read()
    go.touch()
    outs = []
    for p in procs:
        out, err = p.communicate(timeout=120)
        assert p.returncode == 0, err
        outs.append(json.loads(out))
    shared_results = [tuple(r) for o in outs for r in o["shared"]]
    # The same recording raced 3 x 40 times: one row, inserted exactly once.
    assert len({run_id for run_id, _ in shared_results}) == 1
    assert sum(inserted for _, inserted in shared_results) == 1
    own = {int(i): tuple(r) for o in outs for i, r in o["runs"].items()}
    assert all(inserted for _, inserted in own.values())
    with open_history(location) as h:
        stored = {index_of(r): r for r in h.runs(MACHINE)}
    assert len(stored) == 3 * count + 1
    assert {i: stored[i].id for i in own} == {i: run_id for i, (run_id, _) in own.items()}
    for i, row in stored.items():
        assert row == dataclasses.replace(run_for(i), id=row.id)


def _hold_and_add(location, tmp_path, index, timeout_s, hold_s):
    """Process A holds a transaction that added run ``index``; process B adds it too.

    Returns B's report and A's.
    """
    go, release = tmp_path / "go", tmp_path / "release"
    holder = _child("hold", location, index, release)
    assert holder.stdout.readline() == "holding\n", holder.stderr.read()
    adder = _child("add", location, index, timeout_s, env={**os.environ, "GO": str(go)})
    assert adder.stdout.readline() == "ready\n", adder.stderr.read()
    go.touch()
    time.sleep(hold_s)
    release.touch()
    out, _ = adder.communicate(timeout=60)
    held, _ = holder.communicate(timeout=60)
    return out, held


def test_a_writer_waits_for_another_processes_transaction(location, tmp_path):
    out, held = _hold_and_add(location, tmp_path, 5, timeout_s=30, hold_s=0.8)
    got = json.loads(out)
    # It waited for the holder's commit, then found the holder's row.
    assert got["inserted"] is False
    assert got["id"] == _committed(held)[5]
    assert got["elapsed_s"] > 0.6


def test_a_writer_held_up_beyond_the_busy_timeout_fails_with_one_line(location, tmp_path):
    out, held = _hold_and_add(location, tmp_path, 6, timeout_s=0.3, hold_s=1.0)
    assert out.startswith("error history ") and out.count("\n") == 1
    assert "another process held" in out and "for more than 0.3 s" in out
    with open_history(location) as h:  # the holder's run landed
        assert [r.id for r in h.runs(MACHINE)] == [_committed(held)[6]]


def test_a_write_that_times_out_inside_a_transaction_is_undone_alone(tmp_path):
    """PostgreSQL locks rows, so a transaction meets another's lock mid-way."""
    location = pg_server.location_for("postgresql", tmp_path)
    release = tmp_path / "release"
    holder = _child("hold", location, 5, release)
    assert holder.stdout.readline() == "holding\n", holder.stderr.read()
    try:
        with open_history(location, busy_timeout_s=0.3) as h:
            with h.transaction():
                h.add_run(run_for(4))
                with pytest.raises(HistoryError, match="another process held a lock"):
                    h.add_run(run_for(5))  # the holder's uncommitted recording
                h.add_run(run_for(6))
            release.touch()
            holder.communicate(timeout=60)
            assert [index_of(r) for r in h.runs(MACHINE)] == [4, 5, 6]
    finally:
        release.touch()
        holder.wait(60)


# --- SQLite files ---


def _filled(tmp_path, n=300):
    path = tmp_path / "history.db"
    with open_history(path) as h, h.transaction():
        for i in range(n):
            h.add_run(run_for(i))
    assert not Path(f"{path}-wal").exists()  # checkpointed on close: all in the .db
    return path


def _refused(path):
    with pytest.raises(HistoryError) as err:
        open_history(path)
    text = str(err.value)
    assert text.startswith(f"history {path}: ") and "\n" not in text
    return text


def test_a_damaged_page_is_one_line(tmp_path):
    path = _filled(tmp_path)
    data = bytearray(path.read_bytes())
    page = int.from_bytes(data[16:18], "big")
    rng = random.Random(3)
    at = page * (len(data) // page // 2)  # one page in the middle of the runs' tree
    data[at + 8 : at + page] = bytes(rng.randrange(256) for _ in range(page - 8))
    path.write_bytes(bytes(data))
    assert "the database is damaged" in _refused(path)


def test_a_truncated_file_is_one_line(tmp_path):
    path = _filled(tmp_path)
    data = path.read_bytes()
    path.write_bytes(data[: len(data) // 2])
    assert "the database is damaged" in _refused(path)


def test_a_file_that_is_not_a_database_is_one_line(tmp_path):
    path = tmp_path / "history.db"
    path.write_text("time_s,accel_x,accel_y,accel_z\n" * 500)
    assert _refused(path).endswith(": not a SQLite database")


def test_an_empty_file_becomes_a_history(tmp_path):
    path = tmp_path / "history.db"
    path.touch()
    with open_history(path) as h:
        assert h.schema_version == schema.latest_version() and h.add_run(run_for(1))[1]


def test_a_read_only_location_is_one_line(tmp_path):
    # Root writes anywhere; the check runs as an ordinary user then.
    user = {}
    root = tmp_path
    if os.geteuid() == 0:
        user = {"user": "nobody", "group": pwd.getpwnam("nobody").pw_gid, "extra_groups": []}
        root = Path(tempfile.mkdtemp(prefix="imu-square-ro-"))
        root.chmod(0o755)
    try:
        folder = root / "ro"
        folder.mkdir()
        with open_history(folder / "old.db") as h:  # a history made while it was writable
            h.add_run(run_for(1))
        folder.chmod(0o555)
        code = (
            "import sys\n"
            "from imu_square.errors import HistoryError\n"
            "from imu_square.monitor.history.store import open_history\n"
            "for name in sys.argv[1:]:\n"
            "    try:\n"
            "        open_history(name)\n"
            "    except HistoryError as exc:\n"
            "        print(exc)\n"
        )
        done = subprocess.run(
            [sys.executable, "-c", code, str(folder / "new.db"), str(folder / "sub" / "new.db"),
             str(folder / "old.db")],
            capture_output=True, text=True, timeout=60, check=False, cwd="/", **user,
        )  # fmt: skip
        assert done.returncode == 0, done.stderr
        lines = done.stdout.splitlines()
        assert lines == [
            f"history {folder / 'new.db'}: cannot open it for writing (unable to open database "
            "file): is the location read-only?",
            f"history {folder / 'sub' / 'new.db'}: cannot create its folder: Permission denied",
            lines[2],
        ]
        assert lines[2].startswith(f"history {folder / 'old.db'}: cannot open it for writing (")
    finally:
        (root / "ro").chmod(0o755)
        if root != tmp_path:
            shutil.rmtree(root)


def test_a_backup_taken_while_the_wal_holds_the_runs_has_every_committed_run(tmp_path):
    path = tmp_path / "history.db"
    with open_history(path) as h:
        ids = [h.add_run(run_for(i))[0] for i in range(40)]
        wal = Path(f"{path}-wal")
        assert wal.stat().st_size > 0  # the runs are in the WAL, not yet in the .db
        # A plain copy of the .db without its -wal loses them.
        shutil.copy(path, tmp_path / "plain-copy.db")
        plain = sqlite3.connect(tmp_path / "plain-copy.db")
        try:
            count = plain.execute("SELECT COUNT(*) FROM runs").fetchone()[0]
        except sqlite3.OperationalError:  # not even the table made it
            count = 0
        plain.close()
        assert count < 40
        # Another process holds a transaction open with a run not yet committed.
        holder = _child("hold", path, 40, tmp_path / "release")
        assert holder.stdout.readline() == "holding\n", holder.stderr.read()
        dest = h.backup(tmp_path / "backup.db")
        (tmp_path / "release").touch()
        held, _ = holder.communicate(timeout=60)
        assert _committed(held)
        expected = h.runs(MACHINE)[:40]
    assert [r.id for r in expected] == ids
    assert not Path(f"{dest}-wal").exists()
    with sqlite3.connect(dest) as check:
        assert check.execute("PRAGMA journal_mode").fetchone() == ("delete",)
    with open_history(dest) as copy:
        assert copy.runs(MACHINE) == expected  # every committed run, not the uncommitted one


def test_a_backup_onto_the_history_itself_is_refused(tmp_path):
    path = tmp_path / "history.db"
    with open_history(path) as h, pytest.raises(HistoryError, match="is the history itself"):
        h.backup(path)
