"""The history on a PostgreSQL server: one central history for many machines and replays.

psycopg 3 is imported here only (extra ``imu-square[postgres]``), so the
SQLite path never needs it.

- The connection is in autocommit; the store's transactions are explicit.
- Statements go to the server as written, with PostgreSQL's own ``$1``
  parameters (psycopg's ``RawCursor``): psycopg never parses them, so a
  literal ``%`` or ``?`` in SQL is just that.
  A reader's transaction is ``REPEATABLE READ, READ ONLY``: one snapshot.
- ``lock_timeout`` is the busy timeout: a writer blocked by another's lock
  waits that long, then fails with one line.
- Creating or migrating the schema takes a transaction-scoped advisory lock,
  so two processes opening a fresh history at once create it once.
- The tables live in the connection's current schema, the first existing one
  of ``search_path``; another is chosen in the URL with
  ``?options=-csearch_path%3Dname``.
- :meth:`PostgresBackend.backup` runs ``pg_dump --format=custom`` on that
  schema, as an argument list with the password in the environment (never a
  shell, never on a command line); ``pg_restore --dbname URL FILE`` restores
  it. Without ``pg_dump`` it refuses with one line.
"""

import glob
import os
import re
import shutil
import subprocess

from imu_square.errors import HistoryError
from imu_square.monitor.history.backend import Backend
from imu_square.monitor.history.encoding import first_line


def redact(url):
    """``url`` with its password replaced by ``***``, fit for messages and logs."""
    url = re.sub(r"(://[^/@:?]*:)[^/@?]*@", r"\1***@", url)
    return re.sub(r"(password=)[^&\s]*", r"\1***", url)


class PostgresBackend(Backend):
    """One connection to a history on a PostgreSQL server.

    Parameters
    ----------
    url : str
        ``postgresql://[user[:password]@][host][:port][/dbname][?param=value&...]``,
        as libpq takes it.
    busy_timeout_s : float
        How long a writer waits for another's lock. [s]
    """

    name = "postgresql"
    # a reader sees one snapshot
    BEGIN_READ = "BEGIN ISOLATION LEVEL REPEATABLE READ, READ ONLY"

    def __init__(self, url, busy_timeout_s):
        self.url = url
        self.location = redact(url)
        self.busy_timeout_s = busy_timeout_s
        try:
            import psycopg
            from psycopg import conninfo
        except ImportError:
            raise HistoryError(
                f"history {self.location}: a PostgreSQL history needs psycopg 3: "
                "pip install 'imu-square[postgres]'"
            ) from None
        self._psycopg = psycopg
        self.errors = (psycopg.Error,)
        try:
            params = conninfo.conninfo_to_dict(url)
        except psycopg.Error as exc:
            raise HistoryError(
                f"history {self.location}: not a valid PostgreSQL URL ({first_line(exc)})"
            ) from None
        extra = {"application_name": "imu-square", "connect_timeout": 10}
        extra = {k: v for k, v in extra.items() if k not in params}
        try:
            self.conn = psycopg.connect(
                url, autocommit=True, cursor_factory=psycopg.RawCursor, **extra
            )
        except psycopg.Error as exc:
            raise HistoryError(
                f"history {self.location}: cannot connect: {first_line(exc)}"
            ) from None
        try:
            self.query("SELECT set_config('lock_timeout', $1, false)", (f"{busy_timeout_s}s",))
            self.schema = self.query("SELECT current_schema()")[0][0]
            if self.schema is None:
                raise HistoryError(
                    f"history {self.location}: no schema to keep the history in: search_path "
                    "names none that exists (create it, or choose another with "
                    "?options=-csearch_path%3Dname)"
                )
        except BaseException:
            self.conn.close()
            raise

    def _error(self, exc):
        """One line naming the history, for any psycopg error."""
        if isinstance(exc, self._psycopg.errors.LockNotAvailable):
            why = f"another process held a lock for more than {self.busy_timeout_s:g} s"
        else:
            why = first_line(exc)
        return HistoryError(f"history {self.location}: {why}")

    @staticmethod
    def mark(i):
        """The marker of the ``i``-th parameter (from 1) in a statement: ``$i``."""
        return f"${i}"

    def lock_schema(self):
        """Serialise schema changes of this schema across processes, until the commit."""
        self.query(
            "SELECT pg_advisory_xact_lock(hashtext('imu-square history ' || current_schema()))"
        )

    def tables(self):
        """Names of the tables in the history's schema."""
        rows = self.query(
            "SELECT table_name FROM information_schema.tables WHERE table_schema = current_schema()"
        )
        return {r[0] for r in rows}

    def columns(self, table):
        """Column names of ``table``, in the table's order."""
        rows = self.query(
            "SELECT column_name FROM information_schema.columns "
            "WHERE table_schema = current_schema() AND table_name = $1 ORDER BY ordinal_position",
            (table,),
        )
        return [r[0] for r in rows]

    def check(self):
        """Nothing to check from the client: the server keeps its own files consistent."""

    def _dump(self, dest, tmp):
        """Dump the history's schema with ``pg_dump --format=custom`` into ``tmp``."""
        from psycopg import conninfo

        pg_dump = find_pg_tool("pg_dump")
        if pg_dump is None:
            raise HistoryError(
                f"history {self.location}: a backup of a PostgreSQL history needs pg_dump "
                "(Debian package postgresql-client), which is not installed"
            )
        params = conninfo.conninfo_to_dict(self.url)
        env = dict(os.environ)
        password = params.pop("password", None)
        if password is not None:
            env["PGPASSWORD"] = str(password)
        schema = '"' + self.schema.replace('"', '""') + '"'
        cmd = [
            pg_dump,
            "--format=custom",
            f"--schema={schema}",
            f"--file={tmp}",
            f"--dbname={conninfo.make_conninfo('', **params)}",
        ]
        done = subprocess.run(cmd, env=env, capture_output=True, text=True, check=False)
        if done.returncode != 0:
            raise HistoryError(
                f"history {self.location}: backup to {dest} failed: pg_dump: "
                f"{first_line(done.stderr or f'exit status {done.returncode}')}"
            )


def find_pg_tool(name):
    """Path of a PostgreSQL client program: on PATH, else the newest Debian install.

    Parameters
    ----------
    name : str
        ``"pg_dump"``, ``"pg_restore"``, ``"initdb"``, ...

    Returns
    -------
    str or None
        The program, or None if it is not installed.
    """
    found = shutil.which(name)
    if found:
        return found
    candidates = glob.glob(f"/usr/lib/postgresql/*/bin/{name}")
    candidates.sort(key=lambda p: int(re.search(r"/(\d+)/bin/", p).group(1)))
    return candidates[-1] if candidates else None
