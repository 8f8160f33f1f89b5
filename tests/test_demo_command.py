"""`gsgeo demo`: builds the scene, creates the demo project with the truth as check points.

Runs the real command line in a subprocess against a real SQLite store in a temporary data
directory; a point measured exactly on a marker must show no difference to the truth.
"""

from __future__ import annotations

import re
import sqlite3
import subprocess
import sys

import numpy as np
import pytest
from servertools import rays_at

from gsgeo.demo import place, scene
from gsgeo.service import Projects, open_store
from tests.conftest import REPO


def _gsgeo(*args, cwd=None):
    return subprocess.run([sys.executable, "-m", "gsgeo", *args], capture_output=True,
                          text=True, timeout=600, cwd=cwd)


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory):
    """The first `gsgeo demo --no-serve` in a fresh data directory: (DATA, its process)."""
    d = tmp_path_factory.mktemp("demo") / "gsgeo-data"
    r = _gsgeo("demo", "--data", str(d), "--no-serve")
    assert r.returncode == 0, r.stderr
    assert "20 check points" in r.stdout and "?scene=demo&project=demo" in r.stdout
    return d, r


@pytest.fixture(scope="module")
def data(demo_run):
    return demo_run[0]


def test_demo_words_match_the_readme(demo_run):
    """The demo tells how to measure in the README's words (3-5 views from different
    directions) and counts in the right number ('1 tile', never '1 tiles')."""
    from gsgeo.demo.build import counted

    readme = " ".join((REPO / "README.md").read_text(encoding="utf-8").split())
    views = re.search(r"click a marker in (\d)–(\d) views from different directions", readme)
    assert views, "the README no longer says how many views"
    out = demo_run[1].stdout
    assert f"click a marker in {views[1]}-{views[2]} views from different directions" in out, out
    tiles = re.search(r"\((\d+) (tiles?)\)", demo_run[1].stderr)
    assert tiles and (tiles[2] == "tile") == (tiles[1] == "1"), demo_run[1].stderr
    assert [counted(1, "tile"), counted(2, "tile"), counted(12_000, "splat")] == \
        ["1 tile", "2 tiles", "12,000 splats"]


def test_demo_builds_scene_and_project(data):
    assert (data / "scenes" / "demo" / "tileset.json").is_file()
    assert (data / "demo" / "scene.ply").is_file()
    con = sqlite3.connect(data / "gsgeo.sqlite")
    try:
        tables = {r[0] for r in con.execute("select name from sqlite_master where type='table'")}
        cp_table = next(t for t in tables if "check" in t)
        ids = sorted(r[0] for r in con.execute(f"select id from {cp_table}"))
    finally:
        con.close()
    assert ids == sorted(v.id for v in scene.VALIDATION_POINTS)
    store = open_store(data)
    try:
        p = Projects(store, data).get_project("demo")
        assert p.crs == place.CRS and p.scene == "demo"
    finally:
        store.close()


def test_a_point_measured_on_a_marker_matches_its_truth(data):
    truth = {t.id: np.array(t.ecef) for t in place.truth_points()}
    store = open_store(data)
    try:
        projects = Projects(store, data)
        projects.add_point("demo", {"id": "T2", "rays": rays_at(truth["T2"])})
        # a point off the truth by 5 cm east-ish: the report must show it
        off = truth["S1"] + 0.05 * np.cross([0.0, 0.0, 1.0], truth["S1"]) / np.linalg.norm(
            np.cross([0.0, 0.0, 1.0], truth["S1"]))
        projects.add_point("demo", {"id": "S1", "rays": rays_at(off)})
        rep = projects.accuracy("demo")
    finally:
        store.close()
    by_id = {r["id"]: r for r in rep["points"]}
    assert rep["counts"]["matched"] == 2
    assert abs(by_id["T2"]["d3D"]) < 1e-3
    assert by_id["S1"]["d3D"] == pytest.approx(0.05, abs=1e-3)
    assert by_id["S1"]["dE"] == pytest.approx(0.05, abs=2e-3)


def test_rerun_reuses_the_scene_and_keeps_measurements(data):
    store = open_store(data)
    try:
        g1 = next(np.array(t.ecef) for t in place.truth_points() if t.id == "G1")
        Projects(store, data).add_point("demo", {"id": "G1", "rays": rays_at(g1)})
    finally:
        store.close()
    r = _gsgeo("demo", "--data", str(data), "--no-serve")
    assert r.returncode == 0, r.stderr
    assert "using the scene built" in r.stderr
    store = open_store(data)
    try:
        projects = Projects(store, data)
        ids = {p.id for p in projects.list_points("demo")}
        n_cp = len(projects.list_check_points("demo"))
    finally:
        store.close()
    assert "G1" in ids   # points measured before the rerun survive
    assert n_cp == 20


def test_bad_arguments_get_a_message(tmp_path):
    f = tmp_path / "a-file"
    f.write_text("x")
    r = _gsgeo("demo", "--data", str(f), "--no-serve")
    assert r.returncode == 2 and "is not a directory" in r.stderr and "Traceback" not in r.stderr
    r = _gsgeo("demo", "--data", str(tmp_path / "d"), "--port", "70000")
    assert r.returncode == 2 and "--port" in r.stderr and "Traceback" not in r.stderr


def test_busy_port_is_reported_before_building(tmp_path):
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        port = s.getsockname()[1]
        r = _gsgeo("demo", "--data", str(tmp_path / "d"), "--port", str(port))
    assert r.returncode == 2 and "in use" in r.stderr and "--port" in r.stderr
    assert not (tmp_path / "d").exists()   # nothing built


def test_the_port_of_a_server_stopped_a_moment_ago_is_free_at_once():
    """After Ctrl-C the server's closed connections sit in TIME_WAIT on its port for a minute;
    `gsgeo demo` on that port again must start (uvicorn binds it with SO_REUSEADDR), while a
    server still listening there is refused."""
    import socket

    from gsgeo.commands.demo import check_port_free
    from gsgeo.errors import InputError

    server = socket.socket()
    server.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    server.bind(("127.0.0.1", 0))
    server.listen()
    port = server.getsockname()[1]
    client = socket.create_connection(("127.0.0.1", port))
    conn, _ = server.accept()
    conn.close()  # the server closes first: its side of the connection goes to TIME_WAIT
    client.recv(1)
    client.close()
    with pytest.raises(InputError, match=f"127.0.0.1:{port}"):
        check_port_free("127.0.0.1", port)  # still listening
    server.close()
    with socket.socket() as plain, pytest.raises(OSError):
        plain.bind(("127.0.0.1", port))  # the TIME_WAIT that made the old check refuse
    check_port_free("127.0.0.1", port)


def test_demo_off_loopback_prints_the_address_with_its_token(data):
    """Bound off loopback the API needs a token: the address the demo prints carries the very
    token the server uses, so opening it works (a bare address would get 401 everywhere)."""
    import os
    import time

    import httpx
    from servertools import free_port

    port = free_port()
    env = {k: v for k, v in os.environ.items() if k != "GSGEO_TOKEN"}
    proc = subprocess.Popen([sys.executable, "-m", "gsgeo", "demo", "--data", str(data),
                             "--host", "0.0.0.0", "--port", str(port)], env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        line = next((ln for ln in proc.stdout if ln.startswith("open")), "")
        token = re.search(r"#token=([\w-]+)$", line.strip())
        assert token, line
        base = f"http://127.0.0.1:{port}"
        deadline = time.monotonic() + 30
        while True:
            assert proc.poll() is None, proc.stderr.read()
            try:
                httpx.get(base + "/api/info", timeout=1.0)
                break
            except httpx.HTTPError:
                assert time.monotonic() < deadline, "the demo's server did not start"
                time.sleep(0.1)
        assert httpx.get(base + "/api/projects").status_code == 401
        r = httpx.get(base + "/api/projects", headers={"Authorization": f"Bearer {token[1]}"})
        assert r.status_code == 200 and "demo" in r.text
    finally:
        proc.terminate()
        proc.communicate(timeout=10)
