"""Georeferencing local scenes by control points (gsgeo.georef, the service, CLI and API).

The held-out end-to-end test builds a scene in a COLMAP-like local frame (scaled, rotated about
a tilted axis, shifted against a true site), tiles it without georeference, measures six
control targets by noisy rays, georeferences it with ``gsgeo georef --apply`` and compares
every splat and independent check points with the truth.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from georef_helpers import SCALE, aim, lon_lat_h, truth
from tiles_helpers import match, random_splats

from gsgeo.crs.ellipsoid import geodetic_to_ecef_closed_form
from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.modelmatrix import rendered_to_georeferenced
from gsgeo.errors import GeometryError, InputError
from gsgeo.georef.control import control_ecef, grid_to_ecef
from gsgeo.georef.helmert import Similarity, fit_similarity, rotation_from_vector
from gsgeo.georef.scale import Distance
from gsgeo.measure.rays import SolveSettings
from gsgeo.service import open_projects
from gsgeo.service.checkpoints import CheckPointRow
from gsgeo.store.sqlite import SQLiteTransaction
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.georefhistory import read_scene_georef
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.reader import read_tileset

GSGEO = [sys.executable, "-m", "gsgeo"]
EGM96 = Path("/usr/share/proj/egm96_15.gtx")


# --- the fit ---------------------------------------------------------------------------------
def test_exact_similarity_is_recovered_to_rounding():
    rng = np.random.default_rng(1)
    true = Similarity(0.37, rotation_from_vector([2.0, -0.4, 0.9]),
                      geodetic_to_ecef_closed_form(10.0, 45.0, 300.0))
    x = geodetic_to_ecef_closed_form(0.0, 0.0, 0.0) + rng.uniform(-50, 50, (5, 3))
    cov = np.tile(np.eye(3) * 1e-4, (5, 1, 1))
    f = fit_similarity(x, true.apply(x), cov, cov)
    assert f.similarity.scale == pytest.approx(0.37, rel=1e-9)  # ECEF rounding / 50 m
    assert np.abs(f.similarity.rotation - true.rotation).max() < 1e-9
    assert np.abs(f.similarity.apply(x) - true.apply(x)).max() < 1e-6
    assert f.vtpv < 1e-10 and f.dof == 8


def test_fewer_than_three_or_collinear_control_is_refused():
    x = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.0]]) + 6.4e6
    cov = np.tile(np.eye(3) * 1e-4, (3, 1, 1))
    with pytest.raises(GeometryError, match="at least 3"):
        fit_similarity(x[:2], x[:2], cov[:2], cov[:2])
    line = np.array([[0, 0, 0], [1, 1, 1], [2, 2, 2.000001]]) + 6.4e6
    with pytest.raises(GeometryError, match="one line"):
        fit_similarity(line, line, cov, cov)


def test_control_in_the_grid_goes_to_ecef_through_the_projects_own_path():
    """grid_to_ecef inverts the measured points' path (datum operation and geoid) to 0.1 mm."""
    if not EGM96.exists():
        pytest.skip("Debian's proj-data (egm96_15.gtx) is not installed")
    x = geodetic_to_ecef_closed_form(np.array([-1.3, -1.25]), np.array([51.7, 51.76]),
                                     np.array([80.0, 130.0]))
    s = SolveSettings(crs="EPSG:27700", geoid=str(EGM96))
    g = to_grid_many(x, None, s.crs, geoid=s.geoid)
    enh = np.column_stack([g.easting, g.northing, g.height])
    assert np.abs(grid_to_ecef(enh, s) - x).max() < 1e-4
    # the same points as control in the grid CRS and as EPSG:4979 land on the same ECEF
    llh = lon_lat_h(x)
    assert np.abs(control_ecef(enh, ["EPSG:27700"] * 2, s, ["a", "b"]) - x).max() < 1e-4
    assert np.abs(control_ecef(llh, ["EPSG:4979"] * 2, s, ["a", "b"]) - x).max() < 1e-4
    with pytest.raises(InputError, match="no height"):
        control_ecef(np.array([[1.0, 2.0, np.nan]]), ["EPSG:4979"], s, ["Z9"])


# --- the held-out end-to-end test --------------------------------------------------------------
@pytest.fixture(scope="module")
def local_site(tmp_path_factory):
    """A local-frame PLY tiled without georeference into DATA/scenes/site, its project with
    six control targets (one with a 0.5 m blunder in height) and four check points."""
    rng = np.random.default_rng(20261124)
    root = tmp_path_factory.mktemp("georef")
    data = root / "data"
    splats = random_splats(rng, 3000, 0, extent=8.0)
    ply = root / "local.ply"
    write_ply(ply, splats)
    out = subprocess.run([*GSGEO, "tiles", str(ply), "-o", str(data / "scenes" / "site")],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    p = splats.positions
    current = Georeference.from_options().placement(p.min(axis=0), p.max(axis=0))
    t = truth()
    targets = rng.uniform(-7, 7, (10, 3))
    targets[:, 2] = rng.uniform(-1, 3, 10)
    svc = open_projects(data)
    svc.create_project(name="site", id="site", scene="site", crs="EPSG:27700")
    x = current.to_ecef(targets)
    up = x[0] / np.linalg.norm(x[0])
    ids = [f"C{i}" for i in range(6)] + [f"K{i}" for i in range(4)]
    for i in range(6):  # control targets, measured before georeferencing
        svc.add_point("site", {"id": ids[i], "rays": aim(rng, x[i], up, 12.0)})
    y = t.apply(targets)
    llh = lon_lat_h(y)
    llh[3, 2] += 0.5  # a blunder in one control height
    svc.add_check_points("site", [CheckPointRow(ids[i], *llh[i], 0.005, 0.01) for i in range(6)],
                         "EPSG:4979", role="control")
    svc.add_check_points("site", [CheckPointRow(ids[i], *llh[i], 0.003, 0.005)
                                  for i in range(6, 10)], "EPSG:4979", role="check")
    svc.store.close()
    return {"data": data, "splats": splats, "targets": targets, "truth_ecef": y, "rng": rng,
            "warning": out.stderr + out.stdout}


def _georef(data: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*GSGEO, "georef", "--project", "site", "--data", str(data), *args],
                          capture_output=True, text=True, timeout=300)


def test_held_out_local_scene_is_georeferenced_by_control(local_site):
    data = local_site["data"]
    assert "georef" in local_site["warning"]  # the tiles warning says how to go on
    scene = data / "scenes" / "site"
    assert read_scene_georef(scene).georeferenced is False

    # the blunder is flagged by its id, and the fit is shown with and without it
    out = _georef(data, "--json")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["outliers"] == ["C3"]
    assert r["without_outliers"]["excluded"] == ["C3"]
    flagged = {c["id"]: c for c in r["control"]}
    assert flagged["C3"]["outlier"] and abs(flagged["C3"]["dH"]) > 0.3
    # applying while a point is flagged is refused, naming it
    refused = _georef(data, "--apply")
    assert refused.returncode == 2 and "C3" in refused.stderr
    assert read_scene_georef(scene).version == 0

    out = _georef(data, "--exclude", "C3", "--apply", "--json")
    assert out.returncode == 0, out.stderr
    r = json.loads(out.stdout)
    assert r["applied"] and r["outliers"] == []
    assert abs(r["scale"] / SCALE - 1) < 1e-3
    state = read_scene_georef(scene)
    assert state.georeferenced and state.version == 1 and len(state.history) == 2

    # every splat of the applied scene within 5 cm of its true ECEF position
    got = read_tileset(scene).positions
    expected = truth().apply(local_site["splats"].positions)
    idx = match(expected, got)
    err = np.linalg.norm(got[idx] - expected, axis=1)
    assert err.max() < 0.05, err.max()

    # check points measured afterwards, in the new frame, within 5 cm (3-D) of the truth
    svc = open_projects(data)
    try:
        rng = local_site["rng"]
        y = local_site["truth_ecef"]
        up = y[0] / np.linalg.norm(y[0])
        for i in range(6, 10):
            svc.add_point("site", {"id": f"K{i - 6}", "rays": aim(rng, y[i], up, 30.0),
                                   "georef_version": 1})
        pts = {q.id: q for q in svc.list_points("site")}
        for i in range(6, 10):
            e = np.array(pts[f"K{i - 6}"].result["point_ecef"]) - y[i]
            assert np.linalg.norm(e) < 0.05, (i, e)
        acc = svc.accuracy("site")
        assert acc["counts"]["matched"] == 4
        # the control measured before the change was re-measured into the new frame
        for i in (0, 1, 2, 4, 5):
            e = np.array(pts[f"C{i}"].result["point_ecef"]) - y[i]
            assert np.linalg.norm(e) < 0.05, (i, e)
            rec = pts[f"C{i}"].record
            assert rec["sigma_e"] > rec["sigma_e_meas"] > 0  # the frame's share is reported
    finally:
        svc.store.close()


# --- service: provenance, undo, atomicity -----------------------------------------------------
@pytest.fixture
def small_site(tmp_path):
    """A bare scene folder (only tileset.json, root at lat 0, lon 0) and a project with five
    measured control targets and their control."""
    rng = np.random.default_rng(7)
    data = tmp_path / "data"
    (data / "scenes" / "s").mkdir(parents=True)
    root = np.eye(4)
    root[:3, :3] = np.array([[0, 1.0, 0], [0, 0, 1.0], [1.0, 0, 0]])  # ENU at (0, 0)
    root[:3, 3] = geodetic_to_ecef_closed_form(0, 0, 0)
    (data / "scenes" / "s" / "tileset.json").write_text(json.dumps(
        {"asset": {"version": "1.1"}, "geometricError": 10,
         "root": {"transform": root.T.reshape(-1).tolist(), "geometricError": 10,
                  "boundingVolume": {"box": [0, 0, 0, 20, 0, 0, 0, 20, 0, 0, 0, 20]}}}))
    svc = open_projects(data)
    svc.create_project(name="s", id="s", scene="s", crs="EPSG:27700")
    targets = rng.uniform(-6, 6, (5, 3))
    x = targets @ root[:3, :3].T + root[:3, 3]
    up = x[0] / np.linalg.norm(x[0])
    for i in range(5):
        svc.add_point("s", {"id": f"G{i}", "rays": aim(rng, x[i], up, 10.0)})
    llh = lon_lat_h(truth().apply(targets))
    svc.add_check_points("s", [CheckPointRow(f"G{i}", *llh[i], 0.005, 0.01) for i in range(5)],
                         "EPSG:4979", role="control")
    yield svc, data, x, rng, up
    svc.store.close()


def test_rays_taken_under_an_old_georeference_are_carried_into_the_new_one(small_site):
    svc, data, x, rng, up = small_site
    before = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    old_rays = aim(rng, x[0], up, 10.0)
    r = svc.georeference("s", apply=True)
    assert r["applied"] and r["remeasured_points"] == 5
    sim = np.array(r["scene"]["similarity"]).reshape(4, 4).T
    after = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    for pid, p in before.items():  # re-measured = the old point carried by the similarity
        assert np.linalg.norm(after[pid] - (sim[:3, :3] @ p + sim[:3, 3])) < 1e-6
    # a viewer that still had version 0 loaded sends its rays with georef_version 0
    stale = svc.add_point("s", {"id": "late", "rays": old_rays, "georef_version": 0})
    fresh = svc.add_point("s", {"id": "late2", "rays": old_rays})
    p_stale = np.array(stale.result["point_ecef"])
    assert np.linalg.norm(p_stale - after["G0"]) < 0.05  # lands on the feature
    assert np.linalg.norm(np.array(fresh.result["point_ecef"]) - p_stale) > 1.0  # not mapped
    # replacing a point's rays with rays from the old frame (PATCH) maps them as well
    patched = svc.update_point("s", "late2", {"rays": old_rays, "georef_version": 0})
    assert np.linalg.norm(np.array(patched.result["point_ecef"]) - p_stale) < 1e-6
    assert patched.frame is not None and patched.frame["version"] == 0
    with pytest.raises(InputError, match="give rays with it"):
        svc.update_point("s", "late2", {"georef_version": 0})
    with pytest.raises(InputError, match="no georeference version 7"):
        svc.add_point("s", {"id": "bad", "rays": old_rays, "georef_version": 7})
    # undo: the scene's previous root, and every point exactly where it was
    u = svc.undo_georeference("s")
    assert u["version"] == 2 and u["georeferenced"] is False
    back = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    for pid, p in before.items():
        assert np.linalg.norm(back[pid] - p) < 1e-6
    assert np.linalg.norm(back["late"] - before["G0"]) < 0.05
    with pytest.raises(InputError, match="nothing to undo"):
        svc.undo_georeference("s")
        svc.undo_georeference("s")


def test_a_store_failure_puts_the_tileset_back(small_site, monkeypatch):
    svc, data, *_ = small_site
    path = data / "scenes" / "s" / "tileset.json"
    text = path.read_bytes()
    stored = {q.id: q.result for q in svc.list_points("s")}

    def broken(*_args, **_kw):
        raise OSError("disk full")

    monkeypatch.setattr(SQLiteTransaction, "update_results", broken)
    with pytest.raises(OSError):
        svc.georeference("s", apply=True)
    monkeypatch.undo()
    assert path.read_bytes() == text
    assert {q.id: q.result for q in svc.list_points("s")} == stored


def test_too_few_measured_control_and_unknown_exclusions_are_named(small_site):
    svc, *_ = small_site
    with pytest.raises(GeometryError, match="at least 3 measured control points; 2 usable"):
        svc.georeference("s", exclude=["G0", "G1", "G2"])
    with pytest.raises(InputError, match="not a control point: nope"):
        svc.georeference("s", exclude=["nope"])


def test_scale_only_fixes_the_scale_from_known_distances(small_site):
    svc, data, *_ = small_site
    pts = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    true_len = 2.5 * np.linalg.norm(pts["G1"] - pts["G0"])
    r = svc.georeference("s", distances=[Distance("G0", "G1", true_len, 0.001)], apply=True)
    assert r["kind"] == "scale" and abs(r["scale"] - 2.5) < 1e-9
    new = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    assert np.linalg.norm(new["G1"] - new["G0"]) == pytest.approx(true_len, rel=1e-9)
    assert read_scene_georef(data / "scenes" / "s").georeferenced is False  # no grid: local


def test_a_scene_without_georeference_keeps_full_position_precision(local_site):
    """Its unit may be many metres: SPZ keeps 18 fractional bits (12 for metric scenes), so
    each splat sits within 2^-19 units of its input position (whatever georeference the
    scene has been given since: the root transforms of the history carry it back)."""
    from gsgeo.tiles.reader import iter_tileset

    scene = local_site["data"] / "scenes" / "site"
    assert {t.header["fractional_bits"] for t in iter_tileset(scene)} == {18}
    state = read_scene_georef(scene)
    back = state.root_of(0) @ np.linalg.inv(state.root_transform)
    got = read_tileset(scene).positions @ back[:3, :3].T + back[:3, 3]
    p = local_site["splats"].positions
    expected = Georeference.from_options().placement(p.min(axis=0), p.max(axis=0)).to_ecef(p)
    idx = match(expected, got)
    assert np.linalg.norm(got[idx] - expected, axis=1).max() < 2e-5


def test_moving_a_project_to_another_scene_forgets_its_frames(small_site):
    svc, data, *_ = small_site
    before = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    svc.georeference("s", apply=True)
    (data / "scenes" / "t").mkdir()
    (data / "scenes" / "t" / "tileset.json").write_bytes(
        (data / "scenes" / "s" / "tileset.json").read_bytes().replace(b'"georef"', b'"x"'))
    svc.update_project("s", {"scene": "t"})  # its rays as taken, no carry from scene s
    moved = {q.id: q for q in svc.list_points("s")}
    for pid, p in before.items():
        assert moved[pid].frame is None
        assert np.linalg.norm(np.array(moved[pid].result["point_ecef"]) - p) < 1e-6


def test_stored_rays_many_equals_the_point_by_point_path():
    """The stacked reading of stored rays (re-measure after a georeference change) gives what
    stored_rays(rays).mapped(carry) gives, point by point; unusual points keep their errors."""
    from gsgeo.service.measuring import stored_rays, stored_rays_many

    rng = np.random.default_rng(5)
    x = geodetic_to_ecef_closed_form(-1.3, 51.7, 80.0)
    up = x / np.linalg.norm(x)
    sim = Similarity(2.5, rotation_from_vector([0.2, -0.1, 0.4]), np.array([10.0, -4.0, 2.0]))
    turn = Similarity(1.0, rotation_from_vector([0.0, 0.0, 0.3]), np.array([5.0, 0, 0]))
    points, carries = [], []
    for k in range(12):
        rays = aim(rng, x + rng.normal(0, 5, 3), up, 10.0, n=2 + k % 4)
        if k % 3:  # under a viewer modelMatrix: a similarity, or the identity
            m = turn.matrix() if k % 3 == 1 else np.eye(4)
            for r in rays:
                r["model_matrix"] = m.T.reshape(-1).tolist()
                r["pixel"], r["viewport"] = [10.0, 20.0], [800.0, 600.0]
        points.append(rays)
        carries.append(sim.matrix() if k % 2 else None)
    want = [stored_rays(p) if c is None else stored_rays(p).mapped(c)
            for p, c in zip(points, carries, strict=True)]

    def georeferenced(r):  # a modelMatrix may be applied on the way in: the same rays
        o, d, _ = rendered_to_georeferenced(r.origins, r.directions,
                                            [r.model_matrix(i) for i in range(len(r))])
        return o, d / np.linalg.norm(d, axis=1, keepdims=True)

    bad = aim(rng, x, up, 10.0)
    bad[1]["direction"] = [0.0, 0.0, 0.0]
    fast = stored_rays_many(points, carries)
    assert all(r.model_matrices is None for r in fast)  # the stacked path ran
    mixed = stored_rays_many(points + [bad], carries + [None])  # point by point
    assert isinstance(mixed[-1], InputError) and "rays[1].direction" in str(mixed[-1])
    for got in (fast, mixed[:-1]):
        for g, w in zip(got, want, strict=True):
            (go, gd), (wo, wd) = georeferenced(g), georeferenced(w)
            assert np.abs(go - wo).max() < 1e-6 and np.abs(gd - wd).max() < 1e-12
            assert np.array_equal(g.ifov, w.ifov)
            for a, b in ((g.pixels, w.pixels), (g.viewports, w.viewports)):
                assert (a is None) == (b is None) and (a is None or np.array_equal(a, b))


def test_a_georeference_applied_without_the_store_is_caught_up_on_the_next_read(small_site):
    """gsgeo georef SESSION --apply (or a crash between tileset.json and the store) moves the
    scene without the project: its next read re-measures, so no point stays in the old frame."""
    from gsgeo.tiles.georefhistory import apply_similarity

    svc, data, *_ = small_site
    before = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    sim = Similarity(1.5, rotation_from_vector([0.0, 0.1, 0.2]), np.array([3.0, 2.0, 1.0]))
    apply_similarity(data / "scenes" / "s", sim.matrix(), kind="similarity",
                     frame_covariance=None, summary=None)
    after = {q.id: np.array(q.result["point_ecef"]) for q in svc.list_points("s")}
    for pid, p in before.items():
        assert np.linalg.norm(after[pid] - sim.apply(p)) < 1e-6
    assert svc.get_project("s").scene_version == 1
    assert svc.follow_scene("s") is False  # nothing more to do
