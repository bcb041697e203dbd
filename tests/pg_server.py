"""A throw-away PostgreSQL server for the tests: initdb + postgres in a temporary folder.

Debian's ``postgresql`` package (``.ci/run`` installs it) puts ``initdb`` and
``postgres`` in ``/usr/lib/postgresql/<version>/bin``. The server listens on a
unix socket in its own folder only (no TCP port to collide with anything).
``initdb`` refuses to run as root, and CI runs as root: then the server runs
as the ``postgres`` user the package creates (or ``nobody``), through
``subprocess``'s ``user=``/``group=``, in a folder that user owns.

One server per test process (:func:`shared`), stopped at exit; each test gets
a fresh schema in it (:meth:`PgServer.new_url`), so tests never see each
other's tables.
"""

import atexit
import grp
import os
import pwd
import shutil
import signal
import subprocess
import tempfile
import time
import uuid
from pathlib import Path
from urllib.parse import quote

from imu_square.monitor.history.postgres import find_pg_tool

_SERVER = None
_FAILED = None


def skip_reason():
    """Why PostgreSQL tests cannot run here, or None: only missing server binaries."""
    if find_pg_tool("initdb") is None or find_pg_tool("postgres") is None:
        return (
            "PostgreSQL server binaries (initdb, postgres) are not installed: "
            "apt-get install postgresql"
        )
    return None


class PgServer:
    """A running throw-away server; :meth:`stop` ends it and removes its folder."""

    def __init__(self):
        initdb = os.path.realpath(find_pg_tool("initdb"))
        postgres = os.path.join(os.path.dirname(initdb), "postgres")
        if not os.path.exists(postgres):
            postgres = os.path.realpath(find_pg_tool("postgres"))
        self.root = Path(tempfile.mkdtemp(prefix="imu-square-pg-"))
        self.data = self.root / "data"
        self.log = self.root / "server.log"
        self._as = {}
        if os.geteuid() == 0:
            user = "postgres" if _has_user("postgres") else "nobody"
            entry = pwd.getpwnam(user)
            os.chown(self.root, entry.pw_uid, entry.pw_gid)
            self._as = {
                "user": entry.pw_uid,
                "group": entry.pw_gid,
                "extra_groups": [],
                "cwd": str(self.root),
            }
        self.user = "postgres"
        env = {"PATH": os.environ.get("PATH", ""), "LC_ALL": "C", "LANG": "C"}
        done = subprocess.run(
            [initdb, "-D", str(self.data), "-U", self.user, "-A", "trust", "-E", "UTF8",
             "--locale=C", "--no-sync"],
            capture_output=True, text=True, env=env, check=False, **self._as,
        )  # fmt: skip
        if done.returncode != 0:
            raise RuntimeError(f"initdb failed: {done.stderr.strip() or done.stdout.strip()}")
        self._log_file = open(self.log, "wb")  # open while the server runs
        self.proc = subprocess.Popen(
            [postgres, "-D", str(self.data), "-k", str(self.root),
             "-c", "listen_addresses=", "-c", "max_connections=60"],
            stdout=self._log_file, stderr=subprocess.STDOUT, env=env, **self._as,
        )  # fmt: skip
        self._wait_ready()

    def _wait_ready(self):
        import psycopg

        deadline = time.monotonic() + 60
        while True:
            if self.proc.poll() is not None:
                raise RuntimeError(f"postgres exited: {self.log.read_text(errors='replace')}")
            try:
                psycopg.connect(self.conninfo(), connect_timeout=2).close()
                return
            except psycopg.OperationalError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.1)

    def conninfo(self, dbname="postgres"):
        """libpq key/value string for a database of this server."""
        return f"host={self.root} user={self.user} dbname={dbname}"

    def url(self, dbname="postgres", schema=None):
        """A ``postgresql://`` URL of a database (and a schema) of this server."""
        query = f"host={quote(str(self.root), safe='/')}&user={self.user}"
        if schema is not None:
            query += "&options=" + quote(f"-csearch_path={schema}", safe="")
        return f"postgresql:///{dbname}?{query}"

    def new_url(self):
        """A fresh, empty schema and the URL whose search_path names it."""
        import psycopg

        schema = f"t_{uuid.uuid4().hex[:16]}"
        with psycopg.connect(self.conninfo(), autocommit=True) as conn:
            conn.execute(f"CREATE SCHEMA {schema}")
        return self.url(schema=schema)

    def new_database(self):
        """A fresh, empty database; returns its name."""
        import psycopg

        name = f"d_{uuid.uuid4().hex[:16]}"
        with psycopg.connect(self.conninfo(), autocommit=True) as conn:
            conn.execute(f"CREATE DATABASE {name}")
        return name

    def stop(self):
        """Fast shutdown, then remove the folder."""
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGINT)
            try:
                self.proc.wait(30)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self._log_file.close()
        shutil.rmtree(self.root, ignore_errors=True)


def _has_user(name):
    try:
        pwd.getpwnam(name)
        grp.getgrgid(pwd.getpwnam(name).pw_gid)
    except KeyError:
        return False
    return True


def shared():
    """The test process's one server, started on first use and stopped at exit."""
    global _SERVER, _FAILED
    if _FAILED is not None:
        raise RuntimeError(_FAILED)
    if _SERVER is None:
        try:
            _SERVER = PgServer()
        except Exception as exc:
            _FAILED = f"the throw-away PostgreSQL server did not start: {exc}"
            raise
        atexit.register(_SERVER.stop)
    return _SERVER


def location_for(backend, tmp_path):
    """A fresh, empty history location of ``backend`` ("sqlite" or "postgresql")."""
    if backend == "sqlite":
        return str(tmp_path / "history.db")
    import pytest

    reason = skip_reason()
    if reason:
        pytest.skip(reason)
    return shared().new_url()
