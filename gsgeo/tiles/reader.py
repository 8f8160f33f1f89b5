"""Reading SPZ 3D Tiles (ours and others') back into splats in ECEF.

Walks tileset.json with :class:`gsgeo.tiles.tileset.Tileset` (external tilesets, tile
transforms, the gltfUpAxis turn of glTF content), adds the glTF node matrices, decodes every
SPZ primitive and turns its splats into ECEF (EPSG:4978, metres): centres exactly (float64), rotations and
SH coefficients by the rotation part, log-scales by the uniform scale of the transform.
"""

from __future__ import annotations

import math
import os
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles import spz
from gsgeo.tiles.gltf import parse_glb
from gsgeo.tiles.splats import Splats, matrix_to_quat, quat_multiply, sh_rotation
from gsgeo.tiles.tileset import Tileset, read_gltf_json


@dataclass
class TileSplats:
    uri: str
    level: int
    splats: Splats           # in ECEF (or the tile content frame, see iter_tileset)
    to_ecef: np.ndarray      # 4x4 content -> ECEF
    header: dict


def transform_splats(s: Splats, m: np.ndarray) -> Splats:
    """Apply a 4x4 similarity transform to splats (centres, orientations, sizes, SH)."""
    a = m[:3, :3]
    scale = np.cbrt(np.linalg.det(a))
    r = a / scale
    u, _, vt = np.linalg.svd(r)
    r = u @ vt
    pos = s.positions @ a.T + m[:3, 3]
    q = matrix_to_quat(r).astype(np.float32)
    rot = quat_multiply(np.broadcast_to(q, s.rotations.shape), s.rotations).astype(np.float32)
    sh = s.sh
    if sh.shape[1]:
        d = sh_rotation(r, sh.shape[1]).astype(np.float32)
        sh = np.einsum("ij,njc->nic", d, sh)
    return Splats(pos, (s.scales + np.float32(math.log(scale))).astype(np.float32), rot,
                  s.opacities, s.colors, sh)


def iter_tileset(path: str | os.PathLike, *, frame: str = "ecef") -> Iterator[TileSplats]:
    """Every SPZ tile of a tileset, its splats in ECEF (frame='ecef') or as stored ('content').

    The tileset is walked by :class:`gsgeo.tiles.tileset.Tileset` (external tilesets, tile
    transforms, gltfUpAxis); ``to_ecef`` is its content-to-ECEF matrix of each primitive.
    """
    ts = Tileset(path)
    for tile in ts.tiles():
        for uri, p in zip(tile.content_uris, tile.content_paths, strict=True):
            try:
                data = p.read_bytes()
            except OSError as exc:
                raise InputError(f"{p}: cannot read tile content ({exc.strerror})") from None
            for blob, node_m in parse_glb(data, str(p)):
                s, header = spz.decode(blob)
                to_ecef = ts.node_to_ecef(tile, node_m)
                if frame == "ecef":
                    s = transform_splats(s, to_ecef)
                yield TileSplats(uri, tile.level, s, to_ecef, header)


def read_tileset(path: str | os.PathLike) -> Splats:
    """All splats of an SPZ tileset, concatenated, in ECEF."""
    parts = [t.splats for t in iter_tileset(path)]
    if not parts:
        raise InputError(f"{path}: the tileset has no SPZ splat content")
    return Splats.concatenate(parts)


def splat_count(path: str | os.PathLike | Tileset) -> int:
    """Number of splats in a tileset (its path, or the tileset already read), from the glTF
    accessor counts (no decoding)."""
    total = 0
    for tile in (path if isinstance(path, Tileset) else Tileset(path)).tiles():
        for p in tile.content_paths:
            gltf, _ = read_gltf_json(_json_head(p), str(p))
            for mesh in gltf.get("meshes", []):
                for prim in mesh["primitives"]:
                    if "KHR_gaussian_splatting" in prim.get("extensions", {}):
                        total += int(gltf["accessors"][prim["attributes"]["POSITION"]]["count"])
    return total


def _json_head(p: Path) -> bytes:
    """The bytes of a GLB up to the end of its JSON chunk (the whole file otherwise)."""
    with open(p, "rb") as f:
        head = f.read(20)
        if head[:4] == b"glTF" and len(head) == 20:
            return head + f.read(struct.unpack("<I", head[12:16])[0])
        return head + f.read()
