"""Benchmark stored-point POSTs (`POST /api/projects/{pid}/points`: solve + store) of
`gsgeo serve` with the SQLite store and with the PostgreSQL store, side by side.

    python benchmarks/store_post.py [--clients 50] [--requests 20] [--think 2]
        [--store postgresql://...] [--workers 1]

Each of `--clients` operators (a thread with its own keep-alive connection) posts
`--requests` points of 3 rays, waiting an exponential think time (mean `--think` s) between
them, like people measuring; `--think 0` is a closed loop (the server's capacity). Reported:
p50, p90, p99 and max latency (ms) and POSTs/s, per backend. Without `--store` a throw-away
PostgreSQL 15 + PostGIS cluster is started in a temporary directory (tests/pgcluster.py:
Debian's postgresql-15 and postgresql-15-postgis-3, fsync off) and stopped at the end.
Everything runs on 127.0.0.1; clients, servers and database share the machine.
"""

from __future__ import annotations

import argparse
import json
import random
import signal
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO / "tests"))
from pgcluster import Cluster  # noqa: E402  (the tests' throw-away cluster)
from servertools import LONDON, ecef_of, rays_at, start_server  # noqa: E402


def run(label: str, extra: list[str], data: Path, clients: int, requests: int,
        think: float) -> dict:
    proc, base = start_server(data, *extra, timeout=60)
    try:
        pid = label.replace("-", "")
        httpx.post(base + "/api/projects", json={"name": pid, "id": pid, "crs": "EPSG:27700"},
                   timeout=30).raise_for_status()
        lat: list[float] = []
        lock = threading.Lock()
        failed: list[str] = []

        def operator(c: int) -> None:
            rng = random.Random(c)
            with httpx.Client(timeout=60) as http:
                for i in range(requests):
                    if think > 0:
                        time.sleep(rng.expovariate(1.0 / think))
                    rays = rays_at(ecef_of(LONDON[0] + 1e-6 * (requests * c + i), LONDON[1],
                                           40.0), 3)
                    t0 = time.perf_counter()
                    r = http.post(f"{base}/api/projects/{pid}/points", json={"rays": rays})
                    dt = (time.perf_counter() - t0) * 1000
                    if r.status_code != 201:
                        failed.append(f"{r.status_code} {r.text[:200]}")
                    with lock:
                        lat.append(dt)

        threads = [threading.Thread(target=operator, args=(c,)) for c in range(clients)]
        t0 = time.perf_counter()
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        wall = time.perf_counter() - t0
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(30)
        except Exception:  # noqa: BLE001 - a server that does not stop is killed
            proc.kill()
    if failed:
        raise RuntimeError(f"{label}: {len(failed)} POSTs failed, e.g. {failed[0]}")
    lat.sort()

    def q(p: float) -> float:
        return round(lat[min(len(lat) - 1, int(p * len(lat)))], 1)

    return {"backend": label, "posts": len(lat), "p50_ms": q(0.5), "p90_ms": q(0.9),
            "p99_ms": q(0.99), "max_ms": round(lat[-1], 1), "posts_per_s": round(len(lat) / wall, 1)}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--requests", type=int, default=20, help="POSTs per client")
    ap.add_argument("--think", type=float, default=2.0, help="mean think time, s (0: closed loop)")
    ap.add_argument("--store", default=None, help="a PostgreSQL URL (default: a throw-away cluster)")
    ap.add_argument("--workers", type=int, default=1, help="gsgeo serve --workers")
    args = ap.parse_args()
    tmp = Path(tempfile.mkdtemp(prefix="gsgeo-bench-store-"))
    cluster = None if args.store else Cluster()
    try:
        url = args.store or cluster.url(cluster.new_database())  # type: ignore[union-attr]
        workers = ["--workers", str(args.workers)]
        rows = [run("sqlite", workers, tmp / "sqlite", args.clients, args.requests, args.think),
                run("postgresql", ["--store", url, *workers], tmp / "pg", args.clients,
                    args.requests, args.think)]
    finally:
        if cluster is not None:
            cluster.stop()
    for r in rows:
        print(json.dumps(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
