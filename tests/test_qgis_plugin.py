"""The QGIS plugin (qgis/gsgeo): its zip, and the plugin in a headless QGIS against a live
`gsgeo serve` that wants a token.

QGIS runs in Debian's own Python (python3-qgis; the project's .venv cannot import it) as a
subprocess, qgis/harness.py, driven line by line; it skips, saying why, where that Python
has no QGIS.
"""

from __future__ import annotations

import ast
import configparser
import json
import os
import queue
import subprocess
import sys
import threading
import zipfile
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, urlsplit

import httpx
import pytest
from servertools import LONDON, ecef_of, free_port, rays_at, start_server

REPO = Path(__file__).resolve().parents[1]
PLUGIN = REPO / "qgis" / "gsgeo"
QGIS_PYTHON = os.path.abspath(os.environ.get("GSGEO_QGIS_PYTHON", "/usr/bin/python3"))
TOKEN = "qgis-test-token"
GRID = "EPSG:27700"
#: Seconds the harness may take for one command (QGIS's start included).
STEP_TIMEOUT = 60.0


def qgis_missing() -> str | None:
    """Why QGIS cannot run here, or None."""
    if not Path(QGIS_PYTHON).exists():
        return f"{QGIS_PYTHON} does not exist (Debian's python3 with python3-qgis)"
    probe = subprocess.run(
        [QGIS_PYTHON, "-c", "import qgis.core, qgis.gui; from qgis.core import Qgis; "
                            "print(Qgis.QGIS_VERSION)"],
        capture_output=True, text=True, cwd="/", env={**os.environ, "QT_QPA_PLATFORM": "offscreen"})
    if probe.returncode != 0:
        last = (probe.stderr.strip().splitlines() or ["no message"])[-1]
        return (f"{QGIS_PYTHON} cannot import QGIS ({last}); bash scripts/install.sh --test "
                "installs Debian's python3-qgis where apt has it")
    return None


# the zip and the code ----------------------------------------------------------------------
def test_zip_has_the_layout_qgis_installs(tmp_path):
    out = tmp_path / "out" / "gsgeo-qgis.zip"
    r = subprocess.run(["bash", "scripts/build_qgis_plugin.sh", str(out)], cwd=REPO,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    with zipfile.ZipFile(out) as z:
        names = set(z.namelist())
        meta = configparser.ConfigParser()
        meta.read_string(z.read("gsgeo/metadata.txt").decode())
        init = ast.parse(z.read("gsgeo/__init__.py"))
    expected = {f"gsgeo/{p.relative_to(PLUGIN)}" for p in PLUGIN.rglob("*")
                if p.is_file() and "__pycache__" not in p.parts and p.suffix != ".pyc"}
    assert names == expected
    assert all(n.startswith("gsgeo/") for n in names)
    assert meta["general"]["qgisMinimumVersion"] == "3.22"
    for key in ("name", "description", "version", "author", "email"):
        assert meta["general"][key].strip(), key
    assert any(isinstance(n, ast.FunctionDef) and n.name == "classFactory" for n in init.body)


def test_plugin_talks_http_only():
    """No module of the plugin imports the gsgeo package (only its own modules, relatively)."""
    for path in PLUGIN.rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                assert not any(a.name.split(".")[0] == "gsgeo" for a in node.names), path
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                assert (node.module or "").split(".")[0] != "gsgeo", path


def test_ruff_and_mypy_pass_on_the_plugin(tmp_path):
    """ruff (the project's rules) and mypy with every function annotated; QGIS's own modules
    are not importable in .venv, so mypy takes them as untyped."""
    r = subprocess.run([sys.executable, "-m", "ruff", "check", "qgis"], cwd=REPO,
                       capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr
    r = subprocess.run([sys.executable, "-m", "mypy", "qgis/gsgeo", "--ignore-missing-imports",
                        "--disallow-untyped-defs", "--disallow-incomplete-defs",
                        "--cache-dir", str(tmp_path / "mypy")],
                       cwd=REPO, capture_output=True, text=True)
    assert r.returncode == 0, r.stdout + r.stderr


# the plugin in QGIS ------------------------------------------------------------------------
class Harness:
    """qgis/harness.py under Debian's Python: one JSON command in, one ``@@`` line out."""

    def __init__(self, home: Path, plugins_dir: Path | None = None):
        home.mkdir(parents=True, exist_ok=True)
        env = {**os.environ, "QT_QPA_PLATFORM": "offscreen", "HOME": str(home),
               "QGIS_CUSTOM_CONFIG_PATH": str(home / "qgis-profile"),
               "XDG_RUNTIME_DIR": str(home)}
        env.pop("PYTHONPATH", None)
        self.log = (home / "harness.log").open("w")
        args = [str(plugins_dir)] if plugins_dir else []
        self.proc = subprocess.Popen([QGIS_PYTHON, str(REPO / "qgis" / "harness.py"), *args],
                                     cwd=home, env=env, text=True, stdin=subprocess.PIPE,
                                     stdout=subprocess.PIPE, stderr=self.log)
        self.lines: queue.Queue[str] = queue.Queue()
        threading.Thread(target=self.pump, daemon=True).start()
        try:
            self.hello = self.answer()
        except AssertionError:
            self.close()
            raise

    def pump(self) -> None:
        assert self.proc.stdout is not None
        for line in self.proc.stdout:
            if line.startswith("@@ "):
                self.lines.put(line[3:])
        self.lines.put("")

    def answer(self) -> dict[str, Any]:
        try:
            line = self.lines.get(timeout=STEP_TIMEOUT)
        except queue.Empty:
            raise AssertionError(f"the QGIS harness did not answer in {STEP_TIMEOUT} s") from None
        if not line:
            raise AssertionError(f"the QGIS harness ended: {Path(self.log.name).read_text()[-3000:]}")
        return json.loads(line)

    def __call__(self, cmd: str, **kw: Any) -> dict[str, Any]:
        assert self.proc.stdin is not None
        self.proc.stdin.write(json.dumps({"cmd": cmd, **kw}) + "\n")
        self.proc.stdin.flush()
        out = self.answer()
        assert "error" not in out or cmd == "connect", out.get("trace") or out
        return out

    def close(self) -> None:
        if self.proc.poll() is None and self.proc.stdin is not None:
            try:
                self.proc.stdin.write('{"cmd": "quit"}\n')
                self.proc.stdin.flush()
                self.proc.wait(20)
            except (OSError, subprocess.TimeoutExpired):
                self.proc.kill()
                self.proc.wait(10)
        self.log.close()


def test_zip_installs_and_starts_in_qgis(tmp_path):
    """The zip extracted into a plugins folder is found, loaded and started the way QGIS
    starts installed plugins (qgis.utils), from that folder, and unloads cleanly."""
    reason = qgis_missing()
    if reason:
        pytest.skip(reason)
    out = tmp_path / "gsgeo-qgis.zip"
    subprocess.run(["bash", "scripts/build_qgis_plugin.sh", str(out)], cwd=REPO, check=True,
                   capture_output=True, timeout=60)
    plugins = tmp_path / "profile" / "python" / "plugins"
    with zipfile.ZipFile(out) as z:
        z.extractall(plugins)
    qgis = Harness(tmp_path / "home", plugins)
    try:
        assert qgis.hello["module"] == str(plugins / "gsgeo" / "__init__.py")
        assert (qgis.hello["name"], qgis.hello["min_version"]) == ("gsgeo", "3.22")
        assert qgis("unload") == {"actions": 0, "token_hook": False, "live": False}
    finally:
        qgis.close()


def place(k: int) -> tuple[float, float, float]:
    """The k-th test point: lon, lat (degrees), WGS 84 ellipsoidal height (m), near London."""
    return (LONDON[0] + 3e-4 * k, LONDON[1] + 2e-4 * k, 40.0 + k)


@pytest.fixture
def live(tmp_path):
    """A server that wants a token, a project in EPSG:27700 with points P1..P3, the harness."""
    reason = qgis_missing()
    if reason:
        pytest.skip(reason)
    proc, base = start_server(tmp_path / "data", env={"GSGEO_TOKEN": TOKEN})
    http = httpx.Client(base_url=base, headers={"Authorization": f"Bearer {TOKEN}"}, timeout=30)
    harness = None
    try:
        pid = http.post("/api/projects", json={"name": "QGIS test", "crs": GRID}).json()["id"]
        for k in (1, 2, 3):
            r = http.post(f"/api/projects/{pid}/points",
                          json={"id": f"P{k}", "code": "mark", "rays": rays_at(ecef_of(*place(k)))})
            assert r.status_code == 201, r.text
        harness = Harness(tmp_path / "home")
        yield base, http, pid, harness
    finally:
        if harness is not None:
            harness.close()
        http.close()
        proc.terminate()
        proc.wait(10)


def layer(layers: list[dict[str, Any]], collection: str) -> dict[str, Any]:
    found = [lyr for lyr in layers if lyr["collection"] == collection]
    assert found, f"no layer of {collection}: {[lyr['collection'] for lyr in layers]}"
    return found[0]


def test_plugin_adds_live_layers_and_sends_control_points(live):
    base, http, pid, qgis = live
    assert "OAPIF" in qgis.hello["providers"], "QGIS has no OAPIF provider: install qgis-providers"
    bad = qgis("connect", url=base, token="wrong")["error"]  # said, not a crash
    assert "401" in bad and "GsgeoApiError" in bad
    down = qgis("connect", url=f"http://127.0.0.1:{free_port()}", token="")["error"]
    assert "the server does not answer" in down, down
    assert pid in qgis("connect", url=base, token=TOKEN)["projects"]

    added = qgis("add_layers", project=pid, to_crs=GRID)
    layers = added["layers"]
    assert not [m for m in added["messages"] if "could not" in m or "no collections" in m]
    assert all(lyr["valid"] and lyr["provider"] == "OAPIF" for lyr in layers), layers
    assert all(f"url='{base}/ogc'" in lyr["source"] and TOKEN not in lyr["source"] for lyr in layers)
    assert {f"{pid}.points", f"{pid}.lines", f"{pid}.polygons"} <= {lyr["collection"] for lyr in layers}

    api = {q["id"]: q["record"] for q in
           http.get(f"/api/projects/{pid}/points", params={"summary": True}).json()["points"]}
    points = layer(layers, f"{pid}.points")
    assert points["crs"] in ("EPSG:4326", "OGC:CRS84")  # what QGIS 3.22's OAPIF reads
    assert points["count"] == len(api) == 3
    got = {f["point_id"]: f for f in points["features"]}
    assert set(got) == set(api)
    for pt_id, rec in api.items():
        assert got[pt_id]["code"] == rec["code"] == "mark"  # attributes come along
        lon, lat, h = got[pt_id]["xyz"]
        assert abs(lon - rec["lon"]) < 1e-9 and abs(lat - rec["lat"]) < 1e-9
        assert abs(h - rec["h_wgs84"]) < 1e-4
        e, n = got[pt_id]["grid"]  # CRS84 taken into the grid by QGIS itself
        assert abs(e - rec["easting"]) < 1e-3 and abs(n - rec["northing"]) < 1e-3, (pt_id, rec)

    # the empty map took the project's grid and shows its points
    assert added["project_crs"] == added["map_crs"] == GRID
    x0, y0, x1, y1 = added["map_extent"]
    assert all(x0 < r["easting"] < x1 and y0 < r["northing"] < y1 for r in api.values()), added

    # live: a point stored now is in the layer after a refresh
    r = http.post(f"/api/projects/{pid}/points", json={"id": "P4", "rays": rays_at(ecef_of(*place(4)))})
    assert r.status_code == 201
    again = layer(qgis("refresh")["layers"], f"{pid}.points")
    assert again["count"] == 4 and "P4" in {f["point_id"] for f in again["features"]}
    # adding the project again reloads its layers, it does not add them twice
    twice = qgis("add_layers", project=pid)["layers"]
    assert sorted(lyr["collection"] for lyr in twice) == sorted(lyr["collection"] for lyr in layers)

    # select P2 and send it as a control point
    sent = qgis("send", collection=f"{pid}.points", ids=["P2"], role="control")
    assert sent["selected"] == 1 and sent["answer"] == {"imported": 1}, sent
    cps = http.get(f"/api/projects/{pid}/checkpoints").json()["check_points"]
    assert [(c["id"], c["role"], c["crs"]) for c in cps] == [("P2", "control", "EPSG:4979")]
    rec = api["P2"]
    assert abs(cps[0]["x"] - rec["lon"]) < 1e-9 and abs(cps[0]["y"] - rec["lat"]) < 1e-9
    assert abs(cps[0]["z"] - rec["h_wgs84"]) < 1e-4
    # in the map too, though that layer was empty (so without fields) when it was added
    shown = layer(qgis("refresh")["layers"], f"{pid}.check_points")["features"]
    assert [(f["point_id"], f["role"]) for f in shown] == [("P2", "control")], shown

    # nothing selected: nothing sent, and said
    none = qgis("send", collection=f"{pid}.points", ids=[], role="check")
    assert none["answer"] is None and "No selected point features" in none["messages"][-1]
    # a layer of the user's own in the grid, ids from its name field, else the feature id
    mine = qgis("send_memory", crs=GRID, role="check",
                rows=[{"name": "CP9", "x": 530100.25, "y": 180400.5, "z": 12.5},
                      {"name": None, "x": 530110.0, "y": 180410.0, "z": 13.0}])
    assert mine["answer"] == {"imported": 2}, mine
    cps = {c["id"]: c for c in http.get(f"/api/projects/{pid}/checkpoints").json()["check_points"]}
    assert (cps["CP9"]["role"], cps["CP9"]["crs"]) == ("check", GRID)
    assert (cps["CP9"]["x"], cps["CP9"]["y"], cps["CP9"]["z"]) == (530100.25, 180400.5, 12.5)
    assert set(cps) == {"P2", "CP9", "2"}
    # a refused request is said with the server's reason, nothing stored
    dup = qgis("send_memory", crs=GRID, role="check",
               rows=[{"name": "X", "x": 1.0, "y": 2.0}, {"name": "X", "x": 3.0, "y": 4.0}])
    assert dup["answer"] is None and "duplicate id 'X'" in dup["messages"][-1], dup
    assert len(http.get(f"/api/projects/{pid}/checkpoints").json()["check_points"]) == 3
    # a stored check point is never replaced unasked: the plugin asks, showing old and new
    mine = qgis("send_memory", crs=GRID, role="control", confirm=False,
                rows=[{"name": "CP9", "x": 530200.0, "y": 180500.0, "z": 20.0},
                      {"name": "CP10", "x": 530300.0, "y": 180600.0, "z": 21.0}])
    assert mine["answer"] is None, mine
    (question,) = mine["asked"]
    assert "CP9" in question and "CP10" not in question, question
    assert "530100.25" in question and "530200" in question, question  # old and new x
    assert "check" in question and "control" in question, question  # old and new role
    assert "nothing" in mine["messages"][-1].lower(), mine["messages"]
    cps = {c["id"]: c for c in http.get(f"/api/projects/{pid}/checkpoints").json()["check_points"]}
    assert set(cps) == {"P2", "CP9", "2"}  # declined: nothing stored, CP10 neither
    assert (cps["CP9"]["x"], cps["CP9"]["role"]) == (530100.25, "check")
    mine = qgis("send_memory", crs=GRID, role="control", confirm=True,
                rows=[{"name": "CP9", "x": 530200.0, "y": 180500.0, "z": 20.0}])
    assert mine["answer"] == {"imported": 1} and len(mine["asked"]) == 1, mine
    cps = {c["id"]: c for c in http.get(f"/api/projects/{pid}/checkpoints").json()["check_points"]}
    assert (cps["CP9"]["x"], cps["CP9"]["role"]) == (530200.0, "control")
    assert "replaced" in mine["messages"][-1], mine["messages"]

    # the Connect dialog lists the projects; the connection is kept in QgsSettings
    shown = qgis("dialog", url=base, token=TOKEN)
    assert shown["items"] == 1 and shown["ok"], shown
    refused = qgis("dialog", url="ftp://nowhere", token="")
    assert "http://host:port" in refused["status"] and not refused["ok"]
    assert qgis("settings") == {"url": base, "token": TOKEN, "project": pid}
    assert qgis("live", on=True) == {"active": True, "interval_ms": 5000}
    assert qgis("live", on=False)["active"] is False

    # the error ellipse is drawn to ground scale along its bearing (clockwise from north)
    drawn = qgis("ellipse", major=0.06, minor=0.02, bearing=60.0)
    assert abs(drawn["bearing"] - 60.0) < 2.0, drawn
    assert abs(drawn["major"] - 0.06) < 0.003 and abs(drawn["minor"] - 0.02) < 0.003, drawn

    # the measuring view at a clicked place: a click on P3 on a map in the grid
    p3 = api["P3"]
    opened = qgis("viewer", x=p3["easting"], y=p3["northing"], crs=GRID)["opened"]
    assert len(opened) == 1 and opened[0].startswith(f"{base}/?project={pid}&lon=")
    assert opened[0].endswith(f"#token={TOKEN}")
    query = parse_qs(urlsplit(opened[0]).query)
    assert abs(float(query["lon"][0]) - p3["lon"]) < 1e-7
    assert abs(float(query["lat"][0]) - p3["lat"]) < 1e-7

    # switched off: no action, no token on QGIS's requests, no timer left behind
    assert qgis("unload") == {"actions": 0, "token_hook": False, "live": False}
