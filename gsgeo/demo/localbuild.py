"""Build the demo's local variant: the demo in an arbitrary local frame, tiled without georeference.

Layout (DATA is the directory `gsgeo serve --data` uses):

- ``DATA/demo-local/scene.ply``       the splats in the local frame (:mod:`gsgeo.demo.localframe`)
- ``DATA/demo-local/control.csv``     the control points: point_id, code, easting, northing,
                                      height, sigma_h, sigma_v, description (EPSG:27700;
                                      height = WGS 84 ellipsoidal, as the demo's check points)
- ``DATA/demo-local/checkpoints.csv`` the other validation points, same columns (role check)
- ``DATA/demo-local/truth.json``      the local frame, the true similarity (rendered ECEF of
                                      the local tileset -> true ECEF) and every point in the
                                      grid, true ECEF, the local frame and rendered ECEF
- ``DATA/scenes/demo-local/``         the scene of ``gsgeo tiles scene.ply`` without
                                      georeference: at lat 0, lon 0, with the command's warning

A build is reused while ``truth.json`` carries the current :data:`VERSION` and the tileset
exists; otherwise everything is rebuilt (each file written atomically).
"""

from __future__ import annotations

import csv
import io
import json
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import TextIO

import numpy as np

from gsgeo.demo import localframe, place
from gsgeo.demo import splats as demo_splats
from gsgeo.demo.build import atomic_write, build_scene, counted
from gsgeo.errors import InputError

#: Bump when the local frame, the control or the splats change: older builds are rebuilt.
VERSION = 1
SCENE_NAME = "demo-local"
#: Six well-spread targets (west, east, north, south-west, south-east; from the ground to the
#: roof) that serve as control; every other validation point is a check point.
CONTROL_IDS = ("G2", "G3", "G4", "R1", "T3", "T4")
#: Stated precision of the control and check coordinates (m, 1 sigma): an RTK GNSS survey.
SIGMA_H = 0.01
SIGMA_V = 0.015


@dataclass
class LocalBuild:
    """Where a local-variant build is and what it holds; ``similarity`` the true 4x4
    (rendered ECEF of the local tileset -> true ECEF)."""

    data_dir: Path
    ply: Path
    tileset: Path
    control_csv: Path
    checkpoints_csv: Path
    truth_json: Path
    splats: int
    built: bool          # False: an existing build was reused
    seconds: float
    similarity: np.ndarray


def paths(data_dir: str | os.PathLike) -> dict[str, Path]:
    d = Path(data_dir)
    return {"ply": d / SCENE_NAME / "scene.ply", "control": d / SCENE_NAME / "control.csv",
            "check": d / SCENE_NAME / "checkpoints.csv", "truth": d / SCENE_NAME / "truth.json",
            "scene": d / "scenes" / SCENE_NAME}


def role(point_id: str) -> str:
    """'control' for the ids of :data:`CONTROL_IDS`, else 'check'."""
    return "control" if point_id in CONTROL_IDS else "check"


def points_csv_text(truth: list[place.TruthPoint]) -> str:
    """The CSV of ``truth`` with the stated sigmas (columns sigma_h, sigma_v)."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["point_id", "code", "easting", "northing", "height", "sigma_h", "sigma_v",
                "description"])
    for t in truth:
        w.writerow([t.id, t.code, f"{t.easting:.4f}", f"{t.northing:.4f}", f"{t.height:.4f}",
                    f"{SIGMA_H:g}", f"{SIGMA_V:g}", t.description])
    return buf.getvalue()


def _doc(path: Path) -> dict | None:
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    return doc if isinstance(doc, dict) else None


def is_built(data_dir: str | os.PathLike) -> bool:
    """True when DATA holds a complete local-variant build of the current VERSION."""
    p = paths(data_dir)
    if not all(f.is_file() for f in (p["scene"] / "tileset.json", p["control"], p["check"])):
        return False
    doc = _doc(p["truth"])
    return doc is not None and doc.get("version") == VERSION


def truth_document(truth: list[place.TruthPoint], splats: int, tiles: int) -> dict:
    """truth.json: the local frame, the true similarity and every point in all its frames."""
    s = localframe.true_similarity()
    to_local = localframe.ecef_to_local()
    ecef = np.array([t.ecef for t in truth])
    local = localframe.apply(to_local, ecef)
    rendered = localframe.apply(localframe.local_to_rendered(), local)
    points = []
    for i, t in enumerate(truth):
        points.append({
            "id": t.id, "role": role(t.id), "code": t.code, "description": t.description,
            "easting": t.easting, "northing": t.northing, "height": t.height,
            "sigma_h": SIGMA_H, "sigma_v": SIGMA_V, "ecef": list(t.ecef),
            "local": [float(v) for v in local[i]], "rendered_ecef": [float(v) for v in rendered[i]]})
    return {
        "version": VERSION,
        "place": place.PLACE,
        "crs": place.CRS,
        "heights": "heights are WGS 84 ellipsoidal heights (what gsgeo reports for EPSG:27700 "
                   "without --vertical), as in the demo's check points",
        "georeference": "none: gsgeo tiles without georeference (local ENU at lat 0, lon 0)",
        "local_frame": {
            "definition": "q = scale * rotation @ site_rotation.T @ (X - site_centre) + shift; "
                          "X true ECEF (m), q local units",
            "scale": localframe.SCALE, "axis": list(localframe.AXIS),
            "angle_deg": localframe.ANGLE_DEG, "shift": list(localframe.SHIFT),
            "rotation": localframe.rotation().tolist(),
            "site_centre": [float(v) for v in localframe.site_frame().centre],
            "site_rotation": localframe.site_frame().rotation.tolist()},
        "true_similarity": {
            "definition": "rendered ECEF of the local tileset -> true ECEF (y = s R x + t); "
                          "what a perfect georeference finds",
            "matrix": localframe.column_major(s),
            "scale": float(np.cbrt(np.linalg.det(s[:3, :3]))),
            "rotation": (s[:3, :3] / np.cbrt(np.linalg.det(s[:3, :3]))).tolist(),
            "translation": [float(v) for v in s[:3, 3]]},
        "control_ids": list(CONTROL_IDS),
        "sigma_h": SIGMA_H, "sigma_v": SIGMA_V,
        "splats": splats,
        "tiles": tiles,
        "points": points,
    }


def read_similarity(truth_json: Path) -> np.ndarray:
    """The true similarity (4x4) of a build's truth.json."""
    doc = _doc(truth_json)
    if doc is None:
        raise InputError(f"{truth_json}: cannot read the local demo's truth")
    return np.asarray(doc["true_similarity"]["matrix"], np.float64).reshape(4, 4).T


def build_local_demo(data_dir: str | os.PathLike, *, force: bool = False,
                     progress: TextIO | None = sys.stderr) -> LocalBuild:
    """Build (or reuse) the demo's local variant and its control in ``data_dir``."""
    from gsgeo.tiles.georef import Georeference

    t0 = time.monotonic()
    d = Path(data_dir)
    if d.exists() and not d.is_dir():
        raise InputError(f"--data {d}: is not a directory")
    p = paths(d)
    if not force and is_built(d):
        doc = _doc(p["truth"]) or {}
        return LocalBuild(d, p["ply"], p["scene"], p["control"], p["check"], p["truth"],
                          int(doc.get("splats", 0)), False, time.monotonic() - t0,
                          read_similarity(p["truth"]))

    def say(msg: str) -> None:
        if progress is not None:
            print(f"gsgeo demo: {msg}", file=progress, flush=True)

    p["ply"].parent.mkdir(parents=True, exist_ok=True)
    p["scene"].parent.mkdir(parents=True, exist_ok=True)
    say("sampling splats on the scene geometry, in a local frame (scale "
        f"{localframe.SCALE:g}, turned {localframe.ANGLE_DEG:g} deg about a tilted axis, shifted) ...")
    n = demo_splats.write_ply(p["ply"], localframe.local_part(demo_splats.build_part()))
    say(f"wrote {n:,} splats to {p['ply']}; converting with gsgeo tiles (no georeference) ...")
    tiles = build_scene(p["ply"], p["scene"], Georeference.from_options(), progress)
    truth = place.truth_points()
    atomic_write(p["control"], points_csv_text([t for t in truth if role(t.id) == "control"]))
    atomic_write(p["check"], points_csv_text([t for t in truth if role(t.id) == "check"]))
    doc = truth_document(truth, n, tiles)
    atomic_write(p["truth"], json.dumps(doc, indent=1))   # written last: marks the build done
    say(f"scene {p['scene']} ({counted(tiles, 'tile')}, not georeferenced), "
        f"{len(CONTROL_IDS)} control and {len(truth) - len(CONTROL_IDS)} check points in "
        f"{time.monotonic() - t0:.1f} s")
    return LocalBuild(d, p["ply"], p["scene"], p["control"], p["check"], p["truth"], n, True,
                      time.monotonic() - t0, read_similarity(p["truth"]))
