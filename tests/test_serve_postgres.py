"""Two `gsgeo serve --store postgresql://...` processes (each with its own data directory) on
one database: eight clients write points through both, one server is SIGKILLed mid-load, no
acknowledged point is lost; a stale If-Match gets 412 from either server; the project's
points are a PostGIS layer with SRID 27700."""

from __future__ import annotations

import signal
import threading

import httpx
import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import LONDON, ecef_of, rays_at, start_server

pytestmark = pytest.mark.slow


def test_two_servers_share_one_database_and_a_killed_one_loses_nothing(request, tmp_path):
    cluster = request.getfixturevalue("pg_cluster")
    db = cluster.new_database()
    url = cluster.url(db)
    servers = []
    try:
        for name in ("a", "b"):
            servers.append(start_server(tmp_path / name, "--store", url))
        (proc_a, base_a), (proc_b, base_b) = servers
        r = httpx.post(base_a + "/api/projects", json={"name": "site", "id": "site",
                                                       "crs": "EPSG:27700"})
        assert r.status_code == 201, r.text
        acknowledged: list[str] = []
        lock = threading.Lock()
        killed = threading.Event()
        failures: list[str] = []

        def client(c: int) -> None:
            with httpx.Client(timeout=30) as http:
                for i in range(16):
                    base = (base_a, base_b)[(c + i) % 2]
                    pid = f"C{c}-{i}"
                    rays = rays_at(ecef_of(LONDON[0] + 1e-5 * (16 * c + i), LONDON[1], 40), 3)
                    try:
                        r = http.post(f"{base}/api/projects/site/points",
                                      json={"id": pid, "rays": rays})
                    except httpx.HTTPError:
                        if base != base_b or not killed.is_set():
                            failures.append(f"{pid}: no answer from {base}")
                        continue
                    if r.status_code == 201:
                        with lock:
                            acknowledged.append(pid)
                            if len(acknowledged) == 40:  # mid-load: B dies without warning
                                proc_b.send_signal(signal.SIGKILL)
                                killed.set()
                    elif base != base_b or not killed.is_set():
                        failures.append(f"{pid}: {r.status_code} {r.text}")

        threads = [threading.Thread(target=client, args=(c,)) for c in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        assert failures == []
        assert killed.is_set() and proc_b.wait(10) == -signal.SIGKILL
        got = httpx.get(base_a + "/api/projects/site/points?summary=true").json()
        ids = {p["id"] for p in (got["points"] if isinstance(got, dict) else got)}
        assert set(acknowledged) <= ids and len(acknowledged) >= 64

        # optimistic concurrency across the database: a stale If-Match is refused
        one = acknowledged[0]
        r = httpx.get(f"{base_a}/api/projects/site/points/{one}")
        etag = r.headers["ETag"]
        r = httpx.patch(f"{base_a}/api/projects/site/points/{one}", json={"code": "kerb"},
                        headers={"If-Match": etag})
        assert r.status_code == 200 and r.headers["ETag"] != etag, r.text
        r = httpx.patch(f"{base_a}/api/projects/site/points/{one}", json={"code": "wall"},
                        headers={"If-Match": etag})
        assert r.status_code == 412, r.text

        # GIS clients see the points as a typed layer in the project's grid
        assert cluster.sql(db, "SELECT type, srid, coord_dimension FROM geometry_columns"
                               " WHERE f_table_name = 'gsgeo_site_points'") == [("POINT", 27700, 3)]
        n = cluster.sql(db, "SELECT count(*) FROM gsgeo_site_points WHERE geom IS NOT NULL")
        assert n[0][0] == len(ids)
    finally:
        for proc, _ in servers:
            if proc.poll() is None:
                proc.kill()
            proc.wait(10)
            for stream in (proc.stdout, proc.stderr):
                if stream is not None:
                    stream.close()
