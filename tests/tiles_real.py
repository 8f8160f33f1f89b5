"""Rebuilding a PLY from the shared real tileset and converting it back with gsgeo tiles."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from gsgeo.tiles.build import Summary, build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
from gsgeo.tiles.reader import iter_tileset, transform_splats
from gsgeo.tiles.splats import Splats


def real_root_frame(tileset_dir: Path) -> tuple[Splats, np.ndarray]:
    """All splats of the tileset in its root tile frame, and the root transform (row-major)."""
    doc = json.loads((tileset_dir / "tileset.json").read_text())
    root = np.array(doc["root"]["transform"], float).reshape(4, 4).T
    inv = np.linalg.inv(root)
    parts = [transform_splats(t.splats, inv @ t.to_ecef)
             for t in iter_tileset(tileset_dir, frame="content")]
    return Splats.concatenate(parts), root


def rebuild_ply_and_tiles(tileset_dir: Path, work: Path, out: Path) -> Summary:
    """PLY in the root ENU frame (float32 is fine: coordinates within ±200 m) + --transform."""
    s, root = real_root_frame(tileset_dir)
    write_ply(work / "real.ply", s)
    (work / "root.json").write_text(json.dumps(root.T.reshape(-1).tolist()))
    from gsgeo.tiles.georef import load_matrix
    return build_tileset(work / "real.ply", out,
                         Georeference("transform", matrix=load_matrix(work / "root.json")),
                         progress=None)
