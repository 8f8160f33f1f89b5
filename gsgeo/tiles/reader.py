"""Reading SPZ 3D Tiles (ours and others') back into splats in ECEF.

Walks tileset.json (following external tilesets), composes tile transforms, CesiumJS's
Y-up -> Z-up turn of glTF content and the glTF node matrices, decodes every SPZ primitive
and turns its splats into ECEF (EPSG:4978, metres): centres exactly (float64), rotations and
SH coefficients by the rotation part, log-scales by the uniform scale of the transform.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles import spz
from gsgeo.tiles.gltf import Y_UP_TO_Z_UP, parse_glb
from gsgeo.tiles.splats import Splats, matrix_to_quat, quat_multiply, sh_rotation


@dataclass
class TileSplats:
    uri: str
    level: int
    splats: Splats           # in ECEF (or the tile content frame, see iter_tileset)
    to_ecef: np.ndarray      # 4x4 content -> ECEF
    header: dict


def _colmajor(m: list) -> np.ndarray:
    a = np.asarray(m, np.float64)
    if a.shape != (16,):
        raise InputError("a tile transform must have 16 numbers")
    return a.reshape(4, 4).T


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
    """Every SPZ tile of a tileset, its splats in ECEF (frame='ecef') or as stored ('content')."""
    path = Path(path)
    if path.is_dir():
        path = path / "tileset.json"
    try:
        doc = json.loads(path.read_text(encoding="utf-8"))
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg})") from None
    if "root" not in doc:
        raise InputError(f"{path}: not a 3D Tiles tileset (no 'root')")
    yield from _walk(doc["root"], path.parent, np.eye(4), 0, frame)


def _walk(tile: dict, base: Path, parent: np.ndarray, level: int, frame: str):
    m = parent @ _colmajor(tile["transform"]) if "transform" in tile else parent
    contents = ([tile["content"]] if "content" in tile else []) + tile.get("contents", [])
    for c in contents:
        uri = c.get("uri") or c.get("url")
        if not uri:
            continue
        p = base / uri
        if p.suffix.lower() == ".json":
            doc = json.loads(p.read_text(encoding="utf-8"))
            yield from _walk(doc["root"], p.parent, m, level, frame)
            continue
        try:
            data = p.read_bytes()
        except OSError as exc:
            raise InputError(f"{p}: cannot read tile content ({exc.strerror})") from None
        for blob, node_m in parse_glb(data, str(p)):
            s, header = spz.decode(blob)
            to_ecef = m @ Y_UP_TO_Z_UP @ node_m
            if frame == "ecef":
                s = transform_splats(s, to_ecef)
            yield TileSplats(uri, level, s, to_ecef, header)
    for child in tile.get("children", []):
        yield from _walk(child, base, m, level + 1, frame)


def read_tileset(path: str | os.PathLike) -> Splats:
    """All splats of an SPZ tileset, concatenated, in ECEF."""
    parts = [t.splats for t in iter_tileset(path)]
    if not parts:
        raise InputError(f"{path}: the tileset has no SPZ splat content")
    return Splats.concatenate(parts)


def splat_count(path: str | os.PathLike) -> int:
    """Number of splats in a tileset, from the glTF accessor counts (no decoding)."""
    import struct
    path = Path(path)
    if path.is_dir():
        path = path / "tileset.json"
    doc = json.loads(path.read_text(encoding="utf-8"))
    total = 0

    def walk(tile: dict, base: Path) -> None:
        nonlocal total
        contents = ([tile["content"]] if "content" in tile else []) + tile.get("contents", [])
        for c in contents:
            p = base / (c.get("uri") or c.get("url"))
            if p.suffix.lower() == ".json":
                walk(json.loads(p.read_text(encoding="utf-8"))["root"], p.parent)
                continue
            with open(p, "rb") as f:
                head = f.read(20)
                jlen = struct.unpack("<I", head[12:16])[0]
                gltf = json.loads(f.read(jlen))
            for mesh in gltf.get("meshes", []):
                for prim in mesh["primitives"]:
                    if "KHR_gaussian_splatting" in prim.get("extensions", {}):
                        total += int(gltf["accessors"][prim["attributes"]["POSITION"]]["count"])
        for ch in tile.get("children", []):
            walk(ch, base)

    walk(doc["root"], path.parent)
    return total
