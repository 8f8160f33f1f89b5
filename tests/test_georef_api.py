"""Georeferencing through the HTTP API and the command line: results, refusals, messages."""

from __future__ import annotations

import csv
import json
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from georef_helpers import aim, lon_lat_h, truth

from gsgeo.crs.ellipsoid import geodetic_to_ecef_closed_form

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app

GSGEO = [sys.executable, "-m", "gsgeo"]


def _root() -> np.ndarray:
    root = np.eye(4)
    root[:3, :3] = np.array([[0, 1.0, 0], [0, 0, 1.0], [1.0, 0, 0]])  # ENU at lat 0, lon 0
    root[:3, 3] = geodetic_to_ecef_closed_form(0, 0, 0)
    return root


@pytest.fixture
def site(tmp_path):
    """DATA with a bare local scene, a client, a project with 6 measured targets and control
    for 5 of them (ids G0..G4), check point G5."""
    data = tmp_path / "data"
    (data / "scenes" / "loc").mkdir(parents=True)
    root = _root()
    (data / "scenes" / "loc" / "tileset.json").write_text(json.dumps(
        {"asset": {"version": "1.1"}, "geometricError": 10,
         "root": {"transform": root.T.reshape(-1).tolist(), "geometricError": 10,
                  "boundingVolume": {"box": [0, 0, 0, 20, 0, 0, 0, 20, 0, 0, 0, 20]}}}))
    rng = np.random.default_rng(11)
    local = rng.uniform(-6, 6, (6, 3))
    x = local @ root[:3, :3].T + root[:3, 3]
    llh = lon_lat_h(truth().apply(local))
    with TestClient(create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"}))) as c:
        r = c.post("/api/projects", json={"name": "loc", "id": "loc", "scene": "loc",
                                          "crs": "EPSG:27700"})
        assert r.status_code == 201, r.text
        up = x[0] / np.linalg.norm(x[0])
        for i in range(6):
            r = c.post("/api/projects/loc/points",
                       json={"id": f"G{i}", "rays": aim(rng, x[i], up, 10.0)})
            assert r.status_code == 201, r.text
        pts = [{"id": f"G{i}", "x": llh[i, 0], "y": llh[i, 1], "z": llh[i, 2],
                "sigma_h": 0.005, "sigma_v": 0.01} for i in range(5)]
        r = c.post("/api/projects/loc/checkpoints",
                   json={"crs": "EPSG:4979", "role": "control", "points": pts})
        assert r.status_code in (200, 201), r.text
        r = c.post("/api/projects/loc/checkpoints",
                   json={"crs": "EPSG:4979", "role": "check",
                         "points": [{"id": "G5", "x": llh[5, 0], "y": llh[5, 1],
                                     "z": llh[5, 2]}]})
        assert r.status_code in (200, 201), r.text
        yield c, data, llh


def test_status_fit_apply_undo_through_the_api(site):
    c, data, _ = site
    s = c.get("/api/projects/loc/georeference").json()
    assert s["version"] == 0 and s["georeferenced"] is False
    assert [(k["id"], k["measured"], k["sigma_h"]) for k in s["control"]][:2] == \
        [("G0", True, 0.005), ("G1", True, 0.005)]
    scenes = c.get("/api/scenes").json()["scenes"]
    assert scenes[0]["georeferenced"] is False and scenes[0]["georef_version"] == 0

    r = c.post("/api/projects/loc/georeference", json={})
    assert r.status_code == 200, r.text
    fit = r.json()
    assert fit["applied"] is False and fit["scale"] == pytest.approx(2.7, rel=1e-3)
    assert fit["rmse_check"]["count"] == 1 and fit["rmse_check"]["3d"] < 0.05
    assert len(fit["control"]) == 5 and all(k["used"] for k in fit["control"])
    assert json.loads(data.joinpath("scenes/loc/tileset.json").read_text())["root"][
        "transform"] == _root().T.reshape(-1).tolist()  # a preview writes nothing

    r = c.post("/api/projects/loc/georeference", json={"apply": True})
    assert r.status_code == 200, r.text
    applied = r.json()
    assert applied["scene"]["version"] == 1 and applied["remeasured_points"] == 6
    sim = np.array(applied["scene"]["similarity"]).reshape(4, 4).T
    new_root = np.array(json.loads(data.joinpath("scenes/loc/tileset.json").read_text())[
        "root"]["transform"]).reshape(4, 4).T
    assert np.allclose(new_root, sim @ _root(), rtol=0, atol=1e-6)
    s = c.get("/api/projects/loc/georeference").json()
    assert s["georeferenced"] is True and s["current"]["scale"] == pytest.approx(fit["scale"])
    assert c.get("/api/scenes").json()["scenes"][0]["georef_version"] == 1
    rec = c.get("/api/projects/loc/points/G5").json()
    assert rec["record"]["sigma_e"] > rec["record"]["sigma_e_meas"]

    u = c.post("/api/projects/loc/georeference/undo")
    assert u.status_code == 200 and u.json()["version"] == 2
    r = c.post("/api/projects/loc/georeference/undo")
    assert r.status_code == 422 and "nothing to undo" in r.json()["message"]


def test_refusals_name_the_problem(site):
    c, *_ = site
    r = c.post("/api/projects/loc/georeference", json={"exclude": ["G0", "G1", "G2"]})
    assert r.status_code == 422 and "at least 3 measured control points" in r.json()["message"]
    r = c.post("/api/projects/loc/georeference", json={"exclude": ["XX"]})
    assert r.status_code == 422 and "not a control point: XX" in r.json()["message"]
    r = c.post("/api/projects/loc/georeference", json={"bogus": 1})
    assert r.status_code == 422
    r = c.post("/api/projects/nope/georeference", json={})
    assert r.status_code == 404
    r = c.post("/api/projects/loc/georeference",
               json={"scale_only": {"distances": [{"from": "G0", "to": "ZZ", "distance": 3}]}})
    assert r.status_code == 422 and "'ZZ' is not measured" in r.json()["message"]
    r = c.post("/api/projects/loc/points", json={"id": "Q", "rays": aim(
        np.random.default_rng(1), _root()[:3, 3], _root()[:3, 2], 5.0), "georef_version": 9})
    assert r.status_code == 422 and "no georeference version 9" in r.json()["message"]


# --- the command line, session mode ---------------------------------------------------------
@pytest.fixture
def session_files(tmp_path):
    rng = np.random.default_rng(3)
    root = _root()
    local = rng.uniform(-6, 6, (5, 3))
    x = local @ root[:3, :3].T + root[:3, 3]
    up = x[0] / np.linalg.norm(x[0])
    session = {"points": [{"id": f"A{i}", "rays": aim(rng, x[i], up, 10.0)} for i in range(5)]}
    (tmp_path / "s.json").write_text(json.dumps(session))
    llh = lon_lat_h(truth().apply(local))
    with open(tmp_path / "control.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["id", "lon", "lat", "h", "sigma_h", "sigma_v"])
        for i in range(5):
            w.writerow([f"A{i}", *llh[i], 0.005, 0.01])
    return tmp_path


def _run(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([*GSGEO, "georef", *map(str, args)], capture_output=True, text=True,
                          timeout=120)


def test_session_mode_prints_the_fit_and_refuses_bad_input(session_files):
    d = session_files
    out = _run(d / "s.json", "--control", d / "control.csv", "--control-crs", "EPSG:4979",
               "--crs", "EPSG:27700", "--json")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["scale"] == pytest.approx(2.7, rel=1e-3) and len(r["rotation"]) == 3
    assert {"dE", "dN", "dH", "outlier"} <= set(r["control"][0])
    table = _run(d / "s.json", "--control", d / "control.csv", "--control-crs", "EPSG:4979")
    assert table.returncode == 0 and "A0" in table.stdout and "scale 2.7" in table.stdout
    for args, words in [
        (("--exclude", "B7"), "not a control point: B7"),
        (("--exclude", "A0", "--exclude", "A1", "--exclude", "A2"), "at least 3"),
        (("--crs", "EPSG:99999"), "EPSG:99999"),
    ]:
        bad = _run(d / "s.json", "--control", d / "control.csv", "--control-crs", "EPSG:4979",
                   *args)
        assert bad.returncode == 2, (args, bad.stderr)
        assert words in bad.stderr and "Traceback" not in bad.stderr
    lines = (d / "control.csv").read_text().splitlines()
    (d / "line.csv").write_text("\n".join([lines[0]] + [
        f"A{i},{-1.25 + 1e-4 * i},{51.75 + 1e-4 * i},{70 + i},0.005,0.01" for i in range(4)]))
    bad = _run(d / "s.json", "--control", d / "line.csv", "--control-crs", "EPSG:4979")
    assert bad.returncode == 2 and "one line" in bad.stderr
    none = _run("--control", d / "control.csv")
    assert none.returncode == 2 and "session file or --project" in none.stderr


def test_session_mode_applies_to_a_scene_folder_and_undoes(session_files):
    d = session_files
    scene = d / "scene"
    scene.mkdir()
    doc = {"asset": {"version": "1.1"}, "geometricError": 1,
           "root": {"transform": _root().T.reshape(-1).tolist(), "geometricError": 1,
                    "boundingVolume": {"box": [0, 0, 0, 1, 0, 0, 0, 1, 0, 0, 0, 1]}}}
    (scene / "tileset.json").write_text(json.dumps(doc))
    out = _run(d / "s.json", "--control", d / "control.csv", "--control-crs", "EPSG:4979",
               "--apply", scene, "--json")
    assert out.returncode == 0, out.stderr
    assert any("re-measured" in w for w in json.loads(out.stdout)["warnings"])
    got = json.loads((scene / "tileset.json").read_text())
    assert got["extras"]["gsgeo"]["georef"]["version"] == 1
    assert got["root"]["transform"] != doc["root"]["transform"]
    undo = _run("--undo", scene, d / "s.json")
    assert undo.returncode == 0, undo.stderr
    back = json.loads(Path(scene / "tileset.json").read_text())
    assert np.allclose(back["root"]["transform"], doc["root"]["transform"], atol=1e-9)
    assert len(back["extras"]["gsgeo"]["georef"]["history"]) == 3
