"""The monitor's history: one API over SQLite (the embedded default) and PostgreSQL.

>>> with open_history("history.db") as history:  # doctest: +SKIP
...     run_id, inserted = history.add_run(row)
...     runs = history.runs("mill-3", valid_only=True)

:func:`open_history` takes a file path (SQLite) or a ``postgresql://`` URL
(psycopg 3, extra ``imu-square[postgres]``), checks the history, creates or
migrates its schema (:mod:`imu_square.monitor.history.schema`) and returns a
:class:`History`. Its methods take and return the frozen rows of
:mod:`imu_square.monitor.history.rows`, keyed by
:func:`~imu_square.monitor.history.encoding.file_sha256` of the recording and
:func:`~imu_square.monitor.history.encoding.settings_hash` of the analysis settings.

Every write method is one transaction of its own, unless it runs inside
``with history.transaction():``, which makes many writes (a replay's batch)
one transaction: all of them land, or none. Storing the same recording
(SHA-256) twice under the same analysis settings gives the same run row:
:meth:`History.add_run` returns its id and ``inserted=False``.

Times are integer nanoseconds since the Unix epoch, UTC; a time range
``since``/``until`` is half-open, ``since <= t < until``, and takes integer
nanoseconds or aware datetimes.

A :class:`History` is one connection: use it from one thread; each process
opens its own. Processes may write the same history at once: a writer waits
for another's transaction (up to ``busy_timeout_s``) rather than failing.
"""

import os
import re
from contextlib import contextmanager, nullcontext
from datetime import datetime
from pathlib import Path

from imu_square.errors import HistoryError
from imu_square.log import logger
from imu_square.monitor.history import schema
from imu_square.monitor.history.diagnostic_fits import DIAGNOSTIC_FITS, DIAGNOSTICS, DiagnosticFits
from imu_square.monitor.history.encoding import canonical_json, now_ns, ns_from_datetime
from imu_square.monitor.history.outbox import OUTBOX, Outbox
from imu_square.monitor.history.rows import AnchorRow, BaselineRow, EvaluationRow, RunRow
from imu_square.monitor.history.sql import Params, Table

#: Seconds a writer waits for another process's transaction by default.
BUSY_TIMEOUT_S = 60.0

_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://")

RUNS = Table("runs", RunRow)
BASELINES = Table("baselines", BaselineRow, skip=("run_ids",))  # in baseline_runs
ANCHORS = Table("anchors", AnchorRow)
EVALUATIONS = Table("evaluations", EvaluationRow)
#: Every table's columns as this module reads and writes them.
COLUMNS = {
    t.name: t.columns
    for t in (RUNS, BASELINES, ANCHORS, EVALUATIONS, OUTBOX, DIAGNOSTIC_FITS, DIAGNOSTICS)
} | {
    "baseline_runs": ["baseline_id", "run_id"],
    "schema_version": ["version", "description", "applied_at_ns", "software_version"],
}


def default_history_path():
    """The per-user history file: ``$XDG_DATA_HOME/imu-square/history.db``.

    ``XDG_DATA_HOME`` defaults to ``~/.local/share`` (XDG Base Directory
    specification; a relative value is ignored, as the specification asks).

    Returns
    -------
    Path
        The file (it may not exist yet).
    """
    base = os.environ.get("XDG_DATA_HOME", "")
    root = Path(base) if os.path.isabs(base) else Path.home() / ".local" / "share"
    return root / "imu-square" / "history.db"


def is_postgres_url(location):
    """True when ``location`` is a ``postgresql://`` (or ``postgres://``) URL."""
    m = _URL.match(str(location))
    return bool(m) and m.group(1).lower() in ("postgresql", "postgres")


def open_history(location=None, *, busy_timeout_s=BUSY_TIMEOUT_S):
    """Open (and create or migrate) a history.

    Parameters
    ----------
    location : str, Path or None
        A file path for SQLite, a ``postgresql://`` URL for PostgreSQL, or
        None for :func:`default_history_path`.
    busy_timeout_s : float
        How long a writer waits for another process's transaction before it
        fails. [s]

    Returns
    -------
    History
        Open; close it, or use it as a context manager.
    """
    if location is None:
        location = default_history_path()
    usable = isinstance(location, str | os.PathLike) and str(location).strip()
    if not usable or (_URL.match(str(location)) and not is_postgres_url(location)):
        raise HistoryError(
            f"history location must be a file path or a postgresql:// URL, got {location!r}"
        )
    if is_postgres_url(location):
        from imu_square.monitor.history.postgres import PostgresBackend

        backend = PostgresBackend(str(location), busy_timeout_s)
    else:
        from imu_square.monitor.history.sqlite import SqliteBackend

        backend = SqliteBackend(location, busy_timeout_s)
    try:
        return History(backend, schema.migrate(backend))
    except BaseException:
        backend.close()
        raise


def _ns(name, value):
    if value is None or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    if isinstance(value, datetime):
        return ns_from_datetime(value)
    raise HistoryError(f"{name} must be integer nanoseconds or an aware datetime, got {value!r}")


def _window(p, column, since, until):
    """The conditions of the half-open time range ``since <= column < until`` (None: open)."""
    since, until = _ns("since", since), _ns("until", until)
    return [f"{column} {op} {p(t)}" for op, t in ((">=", since), ("<", until)) if t is not None]


class History(Outbox, DiagnosticFits):
    """An open history; see the module's docstring. Made by :func:`open_history`.

    Attributes
    ----------
    location : str
        The file, or the URL without its password.
    backend : str
        ``"sqlite"`` or ``"postgresql"``.
    schema_version : int
        The schema's version.
    """

    def __init__(self, backend, version):
        self._db = backend
        self._depth = 0
        self.location = backend.location
        self.backend = backend.name
        self.schema_version = version

    def __repr__(self):
        return f"<History {self.backend} {self.location}>"

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Close the connection; a transaction still open is rolled back."""
        if self._db is not None:
            self._db.close()
            self._db = None

    @property
    def _conn(self):
        if self._db is None:
            raise HistoryError(f"history {self.location}: is closed")
        return self._db

    # --- transactions ---

    @contextmanager
    def transaction(self):
        """Make the writes in the ``with`` block one transaction: all land or none.

        Blocks nest (an inner block joins the outer one). An exception out of
        the block rolls everything back and propagates; a write method that
        fails inside it undoes only its own changes, so a caller may catch its
        error and go on.
        """
        if self._depth:
            self._depth += 1
            try:
                yield self
            finally:
                self._depth -= 1
            return
        with self._conn.transaction(write=True):
            self._depth = 1
            try:
                yield self
            finally:
                self._depth = 0

    def _write(self):
        # Inside a caller's transaction, each write is a savepoint: one that fails
        # (a lock timeout, ...) is undone alone and the block may go on, on both
        # backends (PostgreSQL would otherwise refuse every later statement).
        return self._conn.savepoint() if self._depth else self.transaction()

    def _read(self):
        return nullcontext() if self._depth else self._conn.transaction(write=False)

    # --- SQL through the tables' converters ---

    def _params(self):
        return Params(self._conn.mark)

    def _insert(self, table, values, conflict=""):
        """Insert a row's ``values`` (by column): ``[(id,)]``, or [] if ``conflict`` skipped it."""
        p = self._params()
        return self._conn.query(
            f"INSERT INTO {table.name} ({', '.join(values)}) VALUES ({p.list(values.values())}) "
            f"{conflict} RETURNING id",
            p.values,
        )

    def _select(self, table, where, p, order="id", join="", more=lambda values: {}):
        """The rows of ``table`` (joined with ``join``) matching ``where``, read back.

        ``more(values)`` gives the fields kept in other tables from the row's column values.
        """
        columns = ", ".join(f"{table.name}.{c}" for c in table.columns)
        sql = f"SELECT {columns} FROM {table.name} {join} WHERE {where} ORDER BY {order}"
        return [table.read(r, **more(r)) for r in self._conn.query(sql, p.values)]

    def _only(self, rows, what, row_id):
        """The one row of ``rows``; raise if there is none."""
        if not rows:
            raise HistoryError(f"history {self.location}: no {what} {row_id!r}")
        return rows[0]

    def _require(self, table, row_id, what):
        p = self._params()
        found = self._conn.query(f"SELECT 1 FROM {table} WHERE id = {p(row_id)}", p.values)
        self._only(found, what, row_id)

    # --- runs ---

    def add_run(self, row):
        """Store an analysed run, once per (machine, recording, settings).

        Parameters
        ----------
        row : RunRow
            The run; its ``id`` is ignored, ``analysed_at_ns`` is stamped if None.

        Returns
        -------
        run_id : int
            The run's row.
        inserted : bool
            False when the same recording was already stored for this machine
            under the same settings: that row is kept as it was.
        """
        if not isinstance(row, RunRow):
            raise HistoryError(f"add_run needs a RunRow, got {type(row).__name__}")
        values = RUNS.values(row, stamp="analysed_at_ns")
        with self._write():
            got = self._insert(
                RUNS, values, "ON CONFLICT (machine_id, recording_sha256, settings_hash) DO NOTHING"
            )
            if got:
                logger.debug("history %s: run %d stored", self.location, got[0][0])
                return got[0][0], True
            run_id = self.run_by_hash(row.machine_id, row.recording_sha256, row.settings_hash).id
        logger.debug("history %s: run %d was already there", self.location, run_id)
        return run_id, False

    def _select_runs(self, where, p):
        return self._select(RUNS, where, p, "recorded_at_ns IS NULL, recorded_at_ns, id")

    def run(self, run_id):
        """The run with id ``run_id``; raise if there is none."""
        p = self._params()
        return self._only(self._select_runs(f"id = {p(run_id)}", p), "run", run_id)

    def run_by_hash(self, machine_id, recording_sha256, settings_hash):
        """The run of this recording under these settings, or None.

        Parameters
        ----------
        machine_id : str
            The machine.
        recording_sha256 : str
            :func:`~imu_square.monitor.history.encoding.file_sha256` of the recording.
        settings_hash : str
            :func:`~imu_square.monitor.history.encoding.settings_hash` of the settings.

        Returns
        -------
        RunRow or None
        """
        p = self._params()
        rows = self._select_runs(
            f"machine_id = {p(machine_id)} AND recording_sha256 = {p(recording_sha256.lower())} "
            f"AND settings_hash = {p(settings_hash.lower())}",
            p,
        )
        return rows[0] if rows else None

    def recording_hashes(self, machine_id, settings_hash=None):
        """SHA-256 of every recording stored for a machine (under these settings).

        A replay skips these without reading the rows.

        Parameters
        ----------
        machine_id : str
            The machine.
        settings_hash : str or None
            Only runs analysed with these settings; all when None.

        Returns
        -------
        set of str
        """
        p = self._params()
        sql = f"SELECT recording_sha256 FROM runs WHERE machine_id = {p(machine_id)}"
        if settings_hash is not None:
            sql += f" AND settings_hash = {p(settings_hash)}"
        return {r[0] for r in self._conn.query(sql, p.values)}

    def runs(self, machine_id, since=None, until=None, valid_only=False, settings_hash=None):
        """A machine's runs in recording-time order (runs of unknown time last).

        Parameters
        ----------
        machine_id : str
            The machine.
        since, until : int, datetime or None
            Half-open range of the recording time, ``since <= t < until``;
            a run of unknown time is outside every range. [ns]
        valid_only : bool
            Leave out the invalid runs.
        settings_hash : str or None
            Only runs analysed with these settings.

        Returns
        -------
        list of RunRow
        """
        p = self._params()
        where = [f"machine_id = {p(machine_id)}", *_window(p, "recorded_at_ns", since, until)]
        if valid_only:
            where.append(f"valid = {p(True)}")
        if settings_hash is not None:
            where.append(f"settings_hash = {p(settings_hash)}")
        return self._select_runs(" AND ".join(where), p)

    def machines(self):
        """The machine ids with a run or a baseline, sorted."""
        rows = self._conn.query(
            "SELECT machine_id FROM runs UNION SELECT machine_id FROM baselines"
        )
        return sorted(r[0] for r in rows)

    # --- baselines ---

    def add_baseline(self, row):
        """Store a new baseline for a machine; it becomes the machine's current one.

        Its runs must exist, belong to the machine, be valid and share one
        analysis settings hash; the store fills in ``settings_hash`` and the
        first and last runs' times from them (or checks the ones given).

        Parameters
        ----------
        row : BaselineRow
            The baseline; its ``id`` is ignored, ``created_at_ns`` is stamped if None.

        Returns
        -------
        int
            The baseline's id.
        """
        if not isinstance(row, BaselineRow):
            raise HistoryError(f"add_baseline needs a BaselineRow, got {type(row).__name__}")
        if row.stale:
            raise HistoryError("BaselineRow.stale must be False for a new baseline")
        with self._write():
            p = self._params()
            runs = {r.id: r for r in self._select_runs(f"id IN ({p.list(row.run_ids)})", p)}
            missing = [i for i in row.run_ids if i not in runs]
            if missing:
                raise HistoryError(
                    f"BaselineRow.run_ids: history {self.location} has no run {missing!r}"
                )
            for run_id, run in sorted(runs.items()):
                if run.machine_id != row.machine_id:
                    raise HistoryError(
                        f"BaselineRow.run_ids: run {run_id} is of machine {run.machine_id!r}, "
                        f"not {row.machine_id!r}"
                    )
                if not run.valid:
                    raise HistoryError(
                        f"BaselineRow.run_ids: run {run_id} is invalid ({run.invalid_reason}); "
                        "an invalid run never enters a baseline"
                    )
            hashes = sorted({r.settings_hash for r in runs.values()})
            if len(hashes) > 1:
                raise HistoryError(
                    f"BaselineRow.run_ids: the runs were analysed with {len(hashes)} different "
                    "settings; a baseline's runs must share one"
                )
            times = [r.recorded_at_ns for r in runs.values() if r.recorded_at_ns is not None]
            derived = {
                "settings_hash": hashes[0],
                "first_run_at_ns": min(times) if times else None,
                "last_run_at_ns": max(times) if times else None,
            }
            for name, value in derived.items():
                given = getattr(row, name)
                if given is not None and given != value:
                    raise HistoryError(
                        f"BaselineRow.{name} is {given!r} but the runs give {value!r}"
                    )
            values = BASELINES.values(row, stamp="created_at_ns") | derived
            baseline_id = self._insert(BASELINES, values)[0][0]
            p = self._params()
            pairs = ", ".join(f"({p.list((baseline_id, run_id))})" for run_id in row.run_ids)
            sql = f"INSERT INTO baseline_runs (baseline_id, run_id) VALUES {pairs}"
            self._conn.execute(sql, p.values)
        logger.debug("history %s: baseline %d stored", self.location, baseline_id)
        return baseline_id

    def _select_baselines(self, where, p):
        with self._read():
            return self._select(BASELINES, where, p, more=self._run_ids)

    def _run_ids(self, values):
        p = self._params()
        sql = f"SELECT run_id FROM baseline_runs WHERE baseline_id = {p(values[0])} ORDER BY run_id"
        return {"run_ids": tuple(r[0] for r in self._conn.query(sql, p.values))}

    def baseline(self, baseline_id):
        """The baseline with id ``baseline_id``; raise if there is none."""
        p = self._params()
        rows = self._select_baselines(f"id = {p(baseline_id)}", p)
        return self._only(rows, "baseline", baseline_id)

    def baselines(self, machine_id):
        """Every baseline of a machine, oldest first."""
        p = self._params()
        return self._select_baselines(f"machine_id = {p(machine_id)}", p)

    def current_baseline(self, machine_id):
        """The machine's current baseline (its latest, stale or not), or None."""
        p = self._params()
        rows = self._select_baselines(
            f"id = (SELECT MAX(id) FROM baselines WHERE machine_id = {p(machine_id)})", p
        )
        return rows[0] if rows else None

    def mark_baseline_stale(self, baseline_id, reason, at_ns=None):
        """Mark a baseline stale (the sensor was remounted, ...).

        Parameters
        ----------
        baseline_id : int
            The baseline.
        reason : str
            Why, one line (for example "the sensor was remounted: set a new baseline").
        at_ns : int, datetime or None
            When; now if None. [ns]

        Returns
        -------
        bool
            True if it became stale now, False if it already was (its first
            reason and time are kept).
        """
        reason = " ".join(str(reason).split()) if isinstance(reason, str) else ""
        if not reason:
            raise HistoryError("mark_baseline_stale: reason must say why, got nothing")
        at_ns = _ns("at_ns", at_ns)
        with self._write():
            p = self._params()
            changed = self._conn.execute(
                f"UPDATE baselines SET stale = {p(True)}, stale_reason = {p(reason)}, "
                f"stale_at_ns = {p(now_ns() if at_ns is None else at_ns)} "
                f"WHERE id = {p(baseline_id)} AND stale = {p(False)}",
                p.values,
            )
            if not changed:
                self._require("baselines", baseline_id, "baseline")
        return bool(changed)

    def set_alarm_design(self, baseline_id, design):
        """Keep a baseline's alarm design (computed once, read every night).

        Parameters
        ----------
        baseline_id : int
            The baseline.
        design : dict
            :meth:`~imu_square.monitor.stats.alarms.AlarmDesign.to_json_dict`.
        """
        p = self._params()
        sql = (
            f"UPDATE baselines SET alarm_design_json = {p(canonical_json(design, 'alarm design'))} "
            f"WHERE id = {p(baseline_id)}"
        )
        with self._write():
            if not self._conn.execute(sql, p.values):
                self._require("baselines", baseline_id, "baseline")

    # --- anchors ---

    def add_anchor(self, row):
        """Store an absolute anchor of a baseline by a reference method.

        Parameters
        ----------
        row : AnchorRow
            The anchor; its ``id`` is ignored, ``created_at_ns`` is stamped if None.

        Returns
        -------
        int
            The anchor's id.
        """
        if not isinstance(row, AnchorRow):
            raise HistoryError(f"add_anchor needs an AnchorRow, got {type(row).__name__}")
        values = ANCHORS.values(row, stamp="created_at_ns")
        with self._write():
            self._require("baselines", row.baseline_id, "baseline")
            return self._insert(ANCHORS, values)[0][0]

    def anchors(self, baseline_id):
        """A baseline's anchors, oldest first."""
        p = self._params()
        return self._select(ANCHORS, f"baseline_id = {p(baseline_id)}", p)

    # --- evaluations ---

    def add_evaluation(self, row):
        """Store the monitor's verdict on a run; a new verdict on the same
        (run, baseline) replaces the old one (a replay re-evaluates).

        An invalid run's verdict can only be ``invalid``: it never moves a chart.

        Parameters
        ----------
        row : EvaluationRow
            The verdict; its ``id`` is ignored, ``created_at_ns`` is stamped if None.

        Returns
        -------
        int
            The verdict's id.
        """
        if not isinstance(row, EvaluationRow):
            raise HistoryError(f"add_evaluation needs an EvaluationRow, got {type(row).__name__}")
        values = EVALUATIONS.values(row, stamp="created_at_ns")
        target = (
            "(run_id) WHERE baseline_id IS NULL"
            if row.baseline_id is None
            else "(run_id, baseline_id) WHERE baseline_id IS NOT NULL"
        )
        updates = ", ".join(f"{c} = excluded.{c}" for c in values)
        with self._write():
            run = self.run(row.run_id)
            if not run.valid and row.state != "invalid":
                raise HistoryError(
                    f"EvaluationRow.state must be 'invalid' for the invalid run {row.run_id}, "
                    f"got {row.state!r}"
                )
            base = None if row.baseline_id is None else self.baseline(row.baseline_id)
            if base is not None and base.machine_id != run.machine_id:
                raise HistoryError(
                    f"EvaluationRow: run {row.run_id} is of machine {run.machine_id!r} but "
                    f"baseline {row.baseline_id} of {base.machine_id!r}"
                )
            return self._insert(
                EVALUATIONS, values, f"ON CONFLICT {target} DO UPDATE SET {updates}"
            )[0][0]

    def _select_evaluations(self, where, p):
        return self._select(
            EVALUATIONS,
            where,
            p,
            "runs.recorded_at_ns IS NULL, runs.recorded_at_ns, runs.id, evaluations.id",
            "JOIN runs ON runs.id = evaluations.run_id",
        )

    def evaluations(self, machine_id, since=None, until=None, baseline_id=None):
        """A machine's verdicts in the recording-time order of their runs.

        Parameters
        ----------
        machine_id : str
            The machine.
        since, until : int, datetime or None
            Half-open range of the runs' recording time. [ns]
        baseline_id : int or None
            Only the verdicts against this baseline.

        Returns
        -------
        list of EvaluationRow
        """
        p = self._params()
        where = [f"runs.machine_id = {p(machine_id)}"]
        where += _window(p, "runs.recorded_at_ns", since, until)
        if baseline_id is not None:
            where.append(f"evaluations.baseline_id = {p(baseline_id)}")
        return self._select_evaluations(" AND ".join(where), p)

    def evaluation(self, run_id, baseline_id=None):
        """The verdict on a run against a baseline (None: judged without one), or None."""
        p = self._params()
        where = f"evaluations.run_id = {p(run_id)} AND evaluations.baseline_id "
        where += "IS NULL" if baseline_id is None else f"= {p(baseline_id)}"
        rows = self._select_evaluations(where, p)
        return rows[0] if rows else None

    # --- maintenance ---

    def check(self):
        """Check the history's integrity (SQLite ``quick_check``); raise one line if damaged."""
        self._conn.check()

    def backup(self, path):
        """Back up the history's committed state into ``path``.

        SQLite: a SQLite file made through the backup API (the committed
        content of the file and of its ``-wal``), checked, self-contained,
        renamed into place. PostgreSQL: ``pg_dump --format=custom`` of the
        history's schema (restore with ``pg_restore --dbname URL FILE``).

        Parameters
        ----------
        path : str or Path
            The backup file; replaced if it exists.

        Returns
        -------
        Path
            ``path``.
        """
        if self._depth:
            raise HistoryError(f"history {self.location}: back up outside a transaction")
        return self._conn.backup(path)
