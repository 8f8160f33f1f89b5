"""Benchmark `gsgeo serve` on its two store backends side by side: intersect and stored points.

    python benchmarks/store_load.py [--backends sqlite postgresql] [--store URL]
        [--kinds intersect points] [--loads one operators saturation]
        [--clients 50] [--requests 40] [--think 2] [--client-procs 2] [--pg-fsync on|off]
        [--store-threads N]
        [--json FILE]

For each backend, one `gsgeo serve` on a free 127.0.0.1 port with a fresh data directory:

- sqlite: the embedded default (DATA/gsgeo.sqlite, WAL, synchronous=FULL);
- postgresql: ``--store URL`` when given (an existing, empty database with PostGIS or a role
  that may create it), else a throw-away PostgreSQL 15 cluster started here as the tests do
  (``initdb`` + ``pg_ctl`` in a temporary directory on a free loopback port, trust
  authentication, PostGIS created by the superuser), with durable commits (fsync on, as the
  SQLite store's synchronous=FULL) unless ``--pg-fsync off``; stopped and removed at the end.

Two request kinds, each under the loads of benchmarks/server.py (one client back to back,
``--clients`` "operators" with exponential think time of mean ``--think`` s, the same
clients back to back = saturation):

- intersect: POST /api/intersect of a 5-ray point (no store involved: the control);
- points: POST /api/projects/bench/points of a 4-ray point, as the viewer stores a point;
  every operator stores into the same project, each point with its own id
  (``<load>-<client>-<n>``), so every request is one write transaction.

Latency is client-side from writing the request to having read the whole answer (keep-alive
HTTP/1.1 connections of asyncio clients in ``--client-procs`` forked processes; each
client's first request warms up and is not timed). Server CPU per request is read from /proc
for the gsgeo process (and its workers), and for PostgreSQL (the postmaster and its backends)
when the cluster was started here.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing as mp
import os
import pwd
import random
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from pathlib import Path

import httpx
import numpy as np

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "benchmarks"))
from server import cpu_seconds, free_port, point_rays, wait_up  # noqa: E402

PG_BIN = Path("/usr/lib/postgresql/15/bin")
PROJECT = "bench"


class PgCluster:
    """A throw-away PostgreSQL cluster with a PostGIS database ``bench`` (as tests/pgcluster.py)."""

    def __init__(self, fsync: bool) -> None:
        self.dir = Path(tempfile.mkdtemp(prefix="gsgeo-bench-pg-"))
        self.data = self.dir / "data"
        self.port = free_port()
        self.running = False
        self.run_as: list[str] = []
        if os.geteuid() == 0:  # initdb refuses to run as root
            pw = pwd.getpwnam("postgres")
            os.chown(self.dir, pw.pw_uid, pw.pw_gid)
            self.run_as = ["setpriv", f"--reuid={pw.pw_uid}", f"--regid={pw.pw_gid}",
                           "--init-groups"]
        try:
            self.tool("initdb", "-D", str(self.data), "-U", "postgres", "--auth=trust",
                      "-E", "UTF8", "--locale=C.UTF-8")
            opts = (f"-p {self.port} -c listen_addresses=127.0.0.1"
                    f" -c unix_socket_directories={self.dir} -c max_connections=200"
                    f" -c fsync={'on' if fsync else 'off'}")
            self.tool("pg_ctl", "-D", str(self.data), "-l", str(self.dir / "log"), "-w",
                      "-t", "60", "-o", opts, "start")
            self.running = True
            self.sql("postgres", "CREATE DATABASE bench")
            self.sql("bench", "CREATE EXTENSION postgis")
        except BaseException:
            self.stop()
            raise

    def tool(self, name: str, *args: str) -> None:
        proc = subprocess.run([*self.run_as, str(PG_BIN / name), *args], capture_output=True,
                              text=True, cwd=self.dir, timeout=120)
        if proc.returncode != 0:
            raise RuntimeError(f"{name} failed ({proc.returncode}): {proc.stderr}")

    def url(self, db: str = "bench") -> str:
        return f"postgresql://postgres@127.0.0.1:{self.port}/{db}"

    def sql(self, db: str, statement: str) -> None:
        import psycopg

        with psycopg.connect(self.url(db), autocommit=True) as con:
            con.execute(statement)  # type: ignore[arg-type]

    def postmaster_pid(self) -> int:
        return int((self.data / "postmaster.pid").read_text().split()[0])

    def stop(self) -> None:
        if self.running:
            self.running = False
            try:
                self.tool("pg_ctl", "-D", str(self.data), "-m", "fast", "-w", "stop")
            except (RuntimeError, subprocess.TimeoutExpired):
                pass
        shutil.rmtree(self.dir, ignore_errors=True)


class ThreadWatch:
    """Counts the threads a process starts while watched (its /proc task ids, sampled every
    10 ms): a request on a fresh thread rebuilds that thread's PROJ objects."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.before = self.tids()
        self.first_seen: dict[str, float] = {}  # task id -> time.perf_counter()
        self.done = threading.Event()
        self.thread = threading.Thread(target=self.watch, daemon=True)
        self.thread.start()

    def tids(self) -> set[str]:
        try:
            return set(os.listdir(f"/proc/{self.pid}/task"))
        except OSError:
            return set()

    def watch(self) -> None:
        while not self.done.wait(0.01):
            now = time.perf_counter()
            for tid in self.tids() - self.before:
                self.first_seen.setdefault(tid, now)

    def stop(self, after: float) -> tuple[int, int]:
        """(threads started in all, of which after ``after``: during the timed requests)."""
        self.done.set()
        self.thread.join()
        return len(self.first_seen), sum(t >= after for t in self.first_seen.values())


def http_request(port: int, path: str, doc: dict) -> bytes:
    body = json.dumps(doc).encode()
    return (b"POST %s HTTP/1.1\r\nHost: 127.0.0.1:%d\r\nContent-Type: application/json\r\n"
            b"Content-Length: %d\r\n\r\n" % (path.encode(), port, len(body)) + body)


async def read_response(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    """One HTTP/1.1 response (status line, headers, Content-Length body) from a keep-alive stream."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.split(b"\r\n")
    status = int(lines[0].split(b" ", 2)[1])
    length = 0
    for line in lines[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    return status, await reader.readexactly(length)


async def run_clients(port: int, requests: dict[int, list[bytes]], ok: int, think: float,
                      seed: int, start_at: float) -> tuple[list[float], int, float, float]:
    """Each client ``c`` sends ``requests[c]`` on one keep-alive connection (the first one a
    warm-up, not timed). Returns (latencies s, errors, first send, last answer)."""
    lat: list[float] = []
    errors = 0
    first, last = math.inf, 0.0

    async def client(c: int, reqs: list[bytes]) -> None:
        nonlocal errors, first, last
        r = random.Random(seed * 1000 + c)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(reqs[0])
        status, body = await read_response(reader)
        if status != ok:
            raise RuntimeError(f"bad warm-up answer {status}: {body[:300]!r}")
        await asyncio.sleep(max(0.0, start_at - time.perf_counter()))
        for req in reqs[1:]:
            if think > 0:
                await asyncio.sleep(r.expovariate(1.0 / think))
            t0 = time.perf_counter()
            writer.write(req)
            status, _ = await read_response(reader)
            t1 = time.perf_counter()
            lat.append(t1 - t0)
            errors += status != ok
            first, last = min(first, t0), max(last, t1)
        writer.close()

    await asyncio.gather(*(client(c, reqs) for c, reqs in requests.items()))
    return lat, errors, first, last


def client_process(conn, port: int, requests: dict[int, list[bytes]], ok: int, think: float,
                   seed: int, start_at: float) -> None:
    try:
        import uvloop

        uvloop.install()
    except ImportError:
        pass
    cpu0 = time.process_time()
    try:
        out = asyncio.run(run_clients(port, requests, ok, think, seed, start_at))
        conn.send(("ok", *out, time.process_time() - cpu0))
    except Exception as exc:  # noqa: BLE001 - reported by the parent
        conn.send(("error", repr(exc)))
    conn.close()


def load_run(port: int, make: Callable[[int, int], bytes], ok: int, clients: int, n: int,
             think: float, seed: int, procs: int) -> dict:
    """``clients`` keep-alive connections over ``procs`` forked processes, each sending
    ``make(c, 0)`` (warm-up) then ``make(c, 1..n)``."""
    requests = {c: [make(c, i) for i in range(n + 1)] for c in range(clients)}
    procs = max(1, min(procs, clients))
    ctx = mp.get_context("fork")
    start_at = time.perf_counter() + 1.0 + 0.02 * clients  # all connected and warm by then
    pipes, workers = [], []
    for p in range(procs):
        parent, child = ctx.Pipe(duplex=False)
        mine = {c: requests[c] for c in range(p, clients, procs)}
        w = ctx.Process(target=client_process,
                        args=(child, port, mine, ok, think, seed, start_at))
        w.start()
        pipes.append(parent)
        workers.append(w)
    parts = [p.recv() for p in pipes]
    for w in workers:
        w.join()
    bad = [p[1] for p in parts if p[0] != "ok"]
    if bad:
        raise RuntimeError(f"client process failed: {bad[0]}")
    a = np.array([x for p in parts for x in p[1]]) * 1000
    wall = max(p[4] for p in parts) - min(p[3] for p in parts)
    return {"requests": int(a.size), "errors": sum(p[2] for p in parts),
            "p50_ms": float(np.percentile(a, 50)), "p95_ms": float(np.percentile(a, 95)),
            "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max()),
            "req_per_s": a.size / wall, "start_at": start_at,
            "client_cpu_ms_per_request": sum(p[5] for p in parts) * 1000 / a.size}


def request_makers(port: int, seed: int) -> dict[str, tuple[Callable[[str], Callable], int]]:
    """Per kind: (load name -> make(client, i) -> request bytes, the expected status)."""
    rng = np.random.default_rng(seed)
    inter = [http_request(port, "/api/intersect",
                          {"rays": point_rays(rng), "crs": "EPSG:27700", "sigma_px": 1.0})
             for _ in range(64)]
    rays4 = [point_rays(rng, 4) for _ in range(64)]

    def intersect(load: str) -> Callable[[int, int], bytes]:
        return lambda c, i: inter[(c + i) % len(inter)]

    def points(load: str) -> Callable[[int, int], bytes]:
        tag = load.split()[0]
        return lambda c, i: http_request(
            port, f"/api/projects/{PROJECT}/points",
            {"id": f"{tag}-{c}-{i}", "code": "BENCH", "rays": rays4[(c + i) % len(rays4)]})

    return {"intersect": (intersect, 200), "points": (points, 201)}


def bench_backend(backend: str, args: argparse.Namespace) -> dict:
    tmp = Path(tempfile.mkdtemp(prefix="gsgeo-bench-"))
    cluster: PgCluster | None = None
    gs: subprocess.Popen | None = None
    out: dict = {"backend": backend, "runs": {}}
    try:
        (tmp / "data" / "scenes").mkdir(parents=True)
        env = {k: v for k, v in os.environ.items() if k != "GSGEO_STORE"}
        port = free_port()
        cmd = [sys.executable, "-m", "gsgeo", "serve", "--data", str(tmp / "data"),
               "--port", str(port), "--workers", str(args.workers)]
        if args.store_threads is not None:
            cmd += ["--store-threads", str(args.store_threads)]
        db_pid = None
        if backend == "postgresql":
            url = args.store
            if url is None:
                cluster = PgCluster(fsync=args.pg_fsync == "on")
                url, db_pid = cluster.url(), cluster.postmaster_pid()
            cmd += ["--store", url]
            out["store"] = "throw-away cluster" if cluster else "given URL"
            out["pg_fsync"] = args.pg_fsync if cluster else None
        gs = subprocess.Popen(cmd, cwd=REPO, env=env, stdout=subprocess.DEVNULL,
                              stderr=subprocess.PIPE, text=True)
        base = f"http://127.0.0.1:{port}"
        wait_up(base + "/api/info", gs)
        r = httpx.post(base + "/api/projects", json={"name": "bench", "id": PROJECT,
                                                     "crs": "EPSG:27700"}, timeout=30)
        if r.status_code != 201:
            gs.terminate()
            raise RuntimeError(f"project not created: {r.status_code} {r.text}\n"
                               f"{gs.communicate(timeout=10)[1][-3000:]}")
        makers = request_makers(port, seed=1)
        loads = (("one client", 1, 200, 0.0),
                 ("operators", args.clients, args.requests, args.think),
                 ("saturation", args.clients, args.requests, 0.0))
        for kind in args.kinds:
            make_for, ok = makers[kind]
            for name, clients, n, think in loads:
                if name.split()[0] not in args.loads:
                    continue
                la0 = os.getloadavg()[0]
                print(f"[{backend}] {kind}, {name}: {clients} x {n}  (load average {la0:.1f})",
                      file=sys.stderr)
                cpu0 = cpu_seconds(gs.pid)
                db0 = cpu_seconds(db_pid) if db_pid else 0.0
                seen = ThreadWatch(gs.pid)
                try:
                    res = load_run(port, make_for(name), ok, clients, n, think, seed=1,
                                   procs=args.client_procs)
                except BaseException:
                    seen.stop(after=0.0)
                    raise
                started, timed = seen.stop(after=res["start_at"])
                res["server_threads_started"] = started
                res["server_threads_started_timed"] = timed
                res_threads = f"{started} ({timed} during the timed requests)"
                total = res["requests"] + clients  # warm-ups cost server CPU too
                res["server_cpu_ms_per_request"] = (cpu_seconds(gs.pid) - cpu0) * 1000 / total
                if db_pid:
                    res["db_cpu_ms_per_request"] = (cpu_seconds(db_pid) - db0) * 1000 / total
                res["loadavg_start"], res["loadavg_end"] = la0, os.getloadavg()[0]
                out["runs"][f"{kind}, {name}"] = res
                db = (f"  PostgreSQL CPU {res['db_cpu_ms_per_request']:.1f} ms/req"
                      if db_pid else "")
                print(f"  p50 {res['p50_ms']:.1f}  p95 {res['p95_ms']:.1f}  p99 "
                      f"{res['p99_ms']:.1f}  max {res['max_ms']:.1f} ms  "
                      f"{res['req_per_s']:.0f} req/s  errors {res['errors']}  server CPU "
                      f"{res['server_cpu_ms_per_request']:.1f} ms/req{db}  server threads "
                      f"started {res_threads}", file=sys.stderr)
        r = httpx.get(f"{base}/api/projects/{PROJECT}", timeout=30)
        out["points_stored"] = r.json().get("counts", {}).get("points")
    finally:
        if gs is not None:
            gs.terminate()
            try:
                gs.wait(10)
            except subprocess.TimeoutExpired:
                gs.kill()
        if cluster is not None:
            cluster.stop()
        shutil.rmtree(tmp, ignore_errors=True)
    return out


def inprocess_profile(backend: str, url: str | None, n: int) -> dict:
    """``n`` stored points through the service in this process (no HTTP, one thread): wall
    ms per point unprofiled, then under cProfile the share of the time spent waiting in the
    database driver's execute/commit calls (round trips, locks, WAL flush); last, 20 points
    each stored on a new thread."""
    import cProfile
    import pstats

    from gsgeo.service import open_projects

    tmp = Path(tempfile.mkdtemp(prefix="gsgeo-bench-inproc-"))
    try:
        (tmp / "scenes").mkdir()
        svc = open_projects(tmp, url=url)
        svc.create_project(name="inproc", id="inproc", crs="EPSG:27700")
        rng = np.random.default_rng(2)
        rays = [point_rays(rng, 4) for _ in range(64)]
        for i in range(20):  # warm up (PROJ objects, pool connections)
            svc.add_point("inproc", {"id": f"w{i}", "rays": rays[i % 64]})
        t0 = time.perf_counter()
        for i in range(n):
            svc.add_point("inproc", {"id": f"a{i}", "rays": rays[i % 64]})
        wall = (time.perf_counter() - t0) * 1000 / n
        prof = cProfile.Profile()
        t0 = time.perf_counter()
        prof.enable()
        for i in range(n):
            svc.add_point("inproc", {"id": f"b{i}", "rays": rays[i % 64]})
        prof.disable()
        profiled = (time.perf_counter() - t0) * 1000 / n
        db = 0.0
        calls = 0
        for (file, _line, func), (_cc, nc, _tt, ct, _callers) in \
                pstats.Stats(prof).stats.items():  # type: ignore[attr-defined]
            if (("psycopg" in file and file.endswith("cursor.py") and func == "execute")
                    or func in ("<method 'execute' of 'sqlite3.Connection' objects>",
                                "<method 'executemany' of 'sqlite3.Connection' objects>",
                                "<method 'commit' of 'sqlite3.Connection' objects>")):
                db += ct
                calls += nc
        fresh: list[float] = []
        for i in range(20):  # one stored point on a new thread (its PROJ objects cold)
            def one(k: int = i) -> None:
                t = time.perf_counter()
                svc.add_point("inproc", {"id": f"f{k}", "rays": rays[k % 64]})
                fresh.append((time.perf_counter() - t) * 1000)
            th = threading.Thread(target=one)
            th.start()
            th.join()
        svc.store.close()
        return {"backend": backend, "points": n, "wall_ms_per_point": wall,
                "profiled_ms_per_point": profiled, "db_wait_ms_per_point": db * 1000 / n,
                "db_calls_per_point": calls / n,
                "fresh_thread_ms_median": float(np.median(fresh)),
                "fresh_thread_ms_max": max(fresh)}
    finally:
        shutil.rmtree(tmp, ignore_errors=True)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--backends", nargs="+", default=["sqlite", "postgresql"],
                    choices=["sqlite", "postgresql"])
    ap.add_argument("--store", default=None, metavar="URL",
                    help="postgresql://... of an existing database for the postgresql backend "
                         "(default: a throw-away cluster started here)")
    ap.add_argument("--pg-fsync", default="on", choices=["on", "off"],
                    help="fsync of the throw-away cluster (default on: durable commits)")
    ap.add_argument("--kinds", nargs="+", default=["intersect", "points"],
                    choices=["intersect", "points"])
    ap.add_argument("--loads", nargs="+", default=["one", "operators", "saturation"],
                    choices=["one", "operators", "saturation"])
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--requests", type=int, default=40, help="requests per client")
    ap.add_argument("--think", type=float, default=2.0,
                    help="mean think time between an operator's requests, s")
    ap.add_argument("--workers", type=int, default=1, help="gsgeo serve --workers")
    ap.add_argument("--store-threads", type=int, default=None,
                    help="gsgeo serve --store-threads (default: the server's)")
    ap.add_argument("--client-procs", type=int, default=2)
    ap.add_argument("--json", default=None, help="write the figures here")
    ap.add_argument("--inprocess", type=int, default=0, metavar="N",
                    help="instead of the HTTP loads: N stored points per backend through the "
                         "service in this process, with the time spent in the database driver")
    args = ap.parse_args()

    if args.inprocess:
        cluster = None
        try:
            for backend in args.backends:
                url = None
                if backend == "postgresql":
                    url = args.store
                    if url is None:
                        cluster = PgCluster(fsync=args.pg_fsync == "on")
                        url = cluster.url()
                r = inprocess_profile(backend, url, args.inprocess)
                print(f"{backend}: {r['wall_ms_per_point']:.2f} ms/point; profiled "
                      f"{r['profiled_ms_per_point']:.2f} ms/point of which in the driver's "
                      f"execute/commit {r['db_wait_ms_per_point']:.2f} ms "
                      f"({r['db_calls_per_point']:.1f} calls/point); on a fresh thread "
                      f"{r['fresh_thread_ms_median']:.1f} ms (median of 20, max "
                      f"{r['fresh_thread_ms_max']:.1f})")
        finally:
            if cluster is not None:
                cluster.stop()
        return 0

    print(f"{os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.1f} at the start",
          file=sys.stderr)
    results = {"cpus": os.cpu_count(), "started": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                time.gmtime()),
               "backends": [bench_backend(b, args) for b in args.backends]}
    if args.json:
        Path(args.json).write_text(json.dumps(results, indent=2))
    print("\n| backend | request | load | requests | p50 ms | p95 ms | p99 ms | max ms | req/s "
          "| server CPU ms/req | PostgreSQL CPU ms/req | load avg |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for b in results["backends"]:
        for name, r in b["runs"].items():
            kind, load = name.split(", ")
            db = f"{r['db_cpu_ms_per_request']:.1f}" if "db_cpu_ms_per_request" in r else "-"
            print(f"| {b['backend']} | {kind} | {load} | {r['requests']} | {r['p50_ms']:.1f} | "
                  f"{r['p95_ms']:.1f} | {r['p99_ms']:.1f} | {r['max_ms']:.1f} | "
                  f"{r['req_per_s']:.0f} | {r['server_cpu_ms_per_request']:.1f} | {db} | "
                  f"{r['loadavg_start']:.1f}-{r['loadavg_end']:.1f} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
