"""The one 3D Tiles reader: walks a tileset.json (following external tilesets) and gives every
tile's computed transform and content, the transform chain from content to ECEF.

A glTF position p of a tile's content lands in ECEF (before the viewer's modelMatrix) at

    tile computed transform x [RTC_CENTER translation] x up-axis turn x node matrices x p

- tile computed transform: the product of the ``transform`` of the root and of every tile on
  the path to the tile (16 numbers, column-major; identity when absent), across external
  tilesets (a content whose uri is a .json tileset: its root becomes a child of the tile);
- ``RTC_CENTER`` (b3dm feature table, 3D Tiles 1.0) or the glTF ``CESIUM_RTC`` extension:
  a translation applied after the glTF's own up-axis conversion;
- up-axis turn: glTF is y-up, 3D Tiles z-up; CesiumJS rotates +90 degrees about x,
  (x, y, z) -> (x, -z, y), unless the tileset declares ``asset.gltfUpAxis`` "Z" (or "X");
- node matrices: glTF ``matrix`` (column-major) or TRS, from the scene's root node down.

The splat reader (:mod:`gsgeo.tiles.reader`) and the server's scene listing use this module.
The viewer's modelMatrix M (recorded with each ray) sits in front of all of this:
rendered = M x georeferenced (:mod:`gsgeo.crs.modelmatrix`). Points transform with the whole
affine matrix, directions with its linear part. ECEF is WGS 84 (EPSG:4978), metres; a tileset
is WGS 84 by definition, so geodetic coordinates use the closed-form ellipsoid formulas and
reading a tileset does not load PROJ.
"""

from __future__ import annotations

import json
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, geodetic_to_ecef_closed_form
from gsgeo.crs.modelmatrix import apply_directions, apply_points, invert_affine, matrix4
from gsgeo.errors import InputError
from gsgeo.tiles.gltf import Y_UP_TO_Z_UP

#: CesiumJS Axis.X_UP_TO_Z_UP: rotation -90 degrees about y.
X_UP_TO_Z_UP = np.array([[0, 0, -1.0, 0], [0, 1.0, 0, 0], [1.0, 0, 0, 0], [0, 0, 0, 1.0]])
#: External tilesets nested deeper than this are refused (a tileset that refers to itself).
MAX_NESTING = 32

__all__ = ["MAX_NESTING", "X_UP_TO_Z_UP", "Y_UP_TO_Z_UP", "GltfContent", "Tile", "Tileset",
           "parse_tileset_json", "read_content", "read_gltf_json", "read_tileset_json",
           "read_tileset_snapshot",
           "up_axis_turn"]


def up_axis_turn(asset: dict) -> np.ndarray:
    """The 4x4 turn of glTF content into the tile's z-up frame for a tileset's ``asset``."""
    up = str(asset.get("gltfUpAxis", "Y")).upper()
    return {"Y": Y_UP_TO_Z_UP, "X": X_UP_TO_Z_UP, "Z": np.eye(4)}.get(up, Y_UP_TO_Z_UP)


@dataclass
class Tile:
    """One tile: its computed transform (tile frame -> ECEF), contents and children."""

    path: str  # e.g. "root/children[0]"
    transform: np.ndarray  # (4, 4) computed transform
    bounding_volume: dict
    content_uri: str | None  # the first non-tileset content, relative to `base`
    children: list[Tile] = field(default_factory=list)
    level: int = 0  # depth in the tile tree (an external tileset's root keeps its parent's)
    base: Path = Path(".")  # directory the content uris are relative to
    content_uris: list[str] = field(default_factory=list)  # every non-tileset content
    gltf_up: np.ndarray | None = None  # up-axis turn of an external tileset; None: the main one

    @property
    def content_paths(self) -> list[Path]:
        return [self.base / u for u in self.content_uris]


@dataclass
class GltfContent:
    """What matters of a glTF / GLB / b3dm for positions: the chain and POSITION bounds."""

    node_matrix: np.ndarray  # (4, 4) product of node matrices from the scene root to the mesh
    rtc_center: np.ndarray | None  # (3,) RTC_CENTER / CESIUM_RTC, or None
    position_min: np.ndarray | None  # (3,) accessor min of POSITION (node frame)
    position_max: np.ndarray | None
    count: int  # number of points / vertices of the first primitive


def _trs(node: dict) -> np.ndarray:
    if "matrix" in node:
        return matrix4(node["matrix"])
    m = np.eye(4)
    t = np.asarray(node.get("translation", [0, 0, 0]), dtype=float)
    x, y, z, w = np.asarray(node.get("rotation", [0, 0, 0, 1]), dtype=float)
    r = np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])
    s = np.asarray(node.get("scale", [1, 1, 1]), dtype=float)
    m[:3, :3] = r * s[None, :]
    m[:3, 3] = t
    return m


def _node_chain(gltf: dict) -> np.ndarray:
    """Product of node matrices from the default scene's root down to the first mesh node."""
    nodes = gltf.get("nodes") or []
    scenes = gltf.get("scenes") or [{"nodes": list(range(len(nodes)))}]
    roots = scenes[gltf.get("scene", 0)].get("nodes", [])

    def walk(idx: int, acc: np.ndarray, depth: int) -> np.ndarray | None:
        if depth > 64:
            raise InputError("glTF node hierarchy is too deep (cycle?)")
        node = nodes[idx]
        m = acc @ _trs(node)
        if "mesh" in node:
            return m
        for c in node.get("children", []):
            found = walk(c, m, depth + 1)
            if found is not None:
                return found
        return None

    for r in roots:
        found = walk(r, np.eye(4), 0)
        if found is not None:
            return found
    return np.eye(4)


def read_gltf_json(data: bytes, name: str = "content") -> tuple[dict, dict | None]:
    """glTF JSON (and a b3dm feature-table JSON, if any) from .glb, .gltf or .b3dm bytes."""
    feature = None
    if data[:4] == b"b3dm":
        if len(data) < 28:
            raise InputError(f"{name}: truncated b3dm header")
        _, _, _, ft_json, ft_bin, bt_json, bt_bin = struct.unpack("<4sIIIIII", data[:28])
        off = 28
        if ft_json:
            feature = json.loads(data[off:off + ft_json].decode("utf-8").rstrip(" \x00"))
        data = data[off + ft_json + ft_bin + bt_json + bt_bin:]
    if data[:4] == b"glTF":
        if len(data) < 20:
            raise InputError(f"{name}: truncated GLB header")
        clen, ctype = struct.unpack("<II", data[12:20])
        if ctype != 0x4E4F534A:
            raise InputError(f"{name}: first GLB chunk is not JSON")
        return json.loads(data[20:20 + clen].decode("utf-8")), feature
    try:
        return json.loads(data.decode("utf-8")), feature
    except (UnicodeDecodeError, json.JSONDecodeError):
        raise InputError(f"{name}: neither GLB, b3dm nor glTF JSON") from None


def read_content(path: str | Path) -> GltfContent:
    """Read only the JSON headers of a tile's content (.glb, .gltf, .b3dm)."""
    p = Path(path)
    with open(p, "rb") as fh:
        head = fh.read(28)
        if head[:4] == b"glTF":
            clen = struct.unpack("<I", head[12:16])[0]
            data = head + fh.read(clen)
        elif head[:4] == b"b3dm":
            data = head + fh.read()
        else:
            data = head + fh.read()
    gltf, feature = read_gltf_json(data, str(p))
    rtc = None
    if feature and "RTC_CENTER" in feature:
        rtc = np.asarray(feature["RTC_CENTER"], dtype=float)
    ext = (gltf.get("extensions") or {}).get("CESIUM_RTC")
    if ext and "center" in ext:
        rtc = np.asarray(ext["center"], dtype=float)
    pmin = pmax = None
    count = 0
    meshes = gltf.get("meshes") or []
    if meshes and meshes[0].get("primitives"):
        prim = meshes[0]["primitives"][0]
        acc_i = prim.get("attributes", {}).get("POSITION")
        if acc_i is not None:
            acc = gltf["accessors"][acc_i]
            count = int(acc.get("count", 0))
            if "min" in acc and "max" in acc:
                pmin = np.asarray(acc["min"], dtype=float)
                pmax = np.asarray(acc["max"], dtype=float)
    return GltfContent(_node_chain(gltf), rtc, pmin, pmax, count)


class Tileset:
    """A tileset.json with every tile's computed transform (3D Tiles 1.0 and 1.1), external
    tilesets followed."""

    def __init__(self, path: str | os.PathLike[str], doc: dict | None = None) -> None:
        """``doc``: the document of ``path`` already read (one read serves several uses)."""
        p = Path(path)
        if p.is_dir():
            p = p / "tileset.json"
        doc = read_tileset_json(p) if doc is None else doc
        self.path = p
        self.doc = doc
        asset = doc.get("asset", {})
        self.version = str(asset.get("version", ""))
        self.gltf_up = up_axis_turn(asset)
        self.root = self._tile(doc["root"], np.eye(4), "root", 0, p.parent, None, (p.resolve(),))

    def _tile(self, t: dict, parent: np.ndarray, where: str, level: int, base: Path,
              up: np.ndarray | None, chain: tuple[Path, ...]) -> Tile:
        if not isinstance(t, dict):
            raise InputError(f"{where}: a tile must be a JSON object")
        m = parent @ matrix4(t["transform"]) if "transform" in t else parent
        # 3D Tiles 1.1 allows several "contents"; positions share the tile's transform.
        contents = ([t["content"]] if t.get("content") else []) + list(t.get("contents") or [])
        given = [c.get("uri") or c.get("url") for c in contents if isinstance(c, dict)]
        uris: list[str] = [u for u in given if u]
        own = [u for u in uris if not u.lower().split("?")[0].endswith(".json")]
        tile = Tile(where, m, t.get("boundingVolume", {}), own[0] if own else None,
                    level=level, base=base, content_uris=own, gltf_up=up)
        for u in uris:
            if u in own:
                continue
            ext = base / u
            if ext.resolve() in chain or len(chain) >= MAX_NESTING:
                raise InputError(f"{ext}: external tilesets refer to each other in a loop")
            doc = read_tileset_json(ext)
            tile.children.append(self._tile(doc["root"], m, f"{where}/{u}", level, ext.parent,
                                            up_axis_turn(doc.get("asset", {})),
                                            chain + (ext.resolve(),)))
        for i, c in enumerate(t.get("children") or []):
            tile.children.append(self._tile(c, m, f"{where}/children[{i}]", level + 1, base, up,
                                            chain))
        return tile

    def tiles(self) -> list[Tile]:
        """Every tile, depth first in document order (external tilesets before children)."""
        out, stack = [], [self.root]
        while stack:
            t = stack.pop()
            out.append(t)
            stack.extend(reversed(t.children))
        return out

    @property
    def root_transform(self) -> np.ndarray:
        return self.root.transform

    def to_ecef(self, points_local: ArrayLike, tile: Tile | None = None) -> np.ndarray:
        """Tileset-local (tile frame, z-up) points (..., 3) -> georeferenced ECEF."""
        return apply_points((tile or self.root).transform, points_local)

    def from_ecef(self, points_ecef: ArrayLike, tile: Tile | None = None) -> np.ndarray:
        """Georeferenced ECEF points (..., 3) -> tileset-local (tile frame)."""
        return apply_points(invert_affine((tile or self.root).transform), points_ecef)

    def directions_to_ecef(self, d_local: ArrayLike, tile: Tile | None = None) -> np.ndarray:
        return apply_directions((tile or self.root).transform, d_local)

    def directions_from_ecef(self, d_ecef: ArrayLike, tile: Tile | None = None) -> np.ndarray:
        return apply_directions(invert_affine((tile or self.root).transform), d_ecef)

    def up_turn(self, tile: Tile) -> np.ndarray:
        """The up-axis turn of a tile's glTF content (its own tileset's gltfUpAxis)."""
        return self.gltf_up if tile.gltf_up is None else tile.gltf_up

    def node_to_ecef(self, tile: Tile, node_matrix: np.ndarray,
                     rtc_center: np.ndarray | None = None) -> np.ndarray:
        """glTF node-frame position -> georeferenced ECEF (4, 4), given the node chain."""
        rtc = np.eye(4)
        if rtc_center is not None:
            rtc[:3, 3] = rtc_center
        return tile.transform @ rtc @ self.up_turn(tile) @ node_matrix

    def content_matrix(self, tile: Tile, content: GltfContent) -> np.ndarray:
        """glTF node-frame position -> georeferenced ECEF (4, 4) for a tile's content."""
        return self.node_to_ecef(tile, content.node_matrix, content.rtc_center)

    def content_bounds_ecef(self) -> np.ndarray:
        """ECEF corners (K * 8, 3) of every content's POSITION min/max box."""
        corners = []
        for t in self.tiles():
            for path in t.content_paths:
                if not path.name.lower().endswith((".glb", ".gltf", ".b3dm")):
                    continue
                c = read_content(path)
                lo, hi = c.position_min, c.position_max   # set together or not at all
                if lo is None or hi is None:
                    continue
                box = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1])
                                for z in (lo[2], hi[2])])
                corners.append(apply_points(self.content_matrix(t, c), box))
        if not corners:
            raise InputError(f"{self.path}: no glTF content with POSITION bounds")
        return np.concatenate(corners)

    def bounding_box_corners_ecef(self, tile: Tile | None = None) -> np.ndarray:
        """ECEF corners (8, 3) of a tile's bounding volume 'box' (or 'region', 'sphere')."""
        t = tile or self.root
        bv = t.bounding_volume
        if "box" in bv:
            b = np.asarray(bv["box"], dtype=float)
            c, ax = b[:3], b[3:].reshape(3, 3)
            local = np.array([c + sx * ax[0] + sy * ax[1] + sz * ax[2]
                              for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            return apply_points(t.transform, local)
        if "sphere" in bv:
            sph = np.asarray(bv["sphere"], dtype=float)
            local = np.array([sph[:3] + sph[3] * np.array([sx, sy, sz])
                              for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            return apply_points(t.transform, local)
        if "region" in bv:
            # radians west, south, east, north and WGS 84 heights (m), by definition
            w, s, e, n, h0, h1 = (float(v) for v in bv["region"])
            lon = np.degrees([w, e]); lat = np.degrees([s, n])  # noqa: E702
            pts = [(lo, la, h) for lo in lon for la in lat for h in (h0, h1)]
            return geodetic_to_ecef_closed_form(*np.array(pts).T)
        raise InputError(f"{t.path}: bounding volume has no box, sphere or region")

    def geodetic_bounds(self, corners_ecef: np.ndarray) -> dict:
        """WGS 84 longitude, latitude (degrees) and ellipsoidal height (m) ranges of ECEF corners."""
        lon, lat, h = ecef_to_geodetic_closed_form(corners_ecef)
        return {"lon": (float(lon.min()), float(lon.max())),
                "lat": (float(lat.min()), float(lat.max())),
                "h": (float(h.min()), float(h.max()))}


def read_tileset_json(p: Path) -> dict:
    """The JSON document of a tileset.json; InputError when missing, unreadable or without
    a root."""
    return read_tileset_snapshot(p)[0]


def read_tileset_snapshot(p: Path) -> tuple[dict, tuple[int, int, int]]:
    """The JSON document of a tileset.json and the identity of the file version it came from
    (inode, modification time in ns, size), both from one open of the file: a tileset
    replaced meanwhile (an atomic rename) gives the old document with the old identity or
    the new with the new, never a mix. InputError as :func:`read_tileset_json`."""
    try:
        with open(p, "rb") as f:
            st = os.fstat(f.fileno())
            raw = f.read()
    except FileNotFoundError:
        raise InputError(f"{p}: no such tileset") from None
    except OSError as exc:
        raise InputError(f"{p}: not a readable tileset.json ({exc})") from None
    return parse_tileset_json(raw, p), (st.st_ino, st.st_mtime_ns, st.st_size)


def parse_tileset_json(raw: bytes, p: Path) -> dict:
    """The JSON document of the bytes of tileset.json ``p``; InputError as
    :func:`read_tileset_json`."""
    try:
        doc = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"{p}: not a readable tileset.json ({exc})") from None
    if not isinstance(doc, dict) or "root" not in doc:
        raise InputError(f"{p}: not a 3D Tiles tileset (no 'root')")
    return doc
