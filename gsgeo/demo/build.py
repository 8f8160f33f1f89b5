"""Build the demo into a data directory: PLY -> `gsgeo tiles` -> scene, plus the ground truth.

Layout (DATA is the directory `gsgeo serve --data` uses):

- ``DATA/demo/scene.ply``       the splats, INRIA 3DGS PLY in the scene frame
- ``DATA/demo/checkpoints.csv`` the ground truth: point_id, code, easting, northing, height
                                (EPSG:27700; height = WGS 84 ellipsoidal, as gsgeo reports)
- ``DATA/demo/truth.json``      the same with ECEF and scene-frame coordinates, the place,
                                the georeference and the build version
- ``DATA/scenes/demo/``         the 3D Tiles scene of ``gsgeo tiles --crs EPSG:27700
                                --offset 545400,258100,12`` (built by the same code, not the CLI)

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
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING, TextIO

from gsgeo.demo import place, scene
from gsgeo.demo import splats as demo_splats
from gsgeo.errors import InputError

if TYPE_CHECKING:
    from gsgeo.tiles.georef import Georeference

#: Bump when the geometry, the splats or the georeference change: older builds are rebuilt.
VERSION = 1
SCENE_NAME = "demo"
#: The whole demo in one tile: CesiumJS 1.145 showed only the root tile of the 5-tile ADD tree
#: gsgeo tiles makes by default (checked in headless Chromium), and one tile of ~350 000 splats
#: renders at once.
MAX_SPLATS_PER_TILE = 400_000


@dataclass
class DemoBuild:
    data_dir: Path
    ply: Path
    tileset: Path
    checkpoints_csv: Path
    truth_json: Path
    splats: int
    built: bool          # False: an existing build was reused
    seconds: float


def paths(data_dir: str | os.PathLike) -> dict[str, Path]:
    d = Path(data_dir)
    return {"ply": d / "demo" / "scene.ply", "csv": d / "demo" / "checkpoints.csv",
            "truth": d / "demo" / "truth.json", "scene": d / "scenes" / SCENE_NAME}


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` (UTF-8) to a temporary file beside ``path``, then rename it there."""
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(text, encoding="utf-8")
    os.replace(tmp, path)


def is_built(data_dir: str | os.PathLike) -> bool:
    """True when DATA holds a complete demo build of the current VERSION."""
    p = paths(data_dir)
    if not (p["scene"] / "tileset.json").is_file() or not p["csv"].is_file():
        return False
    try:
        doc = json.loads(p["truth"].read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return False
    return doc.get("version") == VERSION


def counted(n: int | None, noun: str) -> str:
    """'1 tile', '3 tiles' (English plural by -s); '? tiles' when the count is unknown."""
    if n is None:
        return f"? {noun}s"
    return f"{n:,} {noun}" if n == 1 else f"{n:,} {noun}s"


def checkpoints_csv_text(truth: list[place.TruthPoint]) -> str:
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["point_id", "code", "easting", "northing", "height", "description"])
    for t in truth:
        w.writerow([t.id, t.code, f"{t.easting:.4f}", f"{t.northing:.4f}", f"{t.height:.4f}",
                    t.description])
    return buf.getvalue()


def build_scene(ply: Path, out: Path, georef: Georeference, progress: TextIO | None) -> int:
    """The scene of `gsgeo tiles PLY -o OUT` with the options ``georef`` stands for, through
    the same build_tileset the command uses; returns the tile count. Warnings go to
    `progress` as the command prints them."""
    import numpy as np

    from gsgeo.tiles.build import build_tileset
    from gsgeo.tiles.workers import keep_freed_memory

    keep_freed_memory()   # as `gsgeo tiles` does: the build's temporaries are reused

    def warn(messages: list[str]) -> None:
        if progress is not None:
            for w in messages:
                print(f"gsgeo tiles: warning: {w}", file=progress)

    def started() -> None:
        warn(georef.warnings)
        georef.warnings.clear()

    # values out of range are refused by the build by name; numpy's warnings would add noise
    with np.errstate(all="ignore"):
        summary = build_tileset(ply, out, georef, max_splats=MAX_SPLATS_PER_TILE, level=1,
                                overwrite=True, progress=progress, on_start=started)
    warn(summary.warnings)
    return summary.tiles


def grid_georeference() -> Georeference:
    """The georeference of `gsgeo tiles --crs EPSG:27700 --offset E,N,H --height ellipsoidal`."""
    from gsgeo.tiles.georef import Georeference

    return Georeference.from_options(crs=place.CRS, offset=place.OFFSET, height="ellipsoidal")


def build_demo(data_dir: str | os.PathLike, *, force: bool = False,
               progress: TextIO | None = sys.stderr) -> DemoBuild:
    """Build (or reuse) the demo scene and its ground truth in ``data_dir``."""
    t0 = time.monotonic()
    d = Path(data_dir)
    if d.exists() and not d.is_dir():
        raise InputError(f"--data {d}: is not a directory")
    p = paths(d)
    if not force and is_built(d):
        doc = json.loads(p["truth"].read_text(encoding="utf-8"))
        return DemoBuild(d, p["ply"], p["scene"], p["csv"], p["truth"], int(doc["splats"]),
                         False, time.monotonic() - t0)

    def say(msg: str) -> None:
        if progress is not None:
            print(f"gsgeo demo: {msg}", file=progress, flush=True)

    p["ply"].parent.mkdir(parents=True, exist_ok=True)
    p["scene"].parent.mkdir(parents=True, exist_ok=True)
    say("sampling splats on the scene geometry ...")
    part = demo_splats.build_part()
    n = demo_splats.write_ply(p["ply"], part)
    say(f"wrote {n:,} splats to {p['ply']}; converting with gsgeo tiles "
        f"--crs {place.CRS} --offset {','.join(f'{v:g}' for v in place.OFFSET)} ...")
    tiles = build_scene(p["ply"], p["scene"], grid_georeference(), progress)
    truth = place.truth_points()
    atomic_write(p["csv"], checkpoints_csv_text(truth))
    doc = {
        "version": VERSION,
        "place": place.PLACE,
        "crs": place.CRS,
        "offset": list(place.OFFSET),
        "georeference": f"gsgeo tiles --crs {place.CRS} --offset "
                        f"{','.join(f'{v:g}' for v in place.OFFSET)} --height ellipsoidal "
                        "(scene frame = grid E, N and OSGB36 ellipsoidal height minus offset)",
        "heights": "check point heights are WGS 84 ellipsoidal heights (what gsgeo reports "
                   "for EPSG:27700 without --vertical)",
        "splats": n,
        "tiles": tiles,
        "points": [asdict(t) for t in truth],
        "subsets": list(scene.SUBSETS),
    }
    atomic_write(p["truth"], json.dumps(doc, indent=1))   # written last: marks the build done
    say(f"scene {p['scene']} ({counted(tiles, 'tile')}) and {len(truth)} check "
        f"points in {time.monotonic() - t0:.1f} s")
    return DemoBuild(d, p["ply"], p["scene"], p["csv"], p["truth"], n, True,
                     time.monotonic() - t0)
