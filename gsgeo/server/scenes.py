"""Scenes of a data directory (DATA/scenes/<name>/tileset.json) and their georeference.

The georeference is read from the root tile's transform (column-major 4x4, ECEF metres): its
translation is the scene origin, given as WGS 84 longitude, latitude (degrees) and
ellipsoidal height (metres). Bounds come from the root bounding volume (box, region or
sphere) as a longitude/latitude/height box.
"""

from __future__ import annotations

import threading
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.store.validate import SLUG

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


def list_scenes(data_dir: Path) -> list[dict[str, Any]]:
    root = data_dir / "scenes"
    if not root.is_dir():
        return []
    out = []
    for d in sorted(root.iterdir()):
        if d.is_dir() and SLUG.match(d.name) and (d / "tileset.json").is_file():
            out.append(scene_info(d))
    return out
