"""Scenes of a data directory (DATA/scenes/<name>/tileset.json) and their georeference.

The georeference is read from the root tile's transform (column-major 4x4, ECEF metres): its
translation is the scene origin, given as WGS 84 longitude, latitude (degrees) and
ellipsoidal height (metres). Bounds come from the root bounding volume (box, region or
sphere) as a longitude/latitude/height box.

A scene is a folder whose real path (links followed) lies inside the real scenes folder
``DATA/scenes``: a linked scene folder pointing elsewhere is neither listed nor served. To keep
tilesets on another disk, make ``DATA/scenes`` itself the link. A scenes folder that is the
data directory or encloses it serves nothing, and the store's own files are never served
whatever the links (``store_file_ids``).
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.store import DB_NAME
from gsgeo.store.validate import SLUG

#: The store file and the files SQLite keeps beside it.
STORE_SUFFIXES = ("", "-wal", "-shm", "-journal")

_cache: dict[Path, tuple[tuple[int, int], dict[str, Any]]] = {}
_cache_lock = threading.Lock()


def _bounds(ts) -> dict[str, float] | None:
    """Longitude/latitude (degrees) and ellipsoidal height (m) box of the root bounding volume."""
    from gsgeo.errors import GsgeoError

    try:
        corners = ts.bounding_box_corners_ecef()
    except (GsgeoError, TypeError, ValueError, KeyError, IndexError):
        return None
    if not np.all(np.isfinite(corners)):
        return None
    b = ts.geodetic_bounds(corners)
    return {"west": b["lon"][0], "south": b["lat"][0], "east": b["lon"][1],
            "north": b["lat"][1], "min_height": b["h"][0], "max_height": b["h"][1]}


def _splat_count(scene_dir: Path) -> int | None:
    """Total number of splats, through the tiles package's tileset reader when available."""
    try:
        from gsgeo.tiles import reader  # type: ignore[attr-defined]
    except ImportError:
        return None
    fn = getattr(reader, "splat_count", None) or getattr(reader, "count_splats", None)
    if fn is None:
        return None
    try:
        return int(fn(scene_dir / "tileset.json"))
    except Exception:  # a scene the reader cannot parse still gets listed
        return None


def scene_info(scene_dir: Path) -> dict[str, Any]:
    """Name, URL, origin (lon/lat/h), bounds and splat count of one scene directory."""
    ts = scene_dir / "tileset.json"
    st = ts.stat()
    key = (st.st_mtime_ns, st.st_size)
    with _cache_lock:
        hit = _cache.get(ts)
    if hit and hit[0] == key:
        return hit[1]
    info: dict[str, Any] = {"name": scene_dir.name,
                            "url": f"/scenes/{scene_dir.name}/tileset.json",
                            "origin": None, "bounds": None, "splat_count": None,
                            "transform": None, "error": None}
    from gsgeo.crs.frames import ecef_to_geodetic
    from gsgeo.crs.tileset import Tileset
    from gsgeo.errors import GsgeoError

    try:
        tileset = Tileset(ts)
        m = tileset.root_transform
        info["transform"] = m.T.reshape(-1).tolist()  # column-major, as in tileset.json
        t = m[:3, 3]
        if np.linalg.norm(t) > 1e6:  # a geocentric translation: the scene is georeferenced
            lon, lat, h = ecef_to_geodetic(t)
            info["origin"] = {"lon": float(lon), "lat": float(lat), "height": float(h)}
        info["bounds"] = _bounds(tileset)
        info["splat_count"] = _splat_count(scene_dir)
    except (GsgeoError, OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
        info["error"] = f"tileset.json cannot be read: {exc}"
    with _cache_lock:
        _cache[ts] = (key, info)
    return info


def scenes_root(data_dir: Path) -> Path | None:
    """The real path of ``DATA/scenes``, or None when it is missing or is (or encloses) the
    data directory, which holds the project store."""
    try:
        root = (data_dir / "scenes").resolve(strict=True)
        data = data_dir.resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    if not root.is_dir() or data.is_relative_to(root):
        return None
    return root


def scene_dir(data_dir: Path, name: str) -> Path | None:
    """The real folder of scene ``name``, or None unless ``name`` is a scene name and the
    folder, links followed, lies strictly inside the real scenes folder."""
    root = scenes_root(data_dir)
    if root is None or not SLUG.match(name):
        return None
    try:
        path = (root / name).resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    if path == root or not path.is_relative_to(root) or not path.is_dir():
        return None
    return path


def store_file_ids(data_dir: Path) -> set[tuple[int, int]]:
    """(device, inode) of the store's files as they are now: never served, whatever the
    path or link that reaches them (hard links included)."""
    ids = set()
    for suffix in STORE_SUFFIXES:
        try:
            st = os.stat(data_dir / f"{DB_NAME}{suffix}")
        except OSError:
            continue
        ids.add((st.st_dev, st.st_ino))
    return ids


def _scene_dirs(data_dir: Path) -> Iterator[Path]:
    root = data_dir / "scenes"
    if scenes_root(data_dir) is None:
        return
    for d in sorted(root.iterdir()):
        if scene_dir(data_dir, d.name) is not None and (d / "tileset.json").is_file():
            yield d


def list_scenes(data_dir: Path) -> list[dict[str, Any]]:
    """Every servable scene of the data directory with its georeference (``scene_info``)."""
    return [scene_info(d) for d in _scene_dirs(data_dir)]
