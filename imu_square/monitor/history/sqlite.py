"""The history in one SQLite file: the embedded default.

- WAL journal with ``synchronous=FULL``: a transaction is on disk when its
  COMMIT returns, and readers never block the writer.
- ``isolation_level=None``: Python's sqlite3 then opens no transaction behind
  our back (an insert left in an implicit transaction is lost on SIGKILL).
  Writes are explicit ``BEGIN IMMEDIATE`` ... ``COMMIT``; a reader takes
  ``BEGIN`` (deferred) for one consistent snapshot.
- A busy timeout: a writer waits for another process's transaction to end,
  up to ``busy_timeout_s``, rather than failing at once.
- Foreign keys on; ``PRAGMA quick_check`` on open.
- Back-ups through SQLite's backup API, which reads the committed pages of
  the file *and* its ``-wal`` (a copy of the ``.db`` alone loses what the WAL
  holds), into a temporary file beside the target, checked, then renamed.
- The last connection to close checkpoints the WAL into the file.
"""

import sqlite3
import time
from pathlib import Path

from imu_square.errors import HistoryError
from imu_square.log import logger
from imu_square.monitor.history.backend import Backend
from imu_square.monitor.history.encoding import first_line

# A writer waits this long for another process's transaction before it says it is waiting. [s]
_QUIET_WAIT_S = 2.0
#: RETURNING needs SQLite 3.35.
MIN_SQLITE = (3, 35, 0)


class SqliteBackend(Backend):
    """One connection to a history file.

    Parameters
    ----------
    path : str or Path
        The history file; created, with its folder, when missing.
    busy_timeout_s : float
        How long a writer waits for another process's transaction. [s]
    """

    name = "sqlite"
    # a writer takes the one write lock at once, a reader gets one consistent snapshot
    BEGIN_WRITE = "BEGIN IMMEDIATE"
    errors = (sqlite3.Error,)

    def __init__(self, path, busy_timeout_s):
        self.path = Path(path).expanduser()
        self.location = str(self.path)
        self.busy_timeout_s = busy_timeout_s
        if sqlite3.sqlite_version_info < MIN_SQLITE:
            raise HistoryError(
                f"history {self.location}: needs SQLite {'.'.join(map(str, MIN_SQLITE))} or "
                f"later, this Python has {sqlite3.sqlite_version}"
            )
        if self.path.is_dir():
            raise HistoryError(f"history {self.location}: is a folder, not a history file")
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            raise HistoryError(
                f"history {self.location}: cannot create its folder: {exc.strerror}"
            ) from None
        try:
            self.conn = sqlite3.connect(self.path, timeout=busy_timeout_s, isolation_level=None)
        except sqlite3.Error as exc:
            raise self._error(exc) from exc
        try:
            self.execute("PRAGMA foreign_keys = ON")
            mode = self._switch_to_wal()
            if mode.lower() != "wal":
                raise HistoryError(
                    f"history {self.location}: the file system does not allow SQLite's WAL "
                    f"journal (journal_mode stays {mode!r}); keep the history on a local disk"
                )
            self.execute("PRAGMA synchronous = FULL")
            self.check()
        except BaseException:
            self.conn.close()
            raise

    def _switch_to_wal(self):
        """Set the WAL journal, waiting out other processes doing the same.

        Two processes opening a fresh file at once may both read it in rollback
        mode and then both need the exclusive lock to switch: SQLite returns
        "locked" at once to one of them, without the busy handler (it would
        deadlock). Its statement has then released its lock, so retry.
        """
        deadline = time.monotonic() + self.busy_timeout_s
        while True:
            try:
                return self.conn.execute("PRAGMA journal_mode = WAL").fetchone()[0]
            except sqlite3.Error as exc:
                if "locked" not in str(exc) or time.monotonic() > deadline:
                    raise self._error(exc) from exc
            time.sleep(0.01)

    def _error(self, exc):
        """One line naming the file, for any sqlite3 error."""
        text = first_line(exc)
        low = text.lower()
        if "not a database" in low:
            why = "not a SQLite database"
        elif "malformed" in low or "corrupt" in low:
            why = f"the database is damaged ({text}); restore it from a backup"
        elif "unable to open" in low or "readonly" in low or "read-only" in low:
            why = f"cannot open it for writing ({text}): is the location read-only?"
        elif "locked" in low or "busy" in low:
            why = (
                f"another process held the history for more than {self.busy_timeout_s:g} s ({text})"
            )
        else:
            why = text
        return HistoryError(f"history {self.location}: {why}")

    def _begin(self, write):
        """``BEGIN``, or ``BEGIN IMMEDIATE`` that says so when another process holds the
        history longer than a moment, and then waits the rest of the busy timeout."""
        if not write:
            return self.execute(self.BEGIN_READ)
        quiet_s = min(_QUIET_WAIT_S, self.busy_timeout_s)
        try:
            self._busy_timeout(quiet_s)
            try:
                return self.conn.execute(self.BEGIN_WRITE)
            except sqlite3.OperationalError as exc:
                if "locked" not in str(exc) and "busy" not in str(exc):
                    raise self._error(exc) from exc
            logger.warning(
                "history %s is busy (another process is writing it): waiting up to %g s more",
                self.location,
                self.busy_timeout_s - quiet_s,
            )
            self._busy_timeout(self.busy_timeout_s - quiet_s)
            return self.execute(self.BEGIN_WRITE)
        finally:
            self._busy_timeout(self.busy_timeout_s)

    def _busy_timeout(self, seconds):
        self.conn.execute(f"PRAGMA busy_timeout = {round(seconds * 1000)}")

    @staticmethod
    def mark(i):
        """The marker of the ``i``-th parameter (from 1) in a statement: sqlite3's ``?``."""
        return "?"

    def lock_schema(self):
        """Nothing to do: ``BEGIN IMMEDIATE`` already holds the one write lock."""

    def tables(self):
        """Names of the tables in the file."""
        rows = self.query(
            "SELECT name FROM sqlite_master WHERE type = 'table' AND name NOT LIKE 'sqlite\\_%' "
            "ESCAPE '\\'"
        )
        return {r[0] for r in rows}

    def columns(self, table):
        """Column names of ``table``, in the table's order."""
        return [r[1] for r in self.query(f"PRAGMA table_info({table})")]

    def check(self):
        """Run ``PRAGMA quick_check``; raise one line naming the file if it fails."""
        problems = [r[0] for r in self.query("PRAGMA quick_check") if r[0] != "ok"]
        if problems:
            more = f" and {len(problems) - 1} more" if len(problems) > 1 else ""
            raise HistoryError(
                f"history {self.location}: the database is damaged (quick_check: "
                f"{first_line(problems[0])}{more}); restore it from a backup"
            )

    def _dump(self, dest, tmp):
        """Copy the committed state through the backup API into the SQLite file ``tmp``.

        The copy is checked with ``quick_check`` and switched to a rollback
        journal: one self-contained file.
        """
        if dest.exists() and dest.resolve() == self.path.resolve():
            raise HistoryError(f"history backup {dest}: is the history itself")
        target = sqlite3.connect(tmp, isolation_level=None)
        try:
            self.conn.backup(target)
            problems = [r[0] for r in target.execute("PRAGMA quick_check") if r[0] != "ok"]
            if problems:
                raise sqlite3.DatabaseError(f"the copy fails quick_check: {problems[0]}")
            target.execute("PRAGMA journal_mode = DELETE")
        finally:
            target.close()
