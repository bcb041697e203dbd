"""The history's schema versions and migrations, on both backends."""

import dataclasses
import os
import subprocess
import sys
import time
from pathlib import Path

import pg_server
import pytest
from history_child import MACHINE, run_for

from imu_square.errors import HistoryError
from imu_square.monitor.history import schema
from imu_square.monitor.history.encoding import canonical_json
from imu_square.monitor.history.postgres import PostgresBackend
from imu_square.monitor.history.rows import (
    DiagnosticFitRow,
    DiagnosticRow,
    EvaluationRow,
    OutboxRow,
)
from imu_square.monitor.history.sql import Params
from imu_square.monitor.history.sqlite import SqliteBackend
from imu_square.monitor.history.store import RUNS, is_postgres_url, open_history

CHILD = Path(__file__).with_name("history_child.py")
JSON_FIELDS = ("settings", "quality", "warnings", "per_cycle", "result")


@pytest.fixture(params=["sqlite", "postgresql"])
def location(request, tmp_path):
    return pg_server.location_for(request.param, tmp_path)


def _backend(location):
    if is_postgres_url(location):
        return PostgresBackend(location, 5.0)
    return SqliteBackend(location, 5.0)


def _insert(db, table, values):
    names = ", ".join(values)
    p = Params(db.mark)
    return db.query(
        f"INSERT INTO {table} ({names}) VALUES ({p.list(values.values())}) RETURNING id", p.values
    )[0][0]


def test_a_version_1_history_is_migrated_and_keeps_its_rows(location, tmp_path):
    db = _backend(location)
    assert schema.migrate(db, target=1) == 1
    assert "evaluations" not in db.tables()
    v1_columns = db.columns("runs")
    assert "temperature_start_c" not in v1_columns
    # What an imu-square of schema version 1 wrote: its columns only.
    row = run_for(1)
    values = {}
    for field in dataclasses.fields(row):
        value = getattr(row, field.name)
        column = field.name + "_json" if field.name in JSON_FIELDS else field.name
        if column in v1_columns and column != "id":
            values[column] = canonical_json(value) if field.name in JSON_FIELDS else value
    with db.transaction(write=True):
        run_id = _insert(db, "runs", values)
        base = _insert(
            db,
            "baselines",
            {
                "machine_id": MACHINE,
                "created_at_ns": 5,
                "settings_hash": row.settings_hash,
                "squareness_mean_rad": 1e-5,
                "u_squareness_mean_rad": 1e-6,
                "stale": False,
                "note": "",
            },
        )
        p = Params(db.mark)
        db.execute(
            f"INSERT INTO baseline_runs (baseline_id, run_id) VALUES ({p.list((base, run_id))})",
            p.values,
        )
    db.close()

    with open_history(location) as h:
        assert h.schema_version == schema.latest_version()
        got = h.runs(MACHINE)
        # the baseline of version 1 has no alarm design yet (version 3)
        assert h.current_baseline(MACHINE).alarm_design == {}
        # The thermal columns are new in version 2: unknown for the old run.
        assert got == [
            dataclasses.replace(
                row,
                id=run_id,
                temperature_start_c=None,
                temperature_end_c=None,
                temperature_mean_c=None,
                time_since_power_on_s=None,
            )
        ]
        assert h.current_baseline(MACHINE).run_ids == (run_id,)
        h.add_evaluation(EvaluationRow(run_id=run_id, baseline_id=base, state="ok"))
        assert h.add_run(run_for(2))[1]
        assert h.run(h.runs(MACHINE)[1].id) == dataclasses.replace(
            run_for(2), id=h.runs(MACHINE)[1].id
        )
        log = h._db.query("SELECT version, description FROM schema_version ORDER BY version")
        assert log == [(m.version, m.description) for m in schema.MIGRATIONS]
        migrated = {t: sorted(h._db.columns(t)) for t in schema.TABLES}
    # The migrated history has the tables and columns of a fresh one.
    fresh_location = pg_server.location_for(
        "postgresql" if is_postgres_url(location) else "sqlite", tmp_path / "fresh"
    )
    with open_history(fresh_location) as fresh:
        assert fresh._db.tables() == set(schema.TABLES)
        assert {t: sorted(fresh._db.columns(t)) for t in schema.TABLES} == migrated


def test_a_version_3_history_gets_an_empty_outbox_and_keeps_its_runs(location):
    db = _backend(location)
    assert schema.migrate(db, target=3) == 3
    assert "outbox" not in db.tables()
    row = run_for(1)
    with db.transaction(write=True):
        run_id = _insert(db, "runs", RUNS.values(row))
    db.close()

    with open_history(location) as h:
        assert h.schema_version == schema.latest_version()
        assert h.runs(MACHINE) == [dataclasses.replace(row, id=run_id)]
        assert h.outbox(MACHINE) == []
        alert = OutboxRow(
            machine_id=MACHINE,
            alert_id="0123456789abcdef0123456789abcdef",
            sink="webhook",
            created_at_ns=row.recorded_at_ns,
            alert={"schema": "imu-square.alert/1", "state": "alarm", "record": {"run_id": run_id}},
        )
        outbox_id = h.add_alert(alert)
        (got,) = h.outbox(MACHINE)
        assert got == dataclasses.replace(alert, id=outbox_id, updated_at_ns=got.updated_at_ns)


def test_a_version_4_history_gets_empty_diagnostics_and_keeps_its_runs_and_baseline(location):
    db = _backend(location)
    assert schema.migrate(db, target=4) == 4
    assert "diagnostic_fits" not in db.tables()
    assert "diagnostic_designs_json" not in db.columns("baselines")
    row = run_for(1)
    design = {"sigma_rad": 2.5e-6}
    with db.transaction(write=True):
        run_id = _insert(db, "runs", RUNS.values(row))
        base = _insert(
            db,
            "baselines",
            {
                "machine_id": MACHINE,
                "created_at_ns": 5,
                "settings_hash": row.settings_hash,
                "squareness_mean_rad": 1e-5,
                "u_squareness_mean_rad": 1e-6,
                "stale": False,
                "note": "",
                "alarm_design_json": canonical_json(design),
            },
        )
        p = Params(db.mark)
        db.execute(
            f"INSERT INTO baseline_runs (baseline_id, run_id) VALUES ({p.list((base, run_id))})",
            p.values,
        )
    db.close()

    with open_history(location) as h:
        assert h.schema_version == schema.latest_version()
        assert h.runs(MACHINE) == [dataclasses.replace(row, id=run_id)]
        baseline = h.current_baseline(MACHINE)
        assert baseline.alarm_design == design and baseline.run_ids == (run_id,)
        # the old nights have no diagnostics: a replay fits them (test_monitor_diagnostics)
        assert baseline.diagnostic_designs == {}
        assert h.diagnostic_fits(MACHINE, "0" * 64) == {}
        fit = DiagnosticFitRow(
            run_id=run_id,
            settings={"effects": ["backlash"]},
            seconds=0.5,
            fit={"rss": 1.0},
            values=(
                DiagnosticRow(name="backlash_x", unit="m", value=2e-6, u_value=1e-9),
                DiagnosticRow(name="backlash_y", unit="m", missing_reason="not identifiable"),
            ),
        )
        fit_id, inserted = h.add_diagnostic_fit(fit)
        assert inserted and h.add_diagnostic_fit(fit) == (fit_id, False)  # kept as it was
        (got,) = h.diagnostic_fits(MACHINE, fit.settings_hash).values()
        assert got.values == tuple(
            dataclasses.replace(v, id=got.values[i].id, fit_id=fit_id)
            for i, v in enumerate(fit.values)
        )
        assert got.failure is None and got.fit == {"rss": 1.0}
        # the run fitted again under other settings: each set of settings, oldest first
        other = dataclasses.replace(fit, settings={"effects": ["backlash"], "motion": "linuxcnc"})
        other = dataclasses.replace(other, settings_hash=None)
        assert h.add_diagnostic_fit(other)[1]
        assert h.diagnostic_settings(MACHINE) == {
            fit.settings_hash: fit.settings,
            other.settings_hash: other.settings,
        }
        assert h.diagnostic_settings("another machine") == {}
        # a replay skips the recording now that its valid run has a fit under these settings
        assert h.diagnosed_hashes(MACHINE, row.settings_hash, fit.settings_hash) == {
            row.recording_sha256
        }
        assert h.diagnosed_hashes(MACHINE, row.settings_hash, "0" * 64) == set()
        h.set_diagnostic_designs(base, {"backlash_x": {"key": "k"}})
        assert h.current_baseline(MACHINE).diagnostic_designs == {"backlash_x": {"key": "k"}}
        # a stored diagnostic with neither a value nor a reason is refused by the database
        with pytest.raises(Exception, match=r"(?i)check|constraint"):
            with h.transaction():
                p = Params(h._db.mark)
                h._db.execute(
                    "INSERT INTO diagnostics (fit_id, name, unit) VALUES "
                    f"({p.list((fit_id, 'scale_x', '1'))})",
                    p.values,
                )


def test_a_failed_migration_leaves_the_history_unchanged(location, monkeypatch):
    with open_history(location) as h:
        run_id = h.add_run(run_for(1))[0]
    latest = schema.latest_version()
    broken = schema.Migration(
        latest + 1,
        "broken on purpose",
        (
            "ALTER TABLE runs ADD COLUMN extra_c DOUBLE PRECISION",
            "CREATE TABLE extra (x INTEGER)",
            "CREATE TABLE evaluations (x INTEGER)",  # exists: the migration fails here
        ),
    )
    monkeypatch.setattr(schema, "MIGRATIONS", (*schema.MIGRATIONS, broken))
    with pytest.raises(HistoryError) as err:
        open_history(location)
    text = str(err.value)
    assert "\n" not in text
    assert text.startswith(
        "history " + (location if not is_postgres_url(location) else "postgresql://")
    )
    assert (
        f"migration to schema version {latest + 1} (broken on purpose) failed, the history "
        "is left at "
    ) in text
    assert f"version {latest}: " in text and "already exists" in text
    monkeypatch.undo()
    with open_history(location) as h:
        assert h.schema_version == latest
        assert "extra_c" not in h._db.columns("runs")
        assert "extra" not in h._db.tables()
        assert h.runs(MACHINE) == [dataclasses.replace(run_for(1), id=run_id)]


def test_a_newer_schema_is_refused(location):
    with open_history(location) as h:
        p = Params(h._db.mark)
        h._db.execute(
            "INSERT INTO schema_version (version, description, applied_at_ns, software_version) "
            f"VALUES ({p.list((7, 'from the future', 0, '9.0'))})",
            p.values,
        )
    with pytest.raises(HistoryError, match=r"schema version 7 is newer than this imu-square") as e:
        open_history(location)
    assert str(e.value).endswith(f"knows (up to {schema.latest_version()}); upgrade imu-square")


def test_tables_of_something_else_are_not_a_history(location):
    db = _backend(location)
    db.execute("CREATE TABLE runs (lap INTEGER, seconds REAL)")
    db.close()
    with pytest.raises(HistoryError, match=r"not an imu-square history: it has tables \['runs'\]"):
        open_history(location)


def test_processes_opening_a_fresh_history_at_once_create_it_once(location, tmp_path):
    go = tmp_path / "go"
    env = {**os.environ, "GO": str(go)}
    procs = [
        subprocess.Popen(
            [sys.executable, str(CHILD), "open", location],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )
        for _ in range(3)
    ]
    time.sleep(0.5)  # let them all start and wait
    go.touch()
    outs = [p.communicate(timeout=60) for p in procs]
    assert [(p.returncode, out.strip()) for p, (out, _) in zip(procs, outs, strict=True)] == [
        (0, str(schema.latest_version()))
    ] * 3, [err for _, err in outs]
    with open_history(location) as h:
        versions = h._db.query("SELECT version FROM schema_version ORDER BY version")
        assert versions == [(m.version,) for m in schema.MIGRATIONS]
