"""A throw-away PostgreSQL 15 + PostGIS cluster for the tests (Debian's postgresql-15 and
postgresql-15-postgis-3, installed by ``scripts/install.sh --test``).

``initdb`` in a temporary directory, ``pg_ctl`` on a free 127.0.0.1 port (trust
authentication, the cluster is reachable by this machine only and lives for one test
session), a template database with PostGIS created by the superuser; each test gets a fresh
database copied from it (:meth:`Cluster.new_database`). The cluster is stopped and its
directory removed at the end of the session, also when tests fail (fixture finaliser and an
atexit hook). As root (initdb refuses to run as root) the server runs as the ``postgres`` user.

Use: ``from pgcluster import pg_cluster  # noqa: F401`` in a test module, then a test or
fixture asks for ``pg_cluster``.
"""

from __future__ import annotations

import atexit
import itertools
import os
import pwd
import shutil
import socket
import subprocess
import tempfile
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

PG_BIN = Path("/usr/lib/postgresql/15/bin")
POSTGIS_CONTROL = Path("/usr/share/postgresql/15/extension/postgis.control")
SUPERUSER = "postgres"
TEMPLATE = "gsgeo_template"


def missing_reason() -> str | None:
    """Why a cluster cannot be started here (None: it can)."""
    if not (PG_BIN / "initdb").is_file():
        return f"PostgreSQL 15 is not installed ({PG_BIN}/initdb missing: apt postgresql-15)"
    if not POSTGIS_CONTROL.is_file():
        return f"PostGIS is not installed ({POSTGIS_CONTROL} missing: apt postgresql-15-postgis-3)"
    try:
        import psycopg  # noqa: F401
        import psycopg_pool  # noqa: F401
    except ImportError as exc:
        return f"psycopg 3 / psycopg-pool are not installed ({exc}: pip install -e '.[test]')"
    return None


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


class Cluster:
    """One running cluster; ``url(db)`` is a libpq URL of one of its databases."""

    def __init__(self) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="gsgeo-pg-"))
        self.data = self.dir / "data"
        self.port = free_port()
        self._count = itertools.count(1)
        self._lock = threading.Lock()
        self._running = False
        self._as: list[str] = []
        if os.geteuid() == 0:
            pw = pwd.getpwnam("postgres")
            os.chown(self.dir, pw.pw_uid, pw.pw_gid)
            self._as = ["setpriv", f"--reuid={pw.pw_uid}", f"--regid={pw.pw_gid}",
                        "--init-groups"]
        try:
            self._run("initdb", "-D", str(self.data), "-U", SUPERUSER, "--auth=trust",
                      "-E", "UTF8", "--locale=C.UTF-8", "--no-sync")
            self._run("pg_ctl", "-D", str(self.data), "-l", str(self.dir / "log"), "-w",
                      "-t", "60", "-o",
                      f"-p {self.port} -c listen_addresses=127.0.0.1"
                      f" -c unix_socket_directories={self.dir} -c fsync=off"
                      " -c max_connections=200", "start")
            self._running = True
            self.sql("postgres", f"CREATE DATABASE {TEMPLATE}")
            self.sql(TEMPLATE, "CREATE EXTENSION postgis")
        except BaseException:
            self.stop()
            raise

    def _run(self, tool: str, *args: str) -> None:
        proc = subprocess.run([*self._as, str(PG_BIN / tool), *args], capture_output=True,
                              text=True, cwd=self.dir, timeout=120)
        if proc.returncode != 0:
            log = self.dir / "log"
            tail = log.read_text()[-2000:] if log.is_file() else ""
            raise RuntimeError(f"{tool} failed ({proc.returncode}): {proc.stderr}{tail}")

    def url(self, db: str, user: str = SUPERUSER, password: str | None = None) -> str:
        auth = user if password is None else f"{user}:{password}"
        return f"postgresql://{auth}@127.0.0.1:{self.port}/{db}"

    def sql(self, db: str, statement: str) -> list[tuple]:
        """Run one statement as the superuser (autocommit); its rows, if any."""
        import psycopg

        with psycopg.connect(self.url(db), autocommit=True) as con:
            cur = con.execute(statement)  # type: ignore[arg-type]
            return cur.fetchall() if cur.description else []

    def new_database(self, postgis: bool = True) -> str:
        """A fresh, empty database (with PostGIS, from the template, unless told otherwise);
        its name."""
        with self._lock:
            name = f"t{next(self._count)}"
        template = TEMPLATE if postgis else "template0"
        self.sql("postgres", f"CREATE DATABASE {name} TEMPLATE {template}")
        return name

    def stop(self) -> None:
        if self._running:
            self._running = False
            try:
                self._run("pg_ctl", "-D", str(self.data), "-m", "immediate", "-w", "stop")
            except (RuntimeError, subprocess.TimeoutExpired):
                pass
        shutil.rmtree(self.dir, ignore_errors=True)


_cluster: Cluster | None = None
_cluster_lock = threading.Lock()


def cluster() -> Cluster:
    """The session's cluster, started on first use (skips the test where it cannot be)."""
    global _cluster
    reason = missing_reason()
    if reason is not None:
        pytest.skip(reason)
    with _cluster_lock:
        if _cluster is None:
            _cluster = Cluster()
            atexit.register(_cluster.stop)
        return _cluster


@pytest.fixture(scope="session")
def pg_cluster() -> Iterator[Cluster]:
    """The running cluster; stopped when the session ends, passed or failed."""
    c = cluster()
    try:
        yield c
    finally:
        c.stop()
