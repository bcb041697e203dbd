"""What the SQLite and PostgreSQL backends share: statements, transactions, savepoints, backups.

Both connections run in autocommit (the driver opens no transaction of its
own), so a transaction is SQL: the backend's ``BEGIN_WRITE`` or
``BEGIN_READ``, then ``COMMIT``, or ``ROLLBACK`` when the body raises. A
savepoint is SQL too, the same on both.
Every driver error becomes one :class:`~imu_square.errors.HistoryError` line
naming the history (each backend's ``_error``).
"""

import os
from contextlib import contextmanager, suppress
from pathlib import Path

from imu_square.errors import HistoryError
from imu_square.io.atomic import fsync_dir
from imu_square.monitor.history.encoding import first_line


class Backend:
    """The methods both backends share; a backend sets ``conn``, ``location`` and ``errors``.

    Attributes
    ----------
    BEGIN_WRITE, BEGIN_READ : str
        The statements that open a write and a read transaction.
    errors : tuple of type
        The driver's errors, turned into :class:`HistoryError` by ``_error``.
    """

    BEGIN_WRITE = BEGIN_READ = "BEGIN"
    errors = ()

    def execute(self, sql, params=()):
        """Run one statement; return the number of rows it changed."""
        try:
            return self.conn.execute(sql, params).rowcount
        except self.errors as exc:
            raise self._error(exc) from exc

    def query(self, sql, params=()):
        """Run one statement; return all its rows as tuples."""
        try:
            return self.conn.execute(sql, params).fetchall()
        except self.errors as exc:
            raise self._error(exc) from exc

    def _quietly(self, *statements):
        # after a failure: the connection may be gone or the transaction already ended,
        # and the error that brought us here is the one to report
        with suppress(self.errors):
            for sql in statements:
                self.conn.execute(sql)

    def _begin(self, write):
        """Open a write or a read transaction."""
        self.execute(self.BEGIN_WRITE if write else self.BEGIN_READ)

    @contextmanager
    def transaction(self, write):
        """One transaction: ``BEGIN_WRITE`` or ``BEGIN_READ``, the body, COMMIT or ROLLBACK."""
        self._begin(write)
        try:
            yield
            self.execute("COMMIT")
        except BaseException:
            self._quietly("ROLLBACK")
            raise

    @contextmanager
    def savepoint(self):
        """A savepoint inside the open transaction: undone alone if the body fails."""
        self.execute("SAVEPOINT imu_square_write")
        try:
            yield
        except BaseException:
            self._quietly("ROLLBACK TO imu_square_write", "RELEASE imu_square_write")
            raise
        self.execute("RELEASE imu_square_write")

    def backup(self, path):
        """Write the history's committed state into ``path`` (each backend's ``_dump``).

        The backup is written beside ``path``, synced and renamed over it, so
        ``path`` is never a half-written file.

        Parameters
        ----------
        path : str or Path
            The backup file; replaced if it exists.

        Returns
        -------
        Path
            ``path``.
        """
        dest = Path(path).expanduser()
        if dest.is_dir():
            raise HistoryError(f"history backup {dest}: is a folder, not a file")
        tmp = dest.with_name(f".{dest.name}.{os.getpid()}.partial")
        try:
            self._dump(dest, tmp)
            with open(tmp, "rb") as f:
                os.fsync(f.fileno())
            os.replace(tmp, dest)
            fsync_dir(dest.parent)
        except (OSError, *self.errors) as exc:
            raise HistoryError(
                f"history {self.location}: backup to {dest} failed: {first_line(exc)}"
            ) from exc
        finally:
            tmp.unlink(missing_ok=True)
        return dest

    def close(self):
        """Close the connection."""
        self.conn.close()
