"""`gsgeo demo --local`: the demo in an arbitrary local frame, tiled without georeference, and
its project with control and check points; georeferenced by measured control, it lands on the
truth.

One `gsgeo demo --local --no-serve` (the real command line, a subprocess) and one build of the
georeferenced demo in a temporary data directory serve every test; the end-to-end test works
on a copy, so the others see the scene as built.
"""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys

import numpy as np
import pytest
from plyfile import PlyData
from scipy.spatial import cKDTree
from servertools import rays_at

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form
from gsgeo.demo import localframe, place, scene
from gsgeo.demo import splats as demo_splats
from gsgeo.demo.build import build_demo
from gsgeo.demo.localbuild import CONTROL_IDS, SIGMA_H, SIGMA_V
from gsgeo.service import Projects, open_store
from gsgeo.tiles.georefhistory import read_scene_georef
from gsgeo.tiles.reader import read_tileset
from tests.conftest import REPO

#: SPZ keeps positions to 1/4096 of a content unit (12 fractional bits), half of it either way.
SPZ_HALF_STEP = 0.5 / 4096


def _gsgeo(*args):
    return subprocess.run([sys.executable, "-m", "gsgeo", *args], capture_output=True,
                          text=True, timeout=600)


@pytest.fixture(scope="module")
def local_run(tmp_path_factory):
    """`gsgeo demo --local --no-serve` in a fresh data directory: (DATA, its process)."""
    d = tmp_path_factory.mktemp("demo-local") / "gsgeo-data"
    r = _gsgeo("demo", "--local", "--data", str(d), "--no-serve")
    assert r.returncode == 0, r.stderr
    return d, r


@pytest.fixture(scope="module")
def data(local_run):
    return local_run[0]


@pytest.fixture(scope="module")
def truth(data):
    return json.loads((data / "demo-local" / "truth.json").read_text(encoding="utf-8"))


@pytest.fixture(scope="module")
def similarity(truth):
    return np.asarray(truth["true_similarity"]["matrix"], np.float64).reshape(4, 4).T


def test_the_command_says_where_and_what(local_run):
    out, err = local_run[1].stdout, local_run[1].stderr
    assert "?scene=demo-local&project=demo-local" in out
    assert "6 control points" in out and "14 check points" in out
    assert "not georeferenced" in out
    # the tiles command's own warning, as `gsgeo tiles` without georeference prints it
    assert "gsgeo tiles: warning: no georeference given" in err
    assert f"gsgeo georef --project demo-local --data {local_run[0]} --apply" in out


def test_local_scene_sits_at_lat0_lon0_not_georeferenced(data):
    ts = json.loads((data / "scenes" / "demo-local" / "tileset.json").read_text(encoding="utf-8"))
    root = np.asarray(ts["root"]["transform"], np.float64).reshape(4, 4).T
    lon, lat, h = ecef_to_geodetic_closed_form(root[:3, 3])
    assert abs(lat) < 1e-3 and abs(lon) < 1e-3 and abs(h) < 50, (lat, lon, h)
    state = read_scene_georef(data / "scenes" / "demo-local")
    assert state.georeferenced is False and state.version == 0
    # the normal demo's scene is not built by --local
    assert not (data / "scenes" / "demo").exists()


def test_true_similarity_is_a_similarity_of_the_stated_scale(truth, similarity):
    lin = similarity[:3, :3]
    s = float(np.cbrt(np.linalg.det(lin)))
    assert s == pytest.approx(1 / localframe.SCALE, rel=1e-12)
    assert truth["true_similarity"]["scale"] == pytest.approx(s, rel=1e-12)
    np.testing.assert_allclose((lin / s) @ (lin / s).T, np.eye(3), atol=1e-12)
    # the local frame is not level: the true up leans well away from the local z
    r = np.asarray(truth["local_frame"]["rotation"])
    assert np.degrees(np.arccos(r[2, 2])) > 30


def test_every_point_of_the_truth_is_consistent(truth, similarity):
    """truth.json's frames agree: S maps each point's rendered ECEF onto its true ECEF, which
    is the georeferenced demo's truth; the control ids are the stated ones."""
    by_id = {t.id: t for t in place.truth_points()}
    for p in truth["points"]:
        mapped = localframe.apply(similarity, p["rendered_ecef"])[0]
        assert np.linalg.norm(mapped - np.asarray(by_id[p["id"]].ecef)) < 1e-6, p["id"]
        assert p["role"] == ("control" if p["id"] in CONTROL_IDS else "check")
    assert len(truth["points"]) == len(scene.VALIDATION_POINTS)


def test_local_ply_is_the_demo_moved_by_the_true_similarity(data, similarity):
    """Splat by splat (same order), the local PLY through the lat-0 placement and S lands on
    the demo's splats through its grid path (float32 rounding only)."""
    v = PlyData.read(str(data / "demo-local" / "scene.ply"))["vertex"]
    q = np.stack([v["x"], v["y"], v["z"]], -1).astype(np.float64)
    part = demo_splats.build_part()
    assert len(q) == len(part.positions)
    idx = np.arange(0, len(q), 97)
    got = localframe.apply(similarity @ localframe.local_to_rendered(), q[idx])
    want = place.local_to_ecef(part.positions[idx])
    assert np.linalg.norm(got - want, axis=1).max() < 1e-4


def test_local_tileset_mapped_by_the_true_similarity_lands_on_the_georeferenced_demo(data, similarity):
    """Every sampled splat of the local tileset, mapped by S, has a splat of the georeferenced
    demo's tileset within 1 mm (both quantised by SPZ: at most half a step per axis each, the
    local one 1/SCALE times larger on the ground)."""
    build_demo(data, progress=None)
    geo = read_tileset(data / "scenes" / "demo" / "tileset.json")
    loc = read_tileset(data / "scenes" / "demo-local" / "tileset.json")
    assert loc.count == geo.count
    sample = loc.positions[::53]
    dist, _ = cKDTree(geo.positions).query(localframe.apply(similarity, sample))
    bound = np.sqrt(3) * SPZ_HALF_STEP * (1 / localframe.SCALE + 1)
    assert bound < 1e-3
    assert dist.max() < bound, dist.max()


def test_targets_are_marked_in_the_local_splats(data, truth):
    """Every validation point has its red marker dot in the local tileset, where truth.json
    says it renders (what the viewer shows at lat 0, lon 0)."""
    loc = read_tileset(data / "scenes" / "demo-local" / "tileset.json")
    rgb = 0.5 + demo_splats.SH_C0 * loc.colors
    tree = cKDTree(loc.positions)
    quantum = np.sqrt(3) * SPZ_HALF_STEP
    for p in truth["points"]:
        d, i = tree.query(p["rendered_ecef"])
        assert d < quantum, (p["id"], d)
        np.testing.assert_allclose(rgb[i], demo_splats.MARKER_RGB, atol=0.02)


def test_project_holds_control_and_check_points_with_sigmas(data):
    store = open_store(data)
    try:
        projects = Projects(store, data)
        project = projects.get_project("demo-local")
        cps = projects.list_check_points("demo-local")
        status = projects.georeference_status("demo-local")
    finally:
        store.close()
    assert project.scene == "demo-local" and project.crs == place.CRS
    roles = {c.id: c.role for c in cps}
    assert sorted(i for i, r in roles.items() if r == "control") == sorted(CONTROL_IDS)
    assert sorted(i for i, r in roles.items() if r == "check") == sorted(
        v.id for v in scene.VALIDATION_POINTS if v.id not in CONTROL_IDS)
    assert all(c.sigma_h == SIGMA_H and c.sigma_v == SIGMA_V and c.crs == place.CRS for c in cps)
    truth = {t.id: t for t in place.truth_points()}
    for c in cps:
        assert (c.x, c.y, c.z) == pytest.approx(
            (truth[c.id].easting, truth[c.id].northing, truth[c.id].height), abs=1e-4)
    assert status["georeferenced"] is False
    assert sorted(c["id"] for c in status["control"]) == sorted(CONTROL_IDS)
    assert not any(c["measured"] for c in status["control"])


def test_control_is_well_spread(truth):
    """Control spans the site in plan and in height (a similarity needs no collinear layout)."""
    ctl = np.array([p["local"] for p in truth["points"] if p["role"] == "control"])
    sv = np.linalg.svd(ctl - ctl.mean(axis=0), compute_uv=False) / localframe.SCALE
    assert sv[1] > 10 and sv[2] > 2, sv       # true metres


def _measure_control(projects: Projects, pts: dict, rng: np.random.Generator) -> None:
    """Measure the six control targets: 3 rays each aimed at them in the local scene, 0.3 px
    noise at 1 mrad a pixel."""
    for pid in CONTROL_IDS:
        rays = rays_at(pts[pid]["rendered_ecef"], n=3, rng=rng, noise_rad=3e-4, ifov=1e-3,
                       radius=3.0, height=4.0)      # local units: 10 m and 13 m on the ground
        projects.add_point("demo-local", {"id": pid, "rays": rays, "georef_version": 0})


def _measure_control_and_apply(projects: Projects, pts: dict, rng: np.random.Generator) -> dict:
    """Measure the six control targets, fit and apply; the fit's report."""
    _measure_control(projects, pts, rng)
    return projects.georeference("demo-local", apply=True)


def test_georeference_by_measured_control_recovers_the_true_similarity(data, truth, similarity,
                                                                       tmp_path):
    """The workflow of the README: measure the six control targets (rays aimed at them in the
    local scene, 0.3 px noise), fit and apply; the recovered scale is the true one within
    1e-3, the scene lands on the truth, the control already measured moves with it, and check
    points measured afterwards are within 5 cm of their truth."""
    d = tmp_path / "data"
    shutil.copytree(data, d)
    pts = {p["id"]: p for p in truth["points"]}
    rng = np.random.default_rng(16)
    store = open_store(d)
    try:
        projects = Projects(store, d)
        rep = _measure_control_and_apply(projects, pts, rng)
        assert rep["applied"] is True and rep["outliers"] == []
        s_true = truth["true_similarity"]["scale"]
        assert abs(rep["scale"] / s_true - 1) < 1e-3, (rep["scale"], s_true)
        fitted = np.asarray(rep["matrix"], np.float64).reshape(4, 4).T
        rendered = np.array([p["rendered_ecef"] for p in truth["points"]])
        miss = np.linalg.norm(localframe.apply(fitted, rendered)
                              - localframe.apply(similarity, rendered), axis=1)
        assert miss.max() < 0.02, miss.max()
        state = read_scene_georef(d / "scenes" / "demo-local")
        assert state.georeferenced is True and state.version == 1
        # the control measured before the change is re-solved in the new frame
        for p in projects.list_points("demo-local"):
            assert p.result is not None
            got = np.asarray(p.result["point_ecef"])
            assert np.linalg.norm(got - np.asarray(pts[p.id]["ecef"])) < 0.02, p.id
        for pid in ("G1", "B2", "T1", "S3"):
            rays = rays_at(pts[pid]["ecef"], n=3, rng=rng, noise_rad=3e-4, ifov=1e-3,
                           radius=10.0, height=13.0)
            projects.add_point("demo-local", {"id": pid, "rays": rays, "georef_version": 1})
        acc = projects.accuracy("demo-local")
    finally:
        store.close()
    assert acc["counts"]["matched"] == 4
    assert acc["statistics"]["RMSE_3D"] < 0.05


def test_the_readme_command_georeferences_it(data, truth, tmp_path):
    """`gsgeo georef --project demo-local --data DIR --apply` (the README's command, --json
    to read it) fits the measured control and applies it to the scene."""
    d = tmp_path / "data"
    shutil.copytree(data, d)
    store = open_store(d)
    try:
        _measure_control(Projects(store, d), {p["id"]: p for p in truth["points"]},
                         np.random.default_rng(3))
    finally:
        store.close()
    r = _gsgeo("georef", "--project", "demo-local", "--data", str(d), "--apply", "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert abs(rep["scale"] / truth["true_similarity"]["scale"] - 1) < 1e-3
    assert sorted(c["id"] for c in rep["control"]) == sorted(CONTROL_IDS)
    assert read_scene_georef(d / "scenes" / "demo-local").georeferenced is True


def test_rebuild_after_a_georeference_keeps_points_on_their_features(data, truth, tmp_path):
    """`--rebuild` puts the scene back at lat 0, lon 0; the points measured on it while it was
    georeferenced are solved again there (on their targets), not left at Parker's Piece."""
    d = tmp_path / "data"
    shutil.copytree(data, d)
    pts = {p["id"]: p for p in truth["points"]}
    store = open_store(d)
    try:
        _measure_control_and_apply(Projects(store, d), pts, np.random.default_rng(7))
    finally:
        store.close()
    r = _gsgeo("demo", "--local", "--rebuild", "--data", str(d), "--no-serve")
    assert r.returncode == 0, r.stderr
    assert read_scene_georef(d / "scenes" / "demo-local").georeferenced is False
    store = open_store(d)
    try:
        points = Projects(store, d).list_points("demo-local")
    finally:
        store.close()
    assert sorted(p.id for p in points) == sorted(CONTROL_IDS)
    for p in points:
        assert p.result is not None, p.error
        got = np.asarray(p.result["point_ecef"])
        # local units: 1 cm on the ground is 3 mm here
        assert np.linalg.norm(got - np.asarray(pts[p.id]["rendered_ecef"])) < 0.006, p.id
    assert "6 point(s) measured on scene 'demo-local' solved again" in r.stderr


def test_rerun_reuses_the_build_and_keeps_measurements(data, truth):
    store = open_store(data)
    try:
        g1 = truth["points"][[p["id"] for p in truth["points"]].index("G1")]["rendered_ecef"]
        Projects(store, data).add_point("demo-local", {"id": "G1", "rays": rays_at(g1, n=3)})
    finally:
        store.close()
    r = _gsgeo("demo", "--local", "--data", str(data), "--no-serve")
    assert r.returncode == 0, r.stderr
    assert "using the scene built" in r.stderr
    store = open_store(data)
    try:
        projects = Projects(store, data)
        ids = {p.id for p in projects.list_points("demo-local")}
        roles = [c.role for c in projects.list_check_points("demo-local")]
    finally:
        store.close()
    assert "G1" in ids
    assert roles.count("control") == 6 and roles.count("check") == 14


def test_bad_data_directory_gets_a_message(tmp_path):
    f = tmp_path / "a-file"
    f.write_text("x")
    r = _gsgeo("demo", "--local", "--data", str(f), "--no-serve")
    assert r.returncode == 2 and "is not a directory" in r.stderr and "Traceback" not in r.stderr
    assert f.read_text() == "x"


def test_readme_walks_through_the_local_demo():
    """The README's section names the command, the project and exactly the demo's control."""
    readme = (REPO / "README.md").read_text(encoding="utf-8")
    m = re.search(r"## Georeferencing a local scene \(demo\)\n(.*?)\n## ", readme, re.S)
    assert m, "the README has no section 'Georeferencing a local scene (demo)'"
    text = m[1]
    assert "gsgeo demo --local" in text and "demo-local" in text
    assert "gsgeo georef --project demo-local" in text
    for pid in CONTROL_IDS:
        assert re.search(rf"\b{pid}\b", text), pid
