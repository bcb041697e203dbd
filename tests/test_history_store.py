"""The history's API on both backends: a real SQLite file and a real PostgreSQL server.

Every test here runs twice, once per backend (fixture ``location``); the
PostgreSQL server is a throw-away one (``pg_server.py``).
"""

import dataclasses
import hashlib
import itertools
import json
import subprocess
import sys
from datetime import UTC, datetime, timedelta

import numpy as np
import pg_server
import pytest
from history_child import MACHINE, SETTINGS, index_of, run_for
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from imu_square.errors import HistoryError, ImuSquareError
from imu_square.monitor.history import store
from imu_square.monitor.history.encoding import (
    canonical_json,
    datetime_from_ns,
    file_sha256,
    ns_from_datetime,
    settings_hash,
)
from imu_square.monitor.history.rows import (
    EVALUATION_STATES,
    RUN_FLOAT_FIELDS,
    AnchorRow,
    BaselineRow,
    EvaluationRow,
)
from imu_square.monitor.history.sql import Params
from imu_square.monitor.history.store import default_history_path, open_history

HOUR_NS = 3600 * 10**9


@pytest.fixture(params=["sqlite", "postgresql"])
def location(request, tmp_path):
    return pg_server.location_for(request.param, tmp_path)


@pytest.fixture
def history(location):
    with open_history(location) as h:
        yield h


def stored_as(row, stored):
    """``row`` as the store gives it back: with the id and stamps the store filled in."""
    return dataclasses.replace(row, id=stored.id, analysed_at_ns=stored.analysed_at_ns)


def test_a_run_reads_back_exactly_as_stored(history):
    row = dataclasses.replace(
        run_for(5),
        u_squareness_bootstrap_rad=np.float64("nan"),  # bootstrap skipped: NULL
        dof=np.int64(14),
        squareness_rad=np.float64(1.2345678901234567e-5),
        per_cycle={"squareness_rad": np.array([1e-5, np.nan, -2.5e-300]), "n": np.int32(3)},
        quality={"flags": ("a", "b"), "ratio": np.float32(0.5), 3: None},
        result={"nested": {"deep": [1, 2.5, "µm/m", None, True]}},
    )
    run_id, inserted = history.add_run(row)
    assert inserted and run_id >= 1
    got = history.run(run_id)
    # Normalised once at construction, the row is then stored and read back bit for bit.
    assert got == dataclasses.replace(row, id=run_id)
    assert got.u_squareness_bootstrap_rad is None
    assert got.dof == 14.0 and isinstance(got.dof, float)
    assert got.per_cycle == {"squareness_rad": [1e-5, None, -2.5e-300], "n": 3}
    assert got.quality == {"flags": ["a", "b"], "ratio": 0.5, "3": None}
    assert got.warnings == ("warning of run 5 with µm/m",)
    assert got.settings_hash == settings_hash(SETTINGS)
    assert got.recorded_at == datetime(2026, 9, 21, 14, 13, 20, tzinfo=UTC) + timedelta(hours=5)


_ANY_TEXT = st.text(st.characters(exclude_categories=()), max_size=12)  # NUL, surrogates too
_JSON = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(min_value=-(2**70), max_value=2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | _ANY_TEXT,
    lambda inner: st.lists(inner, max_size=4) | st.dictionaries(_ANY_TEXT, inner, max_size=4),
    max_leaves=16,
)
_UNIQUE = itertools.count(1_000_000)


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    numbers=st.lists(
        st.floats(allow_nan=True, allow_infinity=True), min_size=len(RUN_FLOAT_FIELDS)
    ).map(tuple),
    blob=_JSON,
    word=_ANY_TEXT,
)
def test_any_numbers_and_json_read_back_bit_for_bit(history, numbers, blob, word):
    fields = dict(zip(RUN_FLOAT_FIELDS, numbers, strict=False))
    row = dataclasses.replace(
        run_for(next(_UNIQUE)),
        valid=False,
        invalid_reason="any numbers",
        result={"blob": blob},
        quality={word: blob},
        warnings=[word],
        **fields,
    )
    got = history.run(history.add_run(row)[0])
    assert got == dataclasses.replace(row, id=got.id)
    # Floats bit for bit: NaN is None (NULL), -0.0 is 0.0, the rest exactly as given.
    for name, x in fields.items():
        want = None if x != x else x + 0.0
        assert repr(getattr(got, name)) == repr(want), name
    assert canonical_json(got.result) == canonical_json({"blob": blob})
    assert got.warnings == (word,)


def test_analysed_at_is_stamped_when_not_given(history):
    before = ns_from_datetime(datetime.now(UTC))
    run_id, _ = history.add_run(dataclasses.replace(run_for(1), analysed_at_ns=None))
    after = ns_from_datetime(datetime.now(UTC))
    assert before <= history.run(run_id).analysed_at_ns <= after


def test_the_same_recording_under_the_same_settings_is_one_row(history):
    first, inserted = history.add_run(run_for(1))
    assert inserted
    # Same machine, recording and settings: the first row stays, whatever else differs.
    again = dataclasses.replace(run_for(1), squareness_rad=9e-3, software_version="9.9")
    assert history.add_run(again) == (first, False)
    assert history.run(first).squareness_rad == run_for(1).squareness_rad
    # Other settings, or another machine: a new row.
    other_settings = dataclasses.replace(run_for(1), settings={**SETTINGS, "cutoff_hz": 3.0})
    other_settings = dataclasses.replace(other_settings, settings_hash=None)
    second, inserted = history.add_run(other_settings)
    assert inserted and second != first
    third, inserted = history.add_run(run_for(1, machine="lathe-2"))
    assert inserted and third not in (first, second)
    assert len(history.runs(MACHINE)) == 2
    found = history.run_by_hash(MACHINE, run_for(1).recording_sha256, settings_hash(SETTINGS))
    assert found.id == first
    assert history.run_by_hash(MACHINE, "0" * 64, settings_hash(SETTINGS)) is None
    assert history.recording_hashes(MACHINE) == {run_for(1).recording_sha256}
    assert history.recording_hashes(MACHINE, settings_hash=settings_hash(SETTINGS)) == {
        run_for(1).recording_sha256
    }
    assert history.recording_hashes(MACHINE, settings_hash="0" * 64) == set()


def test_runs_come_in_recording_order_and_filter(history):
    order = [4, 1, 3, 0, 2, 6, 5, 10]  # 3 and 10 are invalid (index % 7 == 3)
    ids = {i: history.add_run(run_for(i))[0] for i in order}
    unknown = dataclasses.replace(run_for(20), recorded_at_ns=None, valid=False, invalid_reason="x")
    ids[20] = history.add_run(unknown)[0]
    history.add_run(run_for(7, machine="other"))
    got = history.runs(MACHINE)
    assert [index_of(r) for r in got] == [0, 1, 2, 3, 4, 5, 6, 10, 20]  # unknown time last
    assert [r.id for r in got] == [ids[i] for i in [0, 1, 2, 3, 4, 5, 6, 10, 20]]
    t = run_for(2).recorded_at_ns
    # Half-open: since <= t < until, in nanoseconds or as aware datetimes.
    assert [index_of(r) for r in history.runs(MACHINE, since=t, until=t + 3 * HOUR_NS)] == [2, 3, 4]
    assert [index_of(r) for r in history.runs(MACHINE, since=datetime_from_ns(t + HOUR_NS))] == [
        3, 4, 5, 6, 10,
    ]  # fmt: skip
    assert [index_of(r) for r in history.runs(MACHINE, until=datetime_from_ns(t))] == [0, 1]
    assert [index_of(r) for r in history.runs(MACHINE, valid_only=True)] == [0, 1, 2, 4, 5, 6]
    assert history.runs(MACHINE, settings_hash="f" * 64) == []
    assert len(history.runs(MACHINE, settings_hash=settings_hash(SETTINGS))) == 9
    assert history.machines() == [MACHINE, "other"]
    with pytest.raises(HistoryError, match="since must be integer nanoseconds"):
        history.runs(MACHINE, since="2026-01-01")
    with pytest.raises(HistoryError, match="with its time zone"):
        history.runs(MACHINE, since=datetime(2026, 1, 1))
    with pytest.raises(HistoryError, match="no run 999"):
        history.run(999)


def _baseline(run_ids, **kw):
    return BaselineRow(
        machine_id=MACHINE,
        run_ids=run_ids,
        squareness_mean_rad=1.2e-5,
        squareness_sd_rad=2e-6,
        u_squareness_mean_rad=1.1e-6,
        eps_c_rad=0.0366,
        u_eps_c_rad=5e-5,
        dof=2,
        **kw,
    )


def test_a_baseline_is_set_from_valid_runs_and_the_latest_is_current(history):
    ids = [history.add_run(run_for(i))[0] for i in range(7)]  # run 3 is invalid
    assert history.current_baseline(MACHINE) is None
    first = history.add_baseline(_baseline([ids[2], ids[0], ids[1]], note="set up"))
    got = history.current_baseline(MACHINE)
    assert got.id == first and got.run_ids == tuple(sorted(ids[:3]))
    assert got.first_run_at_ns == run_for(0).recorded_at_ns
    assert got.last_run_at_ns == run_for(2).recorded_at_ns
    assert got.settings_hash == settings_hash(SETTINGS)
    assert (got.squareness_mean_rad, got.dof, got.note, got.stale) == (1.2e-5, 2.0, "set up", False)
    assert got.created_at_ns is not None
    # Stale: once, with its first reason; it stays current until a new one is set.
    assert history.mark_baseline_stale(first, "the sensor was remounted:\nset a new baseline")
    assert not history.mark_baseline_stale(first, "another reason")
    stale = history.current_baseline(MACHINE)
    assert stale.stale and stale.stale_reason == "the sensor was remounted: set a new baseline"
    assert stale.stale_at_ns is not None
    second = history.add_baseline(_baseline([ids[4], ids[5], ids[6]], created_at_ns=5))
    assert history.current_baseline(MACHINE).id == second
    assert [b.id for b in history.baselines(MACHINE)] == [first, second]
    assert history.baseline(first) == stale
    assert history.current_baseline("nobody") is None
    with pytest.raises(HistoryError, match="no baseline 4242"):
        history.mark_baseline_stale(4242, "x")


def test_a_baseline_refuses_invalid_foreign_missing_or_mixed_runs(history):
    ids = [history.add_run(run_for(i))[0] for i in range(4)]
    foreign = history.add_run(run_for(9, machine="lathe-2"))[0]
    mixed = dataclasses.replace(run_for(8), settings={"cutoff_hz": 2.0}, settings_hash=None)
    mixed_id = history.add_run(mixed)[0]
    with pytest.raises(HistoryError, match=r"run \d+ is invalid \(run 3: too few cycles"):
        history.add_baseline(_baseline(ids))
    with pytest.raises(HistoryError, match="is of machine 'lathe-2', not 'mill-7'"):
        history.add_baseline(_baseline([ids[0], foreign]))
    with pytest.raises(HistoryError, match=r"has no run \[777\]"):
        history.add_baseline(_baseline([ids[0], 777]))
    with pytest.raises(HistoryError, match="2 different settings"):
        history.add_baseline(_baseline([ids[0], mixed_id]))
    with pytest.raises(HistoryError, match="first_run_at_ns is 1 but the runs give"):
        history.add_baseline(_baseline(ids[:2], first_run_at_ns=1))
    with pytest.raises(HistoryError, match="must be False for a new baseline"):
        history.add_baseline(_baseline(ids[:2], stale=True, stale_reason="x"))
    assert history.baselines(MACHINE) == []


def test_a_baselines_alarm_design_is_kept_exactly(history):
    ids = [history.add_run(run_for(i))[0] for i in range(3)]
    base = history.add_baseline(_baseline(ids))
    assert history.baseline(base).alarm_design == {}
    design = {"arl0_nights": 730.0, "sigma_urad": 17.25, "shares": [0.2, 0.3, 0.5], "nu": None}
    history.set_alarm_design(base, design)
    assert history.current_baseline(MACHINE).alarm_design == design
    with pytest.raises(HistoryError, match="no baseline 99"):
        history.set_alarm_design(99, design)


def test_anchors_belong_to_a_baseline(history):
    ids = [history.add_run(run_for(i))[0] for i in range(3)]
    base = history.add_baseline(_baseline(ids))
    a = history.add_anchor(
        AnchorRow(
            baseline_id=base,
            method="ballbar",
            value_rad=8.2e-6,
            u_value_rad=1.5e-6,
            input={"squareness_um_m": 8.2},
        )
    )
    d = history.add_anchor(
        AnchorRow(
            baseline_id=base,
            method="diagonals",
            value_rad=7.9e-6,
            input={"d1_mm": [707.1071, 707.1069], "d2_mm": [707.1010, 707.1012]},
            note="laser, 20 degC",
            created_at_ns=123,
        )
    )
    got = history.anchors(base)
    assert [x.id for x in got] == [a, d]
    assert got[1] == AnchorRow(
        id=d,
        baseline_id=base,
        method="diagonals",
        value_rad=7.9e-6,
        input={"d1_mm": [707.1071, 707.1069], "d2_mm": [707.1010, 707.1012]},
        note="laser, 20 degC",
        created_at_ns=123,
    )
    assert got[0].created_at_ns is not None
    with pytest.raises(HistoryError, match="no baseline 99"):
        history.add_anchor(AnchorRow(baseline_id=99, method="ballbar", value_rad=0.0))
    with pytest.raises(ImuSquareError, match=r"AnchorRow.method must be one of"):
        AnchorRow(baseline_id=base, method="laser", value_rad=0.0)


def test_a_verdict_per_run_and_baseline_replaced_on_re_evaluation(history):
    ids = [history.add_run(run_for(i))[0] for i in range(6)]
    none = history.add_evaluation(EvaluationRow(run_id=ids[0], state="no_baseline"))
    base = history.add_baseline(_baseline(ids[:3]))
    inv = history.add_evaluation(EvaluationRow(run_id=ids[3], baseline_id=base, state="invalid"))
    first = history.add_evaluation(
        EvaluationRow(
            run_id=ids[4],
            baseline_id=base,
            state="ok",
            change_rad=1.2e-6,
            u_change_rad=3.4e-6,
            statistics={"ewma": 0.1, "cusum": [0.0, 0.2]},
        )
    )
    # The same run against the same baseline again (a replay): the verdict is replaced.
    again = history.add_evaluation(
        EvaluationRow(
            run_id=ids[4],
            baseline_id=base,
            state="alarm",
            change_rad=1.4e-5,
            u_change_rad=3e-6,
            statistics={"ewma": 4.0},
            created_at_ns=77,
        )
    )
    assert again == first
    history.add_evaluation(EvaluationRow(run_id=ids[0], state="no_baseline", statistics={"n": 2}))
    history.add_evaluation(EvaluationRow(run_id=ids[5], baseline_id=base, state="warning"))
    got = history.evaluations(MACHINE)
    assert [(e.run_id, e.state) for e in got] == [
        (ids[0], "no_baseline"),
        (ids[3], "invalid"),
        (ids[4], "alarm"),
        (ids[5], "warning"),
    ]
    assert got[0].id == none and got[0].statistics == {"n": 2}
    assert got[1].id == inv
    assert got[2] == EvaluationRow(
        id=first,
        run_id=ids[4],
        baseline_id=base,
        state="alarm",
        change_rad=1.4e-5,
        u_change_rad=3e-6,
        statistics={"ewma": 4.0},
        created_at_ns=77,
    )
    assert history.evaluation(ids[4], base).state == "alarm"
    assert history.evaluation(ids[0]).state == "no_baseline"
    assert history.evaluation(ids[1]) is None
    assert [e.run_id for e in history.evaluations(MACHINE, baseline_id=base)] == ids[3:6]
    t4 = run_for(4).recorded_at_ns
    assert [e.run_id for e in history.evaluations(MACHINE, since=t4, until=t4 + 1)] == [ids[4]]
    other = history.add_run(run_for(8, machine="lathe-2"))[0]
    with pytest.raises(HistoryError, match="of machine 'lathe-2' but baseline"):
        history.add_evaluation(EvaluationRow(run_id=other, baseline_id=base, state="ok"))
    with pytest.raises(HistoryError, match="must be 'invalid' for the invalid run"):
        history.add_evaluation(EvaluationRow(run_id=ids[3], baseline_id=base, state="ok"))
    with pytest.raises(HistoryError, match="no run 555"):
        history.add_evaluation(EvaluationRow(run_id=555, state="no_baseline"))
    # The table's CHECK takes every state the rows allow.
    for state in EVALUATION_STATES:
        baseline = None if state in ("no_baseline", "invalid") else base
        history.add_evaluation(EvaluationRow(run_id=ids[2], baseline_id=baseline, state=state))
    with pytest.raises(ImuSquareError, match="state must be one of"):
        EvaluationRow(run_id=1, state="fine")
    with pytest.raises(HistoryError, match="must name the baseline of a 'alarm' verdict"):
        EvaluationRow(run_id=1, state="alarm")


def test_a_transaction_lands_whole_or_not_at_all(history):
    with history.transaction():
        for i in range(3):
            history.add_run(run_for(i))
        with history.transaction():  # nested blocks join the outer one
            history.add_run(run_for(3))
    assert len(history.runs(MACHINE)) == 4
    with pytest.raises(HistoryError, match="is invalid"), history.transaction():
        for i in range(10, 13):
            history.add_run(run_for(i))
        # Fails inside: everything of the block is rolled back, the runs too.
        history.add_baseline(_baseline([r.id for r in history.runs(MACHINE)]))
    assert [index_of(r) for r in history.runs(MACHINE)] == [0, 1, 2, 3]
    with pytest.raises(KeyboardInterrupt), history.transaction():
        history.add_run(run_for(20))
        raise KeyboardInterrupt
    assert len(history.runs(MACHINE)) == 4
    # The connection is usable after a rollback.
    assert history.add_run(run_for(21))[1]


def test_a_closed_history_says_so(location):
    h = open_history(location)
    h.close()
    h.close()
    with pytest.raises(HistoryError, match="is closed"):
        h.runs(MACHINE)


def test_the_tables_have_the_columns_the_store_uses(location):
    with open_history(location) as h:
        db = h._db
        for table, columns in store.COLUMNS.items():
            assert sorted(db.columns(table)) == sorted(columns), table


def test_sql_holding_a_literal_question_mark_and_percent_runs_as_written(history):
    # The backends take their own parameter markers; the SQL text is never rewritten.
    path = "/data/100% done/what?.mcap"
    history.add_run(dataclasses.replace(run_for(1), recording_path=path))
    history.add_run(run_for(2))
    db = history._db
    p = Params(db.mark)
    rows = db.query(
        "SELECT '?', '%', recording_path FROM runs "
        f"WHERE recording_path LIKE '%?%' AND recording_path LIKE {p('%100%')} "
        f"AND machine_id = {p(MACHINE)}",
        p.values,
    )
    assert rows == [("?", "%", path)]


def test_backup_holds_every_committed_run(history, tmp_path):
    ids = [history.add_run(run_for(i))[0] for i in range(30)]
    base = history.add_baseline(_baseline(ids[:3]))
    history.add_anchor(AnchorRow(baseline_id=base, method="ballbar", value_rad=1e-6))
    history.add_evaluation(EvaluationRow(run_id=ids[5], baseline_id=base, state="ok"))
    dest = tmp_path / "backups" / "history.backup"
    # A missing folder is never made: it may be a share that is not mounted.
    with pytest.raises(HistoryError, match=r"backup to .*history\.backup failed"):
        history.backup(dest)
    assert not dest.parent.exists()
    dest.parent.mkdir()
    assert history.backup(dest) == dest
    restored = _restore(history, dest)
    with open_history(restored) as copy:
        assert copy.runs(MACHINE) == history.runs(MACHINE)
        assert copy.baselines(MACHINE) == history.baselines(MACHINE)
        assert copy.anchors(base) == history.anchors(base)
        assert copy.evaluations(MACHINE) == history.evaluations(MACHINE)
    # A second backup replaces the first, whole.
    history.add_run(run_for(30))
    history.backup(dest)
    with open_history(_restore(history, dest)) as copy:
        assert len(copy.runs(MACHINE)) == 31
    assert sorted(p.name for p in dest.parent.iterdir()) == ["history.backup"]


def _restore(history, dest):
    """Where the backup ``dest`` of ``history`` can be opened from."""
    if history.backend == "sqlite":
        return dest
    server = pg_server.shared()
    name = server.new_database()
    done = subprocess.run(
        [pg_server.find_pg_tool("pg_restore"), "--no-owner", f"--dbname={server.conninfo(name)}",
         str(dest)],
        capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr
    schema = history._db.schema
    return server.url(dbname=name, schema=schema)


def test_backup_inside_a_transaction_is_refused(history, tmp_path):
    with pytest.raises(HistoryError, match="outside a transaction"), history.transaction():
        history.backup(tmp_path / "b")


def test_backends_store_byte_identical_rows(tmp_path):
    """Same rows into SQLite and PostgreSQL read back equal, JSON text included."""
    rows = {}
    for backend in ("sqlite", "postgresql"):
        with open_history(pg_server.location_for(backend, tmp_path)) as h:
            for i in range(8):
                h.add_run(run_for(i))
            rows[backend] = h.runs(MACHINE)
            texts = h._db.query("SELECT result_json, per_cycle_json FROM runs ORDER BY id")
            rows[backend + " json"] = texts
    assert rows["sqlite"] == rows["postgresql"]
    assert rows["sqlite json"] == rows["postgresql json"]
    assert rows["sqlite json"][0][0] == canonical_json(run_for(0).result)


# --- locations, without a database ---


def test_default_history_path_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.setenv("XDG_DATA_HOME", str(tmp_path / "xdg"))
    assert default_history_path() == tmp_path / "xdg" / "imu-square" / "history.db"
    monkeypatch.setenv("XDG_DATA_HOME", "relative/ignored")
    monkeypatch.setenv("HOME", str(tmp_path / "home"))
    assert default_history_path() == tmp_path / "home" / ".local/share/imu-square/history.db"
    monkeypatch.delenv("XDG_DATA_HOME")
    assert default_history_path() == tmp_path / "home" / ".local/share/imu-square/history.db"
    with open_history() as h:  # the default: created with its folders
        assert h.location == str(default_history_path())
        assert h.backend == "sqlite"
    assert default_history_path().is_file()


@pytest.mark.parametrize(
    ("location", "message"),
    [
        ("mysql://db/history", "must be a file path or a postgresql:// URL, got 'mysql://"),
        ("", "must be a file path or a postgresql:// URL, got ''"),
        (42, "must be a file path or a postgresql:// URL, got 42"),
    ],
)
def test_a_location_that_is_neither_path_nor_url_is_refused(location, message):
    with pytest.raises(HistoryError, match=message):
        open_history(location)


def test_a_folder_is_not_a_history(tmp_path):
    with pytest.raises(HistoryError, match=f"history {tmp_path}: is a folder"):
        open_history(tmp_path)


def test_postgres_errors_are_one_line_without_the_password(tmp_path):
    url = f"postgresql://imu:s3cret@/history?host={tmp_path}&password=s3cret"
    with pytest.raises(HistoryError) as err:
        open_history(url)
    text = str(err.value)
    assert "s3cret" not in text and "\n" not in text
    assert (
        text.startswith("history postgresql://imu:***@/history?host=") and "cannot connect" in text
    )


def test_postgres_search_path_without_a_schema_is_refused():
    if pg_server.skip_reason():
        pytest.skip(pg_server.skip_reason())
    url = pg_server.shared().url(schema="no_such_schema")
    with pytest.raises(HistoryError, match="no schema to keep the history in"):
        open_history(url)


def _python(code):
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=False
    )


def test_the_sqlite_path_never_imports_psycopg(tmp_path):
    done = _python(
        "import sys\n"
        "from imu_square.monitor.history.store import open_history\n"
        f"with open_history({str(tmp_path / 'h.db')!r}) as h:\n"
        "    h.runs('m')\n"
        "assert 'psycopg' not in sys.modules, 'psycopg was imported'\n"
    )
    assert done.returncode == 0, done.stderr


def test_a_url_without_psycopg_is_one_clear_line():
    done = _python(
        "import sys\n"
        "sys.modules['psycopg'] = None  # as if it were not installed\n"
        "from imu_square.monitor.history.store import open_history\n"
        "open_history('postgresql://u:pw@db.example/history')\n"
    )
    assert done.returncode != 0
    last = done.stderr.strip().splitlines()[-1]
    assert last == (
        "imu_square.errors.HistoryError: history postgresql://u:***@db.example/history: "
        "a PostgreSQL history needs psycopg 3: pip install 'imu-square[postgres]'"
    )


# --- rows, without a database ---


def test_rows_refuse_what_cannot_be_stored():
    good = run_for(1)
    with pytest.raises(HistoryError, match="recording_sha256 must be 64 hexadecimal digits"):
        dataclasses.replace(good, recording_sha256="abc")
    with pytest.raises(HistoryError, match=r"RunRow.squareness_rad must be a number, got None"):
        dataclasses.replace(good, squareness_rad=None)
    with pytest.raises(HistoryError, match="squareness_rad must be a number, got nan"):
        dataclasses.replace(good, squareness_rad=float("nan"))
    with pytest.raises(HistoryError, match="must say why an invalid run is invalid"):
        dataclasses.replace(good, valid=False)
    with pytest.raises(HistoryError, match="must be None for a valid run"):
        dataclasses.replace(good, invalid_reason="x")
    with pytest.raises(HistoryError, match=r"RunRow.valid must be True or False, got 1"):
        dataclasses.replace(good, valid=1)
    with pytest.raises(HistoryError, match=r"RunRow.machine_id must be one line of text"):
        dataclasses.replace(good, machine_id="a\nb")
    with pytest.raises(HistoryError, match=r"RunRow.result must hold JSON values.*got a object"):
        dataclasses.replace(good, result={"x": object()})
    with pytest.raises(HistoryError, match=r"RunRow.cycles_ccw must be at least 0"):
        dataclasses.replace(good, cycles_ccw=-1)
    with pytest.raises(HistoryError, match=r"RunRow.recorded_at_ns must be an integer"):
        dataclasses.replace(good, recorded_at_ns=1.5)
    with pytest.raises(HistoryError, match="run_ids must not repeat a run"):
        _baseline([1, 1])
    with pytest.raises(HistoryError, match="run_ids must be one or more run ids"):
        _baseline([])
    with pytest.raises(HistoryError, match="stale_reason must say why"):
        _baseline([1], stale=True)
    with pytest.raises(HistoryError, match=r"RunRow.recording_path must be UTF-8 text"):
        dataclasses.replace(good, recording_path="/data/r\udcff.mcap")  # undecodable name
    with pytest.raises(HistoryError, match=r"BaselineRow.note must not hold a NUL character"):
        _baseline([1], note="a\x00b")
    invalid = dataclasses.replace(good, valid=False, invalid_reason="  bad\n file \t end ")
    assert invalid.invalid_reason == "bad file end"


def test_rows_check_as_every_entry_point_does():
    # each row's refusals are HistoryErrors (the choices were plain ImuSquareErrors)
    with pytest.raises(HistoryError, match=r"^AnchorRow.method must be one of"):
        AnchorRow(baseline_id=1, method="laser", value_rad=0.0)
    with pytest.raises(HistoryError, match=r"^EvaluationRow.state must be one of"):
        EvaluationRow(run_id=1, state="fine")
    # a numpy float is no run id (1.5 was cut to run 1)
    with pytest.raises(HistoryError, match=r"^BaselineRow.run_ids must be one or more run ids"):
        _baseline([np.float64(1.5)])
    assert _baseline([np.int64(2), 1]).run_ids == (1, 2)
    # numpy's bool is stored as a bool, as numpy's numbers are stored as numbers
    row = dataclasses.replace(run_for(1), valid=np.bool_(True))
    assert type(row.valid) is bool


def test_settings_hash_and_file_hash(tmp_path):
    a = settings_hash({"b": 1.0, "a": [1, 2], "c": np.float64(0.1)})
    b = settings_hash({"a": (1, 2), "c": 0.1, "b": 1.0})
    assert a == b and len(a) == 64
    assert settings_hash({"b": 1.0000000001, "a": [1, 2], "c": 0.1}) != a
    f = tmp_path / "r.mcap"
    f.write_bytes(b"x" * 3_000_000)
    assert file_sha256(f) == hashlib.sha256(b"x" * 3_000_000).hexdigest()
    with pytest.raises(ImuSquareError, match="cannot read the recording"):
        file_sha256(tmp_path / "missing.mcap")
    assert json.loads(canonical_json({"x": float("inf")})) == {"x": None}


def test_sqlite_runs_in_wal_with_full_sync_foreign_keys_and_a_busy_timeout(tmp_path):
    with open_history(tmp_path / "h.db", busy_timeout_s=12.5) as h:
        q = h._db.query
        assert q("PRAGMA journal_mode") == [("wal",)]
        assert q("PRAGMA synchronous") == [(2,)]  # FULL
        assert q("PRAGMA foreign_keys") == [(1,)]
        assert q("PRAGMA busy_timeout") == [(12500,)]
        h.add_run(run_for(1))
        # No transaction is left open behind the caller's back: the run is committed.
        assert not h._db.conn.in_transaction
        with pytest.raises(HistoryError, match="FOREIGN KEY constraint failed"):
            h._db.execute("INSERT INTO baseline_runs (baseline_id, run_id) VALUES (7, 7)")
