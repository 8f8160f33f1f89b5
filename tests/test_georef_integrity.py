"""A scene's georeference under change: one read per answer, the author of a change that
did not commit, a compact history (old inline histories still load and undo), temporary
files of killed writers cleaned."""

from __future__ import annotations

import builtins
import io
import json
import os
import shutil
from pathlib import Path

import numpy as np
import pytest

from gsgeo.crs.ellipsoid import geodetic_to_ecef_closed_form
from gsgeo.crs.modelmatrix import column_major
from gsgeo.service import audit, open_projects
from gsgeo.service import projects as projects_module
from gsgeo.tiles.georefhistory import apply_similarity, read_scene_georef, undo


def _root() -> np.ndarray:
    root = np.eye(4)
    root[:3, :3] = np.array([[0, 1.0, 0], [0, 0, 1.0], [1.0, 0, 0]])  # ENU at lat 0, lon 0
    root[:3, 3] = geodetic_to_ecef_closed_form(0, 0, 0)
    return root


def _shift(dx: float) -> np.ndarray:
    s = np.eye(4)
    s[:3, 3] = [dx, 0.0, 0.0]
    return s


def _frame_cov(k: float) -> dict:
    from gsgeo.measure.framecov import FrameCovariance

    return FrameCovariance(np.array([float(k), 0.0, 0.0]), np.eye(7) * 1e-6 * k).to_json()


@pytest.fixture
def scene(tmp_path) -> Path:
    d = tmp_path / "data" / "scenes" / "loc"
    d.mkdir(parents=True)
    (d / "tileset.json").write_text(json.dumps(
        {"asset": {"version": "1.1"}, "geometricError": 10,
         "root": {"transform": column_major(_root()), "geometricError": 10,
                  "boundingVolume": {"box": [0, 0, 0, 20, 0, 0, 0, 20, 0, 0, 0, 20]}}}))
    return d


# 1. one read per answer ----------------------------------------------------------------------
def test_scene_listing_pairs_a_transform_with_its_own_version(scene, monkeypatch, tmp_path):
    """Every open of tileset.json is followed at once by a georeference change (the file
    replaced, as an apply does): the answer must still be of one version."""
    from gsgeo.server import scenes as scenes_module

    ts = scene / "tileset.json"
    versions = []
    for k in range(2):
        apply_similarity(scene, _shift(1000.0 * (k + 1)), kind="control",
                         frame_covariance=None, summary=None)
        versions.append(tmp_path / f"v{k + 1}.json")
        shutil.copy(ts, versions[-1])
    shutil.copy(versions[0], ts)
    roots = {h["version"]: h["root_transform"] for h in read_scene_georef(versions[1]).history}
    real_open = builtins.open
    turn = [0]

    def open_then_change(file, *args, **kwargs):
        f = real_open(file, *args, **kwargs)
        if os.fspath(file) == os.fspath(ts):
            turn[0] += 1
            os.replace(shutil.copy(versions[turn[0] % 2], tmp_path / "next.json"), ts)
        return f

    monkeypatch.setattr(builtins, "open", open_then_change)
    monkeypatch.setattr(io, "open", open_then_change)
    info = scenes_module.scene_info(scene)
    monkeypatch.undo()
    assert info["error"] is None, info
    assert info["transform"] == roots[info["georef_version"]], (info["georef_version"], turn)


# 2. the author of a change whose store transaction never committed -----------------------------
def test_a_change_killed_before_its_commit_is_credited_to_its_author(scene, monkeypatch):
    data = scene.parents[1]
    svc = open_projects(data)
    with audit.acting_as("ada"):
        svc.create_project(name="loc", id="loc", scene="loc")
    apply_similarity(scene, _shift(5.0), kind="control", frame_covariance=_frame_cov(1.0),
                     summary={"kind": "control", "scale": 1.0})  # a session's change
    assert svc.follow_scene("loc")

    def killed(*_args, **_kwargs):
        raise KeyboardInterrupt("killed")  # as a kill after the tileset write: no restore

    monkeypatch.setattr(projects_module.Projects, "_remeasure_scene", killed)
    monkeypatch.setattr(projects_module, "restore_on_failure", lambda *a: None)
    with audit.acting_as("ada"), pytest.raises(KeyboardInterrupt):
        svc.undo_georeference("loc")
    monkeypatch.undo()
    assert read_scene_georef(scene).version == 2  # the undo stayed in tileset.json
    with audit.acting_as("bob"):
        svc.georeference_status("loc")  # the next reader catches up
    e = audit.audit_page(svc.store, "loc", limit=1)["entries"][0]
    assert (e["user"], e["action"], e["after"]["version"]) == ("ada", "georeference undone", 2)
    assert e["after"]["caught_up_by"] == "bob"


# 3. a compact history; old inline histories load and undo ------------------------------------
def test_history_stays_compact_and_undo_restores_the_fit(scene):
    ts = scene / "tileset.json"
    big = {"kind": "control", "scale": 1.0, "residuals": [{"id": f"C{i}", "v": [0.1] * 30}
                                                          for i in range(40)]}
    assert len(json.dumps(big)) > 6000
    sizes = []
    for k in range(12):
        apply_similarity(scene, _shift(1.0), kind="control", frame_covariance=_frame_cov(k + 1),
                         summary=big | {"scale": 1.0 + k})
        sizes.append(ts.stat().st_size)
    per_version = (sizes[-1] - sizes[1]) / 10
    assert per_version < 1000, per_version
    state, _ = undo(scene)
    assert state.frame_covariance == _frame_cov(11)
    rec = read_scene_georef(scene).record()
    assert rec["summary"]["scale"] == 11.0 and rec["frame_covariance"] == _frame_cov(11)


def test_an_inline_history_of_an_older_gsgeo_loads_and_undoes(scene):
    ts = scene / "tileset.json"
    doc = json.loads(ts.read_text())
    r0, r1 = _root(), _shift(3.0) @ _root()
    entry = {"at": "2026-01-01T00:00:00Z", "georeferenced": True}
    doc["root"]["transform"] = column_major(r1)
    doc["extras"] = {"gsgeo": {"georef": {
        "version": 1, "georeferenced": True, "kind": "control",
        "frame_covariance": _frame_cov(2.0),
        "history": [entry | {"version": 0, "kind": "tiles", "root_transform": column_major(r0),
                             "parent": None, "frame_covariance": _frame_cov(7.0),
                             "summary": {"scale": 7.0}},
                    entry | {"version": 1, "kind": "control",
                             "root_transform": column_major(r1), "parent": 0,
                             "frame_covariance": _frame_cov(2.0),
                             "summary": {"scale": 2.0}}]}}}
    ts.write_text(json.dumps(doc))
    assert read_scene_georef(scene).record()["summary"] == {"scale": 2.0}
    state, sim = undo(scene)
    assert state.version == 2 and np.allclose(state.root_transform, r0)
    assert np.allclose(sim, np.linalg.inv(_shift(3.0)))
    assert state.frame_covariance == _frame_cov(7.0)
    again = read_scene_georef(scene)
    assert again.record()["summary"] == {"scale": 7.0}
    assert again.record(1)["summary"] == {"scale": 2.0}
    assert all("summary" not in h for h in again.history)  # moved out on the write


# 4. what a killed writer left ---------------------------------------------------------------
def test_the_next_write_removes_what_killed_writers_left(scene):
    dead = scene / ".tileset.999999999.abc123.tmp"  # beyond any pid: no such process
    old = scene / ".tileset.legacy1.tmp"  # an older gsgeo's name, an hour old
    mine = scene / f".tileset.{os.getpid()}.busy.tmp"  # a live writer's
    for f in (dead, old, mine):
        f.write_text("{}")
    os.utime(old, (0, os.path.getmtime(old) - 3600))
    apply_similarity(scene, _shift(1.0), kind="control", frame_covariance=None, summary=None)
    left = sorted(p.name for p in scene.glob(".tileset.*.tmp"))
    assert left == [mine.name], left


# 5. a point whose stated georef_version its rays contradict ---------------------------------
def test_a_point_taken_under_another_version_than_stated_is_refused(scene):
    from georef_helpers import aim

    from gsgeo.store.records import ConflictError

    data = scene.parents[1]
    svc = open_projects(data)
    svc.create_project(name="loc", id="loc", scene="loc")
    apply_similarity(scene, _shift(2.0e6), kind="control", frame_covariance=None, summary=None)
    svc.follow_scene("loc")
    rng = np.random.default_rng(3)
    r0, r1 = _root(), _shift(2.0e6) @ _root()
    local = np.array([3.0, -4.0, 1.5])  # inside the scene's 20 m box
    up = r0[:3, 3] / np.linalg.norm(r0[:3, 3])
    in_v0 = aim(rng, r0[:3, :3] @ local + r0[:3, 3], up, 10.0)
    in_v1 = aim(rng, r1[:3, :3] @ local + r1[:3, 3], up, 10.0)
    # stated right: stored, at the same place of the scene either way
    a = svc.add_point("loc", {"id": "A", "rays": in_v0, "georef_version": 0})
    b = svc.add_point("loc", {"id": "B", "rays": in_v1, "georef_version": 1})
    assert np.allclose(a.result["point_ecef"], b.result["point_ecef"], atol=0.05)
    # rays taken under version 0 said to be of version 1 (a torn read of the scene): 2000 km off
    with pytest.raises(ConflictError) as exc:
        svc.add_point("loc", {"id": "C", "rays": in_v0, "georef_version": 1})
    assert exc.value.field == "georef_version" and "version 0" in str(exc.value), exc.value
    assert [q.id for q in svc.list_points("loc")] == ["A", "B"]
