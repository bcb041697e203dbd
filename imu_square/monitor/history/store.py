"""The monitor's history: one API over SQLite (the embedded default) and PostgreSQL.

>>> with open_history("history.db") as history:  # doctest: +SKIP
...     run_id, inserted = history.add_run(row)
...     runs = history.runs("mill-3", valid_only=True)

:func:`open_history` takes a file path (SQLite) or a ``postgresql://`` URL
(psycopg 3, extra ``imu-square[postgres]``), checks the history, creates or
migrates its schema (:mod:`imu_square.monitor.history.schema`) and returns a
:class:`History`. Its methods take and return the frozen rows of
:mod:`imu_square.monitor.history.rows` (imported here too, with the keys of a run:
:func:`file_sha256` of the recording and :func:`settings_hash` of the
analysis settings).

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

import json
import os
import re
from contextlib import contextmanager, nullcontext
from dataclasses import fields
from datetime import datetime
from pathlib import Path

from imu_square.errors import HistoryError
from imu_square.log import logger
from imu_square.monitor.history import schema
from imu_square.monitor.history.encoding import (
    canonical_json,
    datetime_from_ns,
    file_sha256,
    now_ns,
    ns_from_datetime,
    settings_hash,
)
from imu_square.monitor.history.rows import (
    EVALUATION_STATES,
    AnchorRow,
    BaselineRow,
    EvaluationRow,
    RunRow,
)

__all__ = [
    "EVALUATION_STATES",
    "AnchorRow",
    "BaselineRow",
    "EvaluationRow",
    "History",
    "RunRow",
    "datetime_from_ns",
    "default_history_path",
    "file_sha256",
    "ns_from_datetime",
    "open_history",
    "settings_hash",
]

#: Seconds a writer waits for another process's transaction by default.
BUSY_TIMEOUT_S = 60.0

_URL = re.compile(r"^([A-Za-z][A-Za-z0-9+.-]*)://")

# Row field -> table column, where they differ (JSON fields are stored as text).
_RUN_JSON = {
    "settings": "settings_json",
    "quality": "quality_json",
    "warnings": "warnings_json",
    "per_cycle": "per_cycle_json",
    "result": "result_json",
}
_RUN_FIELDS = [f.name for f in fields(RunRow)]
_RUN_COLUMNS = [_RUN_JSON.get(n, n) for n in _RUN_FIELDS]
_BASELINE_JSON = {"alarm_design": "alarm_design_json"}
_BASELINE_FIELDS = [f.name for f in fields(BaselineRow) if f.name != "run_ids"]
_BASELINE_COLUMNS = [_BASELINE_JSON.get(n, n) for n in _BASELINE_FIELDS]
_ANCHOR_JSON = {"input": "input_json"}
_ANCHOR_FIELDS = [f.name for f in fields(AnchorRow)]
_ANCHOR_COLUMNS = [_ANCHOR_JSON.get(n, n) for n in _ANCHOR_FIELDS]
_EVALUATION_JSON = {"statistics": "statistics_json"}
_EVALUATION_FIELDS = [f.name for f in fields(EvaluationRow)]
_EVALUATION_COLUMNS = [_EVALUATION_JSON.get(n, n) for n in _EVALUATION_FIELDS]

#: Every table's columns as this module reads and writes them.
COLUMNS = {
    "runs": _RUN_COLUMNS,
    "baselines": _BASELINE_COLUMNS,
    "baseline_runs": ["baseline_id", "run_id"],
    "anchors": _ANCHOR_COLUMNS,
    "evaluations": _EVALUATION_COLUMNS,
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
    if not isinstance(location, str | os.PathLike) or not str(location).strip():
        raise HistoryError(
            f"history location must be a file path or a postgresql:// URL, got {location!r}"
        )
    if is_postgres_url(location):
        from imu_square.monitor.history.postgres import PostgresBackend

        backend = PostgresBackend(str(location), busy_timeout_s)
    elif _URL.match(str(location)):
        raise HistoryError(
            f"history location must be a file path or a postgresql:// URL, got {location!r}"
        )
    else:
        from imu_square.monitor.history.sqlite import SqliteBackend

        backend = SqliteBackend(location, busy_timeout_s)
    try:
        before = schema.current_version(backend)
        after = schema.migrate(backend)
    except BaseException:
        backend.close()
        raise
    if before != after:
        logger.info("history %s: schema version %d -> %d", backend.location, before, after)
    return History(backend, after)


def _ns(name, value):
    if value is None or (isinstance(value, int) and not isinstance(value, bool)):
        return value
    if isinstance(value, datetime):
        return ns_from_datetime(value)
    raise HistoryError(f"{name} must be integer nanoseconds or an aware datetime, got {value!r}")


def _marks(n):
    return ", ".join("?" * n)


class History:
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
        values = []
        for name in _RUN_FIELDS:
            value = getattr(row, name)
            if name == "analysed_at_ns" and value is None:
                value = now_ns()
            elif name in _RUN_JSON:
                value = canonical_json(value, f"RunRow.{name}")
            values.append(value)
        columns = _RUN_COLUMNS[1:]
        with self._write():
            got = self._conn.query(
                f"INSERT INTO runs ({', '.join(columns)}) VALUES ({_marks(len(columns))}) "
                "ON CONFLICT (machine_id, recording_sha256, settings_hash) DO NOTHING "
                "RETURNING id",
                values[1:],
            )
            if got:
                logger.debug("history %s: run %d stored", self.location, got[0][0])
                return got[0][0], True
            got = self._conn.query(
                "SELECT id FROM runs WHERE machine_id = ? AND recording_sha256 = ? "
                "AND settings_hash = ?",
                (row.machine_id, row.recording_sha256, row.settings_hash),
            )
        logger.debug("history %s: run %d was already there", self.location, got[0][0])
        return got[0][0], False

    def _select_runs(self, where, params, order=True):
        sql = f"SELECT {', '.join(_RUN_COLUMNS)} FROM runs WHERE {where}"
        if order:
            sql += " ORDER BY recorded_at_ns IS NULL, recorded_at_ns, id"
        return [self._run_row(r) for r in self._conn.query(sql, params)]

    @staticmethod
    def _run_row(values):
        kw = {}
        for name, value in zip(_RUN_FIELDS, values, strict=True):
            if name in _RUN_JSON:
                value = json.loads(value)
            elif name == "valid":
                value = bool(value)
            kw[name] = value
        return RunRow(**kw)

    def run(self, run_id):
        """The run with id ``run_id``; raise if there is none."""
        rows = self._select_runs("id = ?", (run_id,), order=False)
        if not rows:
            raise HistoryError(f"history {self.location}: no run {run_id!r}")
        return rows[0]

    def run_by_hash(self, machine_id, recording_sha256, settings_hash):
        """The run of this recording under these settings, or None.

        Parameters
        ----------
        machine_id : str
            The machine.
        recording_sha256 : str
            :func:`file_sha256` of the recording.
        settings_hash : str
            :func:`settings_hash` of the settings.

        Returns
        -------
        RunRow or None
        """
        rows = self._select_runs(
            "machine_id = ? AND recording_sha256 = ? AND settings_hash = ?",
            (machine_id, recording_sha256.lower(), settings_hash.lower()),
            order=False,
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
        sql = "SELECT recording_sha256 FROM runs WHERE machine_id = ?"
        params = [machine_id]
        if settings_hash is not None:
            sql += " AND settings_hash = ?"
            params.append(settings_hash)
        return {r[0] for r in self._conn.query(sql, params)}

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
        where, params = ["machine_id = ?"], [machine_id]
        since, until = _ns("since", since), _ns("until", until)
        if since is not None:
            where.append("recorded_at_ns >= ?")
            params.append(since)
        if until is not None:
            where.append("recorded_at_ns < ?")
            params.append(until)
        if valid_only:
            where.append("valid = ?")
            params.append(True)
        if settings_hash is not None:
            where.append("settings_hash = ?")
            params.append(settings_hash)
        return self._select_runs(" AND ".join(where), params)

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
            found = {
                r[0]: r[1:]
                for r in self._conn.query(
                    "SELECT id, machine_id, valid, invalid_reason, settings_hash, recorded_at_ns "
                    f"FROM runs WHERE id IN ({_marks(len(row.run_ids))})",
                    row.run_ids,
                )
            }
            missing = [i for i in row.run_ids if i not in found]
            if missing:
                raise HistoryError(
                    f"BaselineRow.run_ids: history {self.location} has no run {missing!r}"
                )
            for run_id, (machine, valid, reason, _, _) in sorted(found.items()):
                if machine != row.machine_id:
                    raise HistoryError(
                        f"BaselineRow.run_ids: run {run_id} is of machine {machine!r}, "
                        f"not {row.machine_id!r}"
                    )
                if not valid:
                    raise HistoryError(
                        f"BaselineRow.run_ids: run {run_id} is invalid ({reason}); "
                        "an invalid run never enters a baseline"
                    )
            hashes = sorted({v[3] for v in found.values()})
            if len(hashes) > 1:
                raise HistoryError(
                    f"BaselineRow.run_ids: the runs were analysed with {len(hashes)} different "
                    "settings; a baseline's runs must share one"
                )
            times = [v[4] for v in found.values() if v[4] is not None]
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
            values = {n: getattr(row, n) for n in _BASELINE_FIELDS} | derived
            if values["created_at_ns"] is None:
                values["created_at_ns"] = now_ns()
            values["alarm_design"] = canonical_json(row.alarm_design, "BaselineRow.alarm_design")
            baseline_id = self._conn.query(
                f"INSERT INTO baselines ({', '.join(_BASELINE_COLUMNS[1:])}) "
                f"VALUES ({_marks(len(_BASELINE_COLUMNS) - 1)}) RETURNING id",
                [values[n] for n in _BASELINE_FIELDS[1:]],
            )[0][0]
            for run_id in row.run_ids:
                self._conn.execute(
                    "INSERT INTO baseline_runs (baseline_id, run_id) VALUES (?, ?)",
                    (baseline_id, run_id),
                )
        logger.debug("history %s: baseline %d stored", self.location, baseline_id)
        return baseline_id

    def _select_baselines(self, where, params):
        with self._read():
            rows = self._conn.query(
                f"SELECT {', '.join(_BASELINE_COLUMNS)} FROM baselines WHERE {where} ORDER BY id",
                params,
            )
            out = []
            for values in rows:
                kw = dict(zip(_BASELINE_FIELDS, values, strict=True))
                kw["stale"] = bool(kw["stale"])
                kw["alarm_design"] = json.loads(kw["alarm_design"])
                kw["run_ids"] = tuple(
                    r[0]
                    for r in self._conn.query(
                        "SELECT run_id FROM baseline_runs WHERE baseline_id = ? ORDER BY run_id",
                        (kw["id"],),
                    )
                )
                out.append(BaselineRow(**kw))
        return out

    def baseline(self, baseline_id):
        """The baseline with id ``baseline_id``; raise if there is none."""
        rows = self._select_baselines("id = ?", (baseline_id,))
        if not rows:
            raise HistoryError(f"history {self.location}: no baseline {baseline_id!r}")
        return rows[0]

    def baselines(self, machine_id):
        """Every baseline of a machine, oldest first."""
        return self._select_baselines("machine_id = ?", (machine_id,))

    def current_baseline(self, machine_id):
        """The machine's current baseline (its latest, stale or not), or None."""
        rows = self._select_baselines(
            "id = (SELECT MAX(id) FROM baselines WHERE machine_id = ?)", (machine_id,)
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
            changed = self._conn.execute(
                "UPDATE baselines SET stale = ?, stale_reason = ?, stale_at_ns = ? "
                "WHERE id = ? AND stale = ?",
                (True, reason, now_ns() if at_ns is None else at_ns, baseline_id, False),
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
        text = canonical_json(design, "alarm design")
        with self._write():
            if not self._conn.execute(
                "UPDATE baselines SET alarm_design_json = ? WHERE id = ?", (text, baseline_id)
            ):
                self._require("baselines", baseline_id, "baseline")

    def _require(self, table, row_id, what):
        if not self._conn.query(f"SELECT 1 FROM {table} WHERE id = ?", (row_id,)):
            raise HistoryError(f"history {self.location}: no {what} {row_id!r}")

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
        values = [getattr(row, n) for n in _ANCHOR_FIELDS]
        values[_ANCHOR_FIELDS.index("input")] = canonical_json(row.input, "AnchorRow.input")
        if row.created_at_ns is None:
            values[_ANCHOR_FIELDS.index("created_at_ns")] = now_ns()
        columns = _ANCHOR_COLUMNS[1:]
        with self._write():
            self._require("baselines", row.baseline_id, "baseline")
            return self._conn.query(
                f"INSERT INTO anchors ({', '.join(columns)}) VALUES ({_marks(len(columns))}) "
                "RETURNING id",
                values[1:],
            )[0][0]

    def anchors(self, baseline_id):
        """A baseline's anchors, oldest first."""
        rows = self._conn.query(
            f"SELECT {', '.join(_ANCHOR_COLUMNS)} FROM anchors WHERE baseline_id = ? ORDER BY id",
            (baseline_id,),
        )
        out = []
        for values in rows:
            kw = dict(zip(_ANCHOR_FIELDS, values, strict=True))
            kw["input"] = json.loads(kw["input"])
            out.append(AnchorRow(**kw))
        return out

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
        values = [getattr(row, n) for n in _EVALUATION_FIELDS]
        values[_EVALUATION_FIELDS.index("statistics")] = canonical_json(
            row.statistics, "EvaluationRow.statistics"
        )
        if row.created_at_ns is None:
            values[_EVALUATION_FIELDS.index("created_at_ns")] = now_ns()
        columns = _EVALUATION_COLUMNS[1:]
        target = (
            "(run_id) WHERE baseline_id IS NULL"
            if row.baseline_id is None
            else "(run_id, baseline_id) WHERE baseline_id IS NOT NULL"
        )
        updates = ", ".join(f"{c} = excluded.{c}" for c in columns)
        with self._write():
            run = self._conn.query("SELECT machine_id, valid FROM runs WHERE id = ?", (row.run_id,))
            if not run:
                raise HistoryError(f"history {self.location}: no run {row.run_id!r}")
            if not run[0][1] and row.state != "invalid":
                raise HistoryError(
                    f"EvaluationRow.state must be 'invalid' for the invalid run {row.run_id}, "
                    f"got {row.state!r}"
                )
            if row.baseline_id is not None:
                base = self._conn.query(
                    "SELECT machine_id FROM baselines WHERE id = ?", (row.baseline_id,)
                )
                if not base:
                    raise HistoryError(f"history {self.location}: no baseline {row.baseline_id!r}")
                if base[0][0] != run[0][0]:
                    raise HistoryError(
                        f"EvaluationRow: run {row.run_id} is of machine {run[0][0]!r} but "
                        f"baseline {row.baseline_id} of {base[0][0]!r}"
                    )
            return self._conn.query(
                f"INSERT INTO evaluations ({', '.join(columns)}) VALUES ({_marks(len(columns))}) "
                f"ON CONFLICT {target} DO UPDATE SET {updates} RETURNING id",
                values[1:],
            )[0][0]

    def _select_evaluations(self, where, params):
        cols = ", ".join(f"e.{c}" for c in _EVALUATION_COLUMNS)
        rows = self._conn.query(
            f"SELECT {cols} FROM evaluations e JOIN runs r ON r.id = e.run_id WHERE {where} "
            "ORDER BY r.recorded_at_ns IS NULL, r.recorded_at_ns, r.id, e.id",
            params,
        )
        out = []
        for values in rows:
            kw = dict(zip(_EVALUATION_FIELDS, values, strict=True))
            kw["statistics"] = json.loads(kw["statistics"])
            out.append(EvaluationRow(**kw))
        return out

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
        where, params = ["r.machine_id = ?"], [machine_id]
        since, until = _ns("since", since), _ns("until", until)
        if since is not None:
            where.append("r.recorded_at_ns >= ?")
            params.append(since)
        if until is not None:
            where.append("r.recorded_at_ns < ?")
            params.append(until)
        if baseline_id is not None:
            where.append("e.baseline_id = ?")
            params.append(baseline_id)
        return self._select_evaluations(" AND ".join(where), params)

    def evaluation(self, run_id, baseline_id=None):
        """The verdict on a run against a baseline (None: judged without one), or None."""
        if baseline_id is None:
            rows = self._select_evaluations("e.run_id = ? AND e.baseline_id IS NULL", (run_id,))
        else:
            rows = self._select_evaluations(
                "e.run_id = ? AND e.baseline_id = ?", (run_id, baseline_id)
            )
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
