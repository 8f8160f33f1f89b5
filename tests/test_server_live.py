"""`gsgeo serve` as a real process on loopback: concurrency, kill -9, restart, token."""

from __future__ import annotations

import signal
import threading
import time
from concurrent.futures import ThreadPoolExecutor

import httpx
import numpy as np
import pyproj
import pytest
from servertools import LONDON, ecef_of, rays_at, start_server

from gsgeo.commands.serve import resolve_token
from gsgeo.store import open_store

UTM30 = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:32630", always_xy=True)
N_CLIENTS = 20
POINTS_PER_CLIENT = 10  # 200 points in all


def target(client: int, k: int) -> tuple[float, float, float]:
    return (LONDON[0] + 2e-4 * client, LONDON[1] + 1e-4 * k, 30.0 + k)


@pytest.fixture
def server(tmp_path):
    proc, base = start_server(tmp_path / "data")
    yield base, tmp_path / "data"
    proc.terminate()
    proc.wait(10)


def test_twenty_concurrent_clients_lose_no_point(server):
    base, data = server
    pid = httpx.post(f"{base}/api/projects", json={"name": "busy", "crs": "EPSG:32630"}).json()["id"]
    barrier = threading.Barrier(N_CLIENTS)

    def client(c: int) -> list[tuple[int, str]]:
        out = []
        with httpx.Client(base_url=base, timeout=60) as h:
            barrier.wait()
            for k in range(POINTS_PER_CLIENT):
                body = {"rays": rays_at(ecef_of(*target(c, k)), 3), "code": f"c{c}k{k}"}
                if c % 2:  # half the clients name their points, half let the server number them
                    body["id"] = f"C{c}-{k}"
                r = h.post(f"/api/projects/{pid}/points", json=body)
                out.append((r.status_code, r.json().get("id")))
        return out

    with ThreadPoolExecutor(N_CLIENTS) as ex:
        results = [x for chunk in ex.map(client, range(N_CLIENTS)) for x in chunk]
    assert [s for s, _ in results] == [201] * (N_CLIENTS * POINTS_PER_CLIENT)
    ids = [i for _, i in results]
    assert len(set(ids)) == len(ids) == N_CLIENTS * POINTS_PER_CLIENT
    pts = httpx.get(f"{base}/api/projects/{pid}/points", timeout=60).json()["points"]
    assert sorted(p["id"] for p in pts) == sorted(ids)
    for p in pts:  # every stored result belongs to its own rays
        c, k = (int(v) for v in p["code"][1:].split("k"))
        e, n = UTM30.transform(*target(c, k)[:2])
        assert p["record"]["easting"] == pytest.approx(e, abs=1e-4)
        assert p["record"]["northing"] == pytest.approx(n, abs=1e-4)


def test_kill_9_during_writes_then_restart_keeps_every_acknowledged_point(tmp_path):
    data = tmp_path / "data"
    proc, base = start_server(data)
    pid = httpx.post(f"{base}/api/projects", json={"name": "crash", "crs": "EPSG:32630"}).json()["id"]
    acknowledged: list[str] = []
    stop = threading.Event()

    def writer(c: int) -> None:
        with httpx.Client(base_url=base, timeout=10) as h:
            k = 0
            while not stop.is_set():
                try:
                    r = h.post(f"/api/projects/{pid}/points",
                               json={"id": f"W{c}-{k}", "rays": rays_at(ecef_of(*target(c, k)), 4)})
                except httpx.HTTPError:
                    return  # the server is gone
                if r.status_code == 201:
                    acknowledged.append(r.json()["id"])
                k += 1

    threads = [threading.Thread(target=writer, args=(c,)) for c in range(6)]
    for t in threads:
        t.start()
    deadline = time.monotonic() + 60
    while len(acknowledged) < 60 and time.monotonic() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    stop.set()
    for t in threads:
        t.join()
    assert len(acknowledged) >= 60

    store = open_store(data)
    try:
        assert store.check_integrity() == []
        with store.transaction(write=False) as tx:
            pts = tx.list_points(pid)
    finally:
        store.close()
    stored = {p.id: p for p in pts}
    assert set(acknowledged) <= set(stored)
    for p in pts:  # complete points only: rays, result and record agree
        assert len(p.rays) == 4 and p.record["n_rays"] == 4 and p.result["point_id"] == p.id

    proc, base = start_server(data)
    try:
        got = httpx.get(f"{base}/api/projects/{pid}/points", timeout=30).json()["points"]
        assert {p["id"] for p in got} == set(stored)
        r = httpx.post(f"{base}/api/projects/{pid}/points",
                       json={"rays": rays_at(ecef_of(*LONDON), 3)})
        assert r.status_code == 201
    finally:
        proc.terminate()
        proc.wait(10)


def test_token_from_environment(tmp_path):
    proc, base = start_server(tmp_path / "data", env={"GSGEO_TOKEN": "tok-123"})
    try:
        assert httpx.get(f"{base}/api/projects").status_code == 401
        r = httpx.get(f"{base}/api/projects", headers={"Authorization": "Bearer tok-123"})
        assert r.status_code == 200
        assert httpx.get(f"{base}/").status_code == 200
    finally:
        proc.terminate()
        proc.wait(10)


def test_token_is_generated_off_loopback_only():
    tok, generated = resolve_token("0.0.0.0", {})
    assert generated and len(tok) >= 24
    assert resolve_token("0.0.0.0", {})[0] != tok
    assert resolve_token("127.0.0.1", {}) == (None, False)
    assert resolve_token("192.168.1.5", {"GSGEO_TOKEN": "abc"}) == ("abc", False)


def test_serve_refuses_a_file_as_data_dir(tmp_path):
    import subprocess
    import sys

    f = tmp_path / "file"
    f.write_text("x")
    r = subprocess.run([sys.executable, "-m", "gsgeo", "serve", "--data", str(f)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "not a directory" in r.stderr


def test_points_are_spread_over_distinct_positions():
    """Guard for the concurrency test above: its targets differ, so mixed-up results show."""
    xy = np.array([UTM30.transform(*target(c, k)[:2]) for c in range(N_CLIENTS)
                   for k in range(POINTS_PER_CLIENT)])
    d = np.linalg.norm(xy[:, None] - xy[None], axis=-1) + np.eye(len(xy)) * 1e9
    assert d.min() > 5.0


def test_two_workers_with_two_solver_threads_share_the_store(tmp_path):
    """`--workers 2 --solver-threads 2`: every answer right, every point in the one store."""
    proc, base = start_server(tmp_path / "data", "--workers", "2", "--solver-threads", "2",
                              timeout=60)
    try:
        pid = httpx.post(f"{base}/api/projects",
                         json={"name": "two", "crs": "EPSG:32630"}).json()["id"]

        def client(c: int) -> list[str]:
            ids = []
            with httpx.Client(base_url=base, timeout=60) as h:
                for k in range(5):
                    t = target(c, k)
                    r = h.post("/api/intersect", json={"rays": rays_at(ecef_of(*t), 3),
                                                       "crs": "EPSG:32630"})
                    assert r.status_code == 200, r.text
                    e, n = UTM30.transform(*t[:2])
                    assert r.json()["easting"] == pytest.approx(e, abs=1e-4)
                    assert r.json()["northing"] == pytest.approx(n, abs=1e-4)
                    r = h.post(f"/api/projects/{pid}/points",
                               json={"rays": rays_at(ecef_of(*t), 3), "id": f"C{c}-{k}"})
                    assert r.status_code == 201, r.text
                    ids.append(r.json()["id"])
            return ids

        with ThreadPoolExecutor(8) as ex:
            ids = [i for chunk in ex.map(client, range(8)) for i in chunk]
        pts = httpx.get(f"{base}/api/projects/{pid}/points", timeout=60).json()["points"]
        assert sorted(p["id"] for p in pts) == sorted(ids) and len(ids) == 40
    finally:
        proc.terminate()
        proc.wait(20)


def test_serve_refuses_a_bad_solver_thread_count(tmp_path):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "gsgeo", "serve", "--data", str(tmp_path),
                        "--solver-threads", "0"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 2 and "--solver-threads" in r.stderr
