"""Scenes of a data directory (DATA/scenes/<name>/tileset.json) and their georeference.

The georeference is read from the root tile's transform (column-major 4x4, ECEF metres): its
translation is the scene origin, given as WGS 84 longitude, latitude (degrees) and
ellipsoidal height (metres). Bounds come from the root bounding volume (box, region or
sphere) as a longitude/latitude/height box.
"""

from __future__ import annotations

import json
import math
import threading
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.store.validate import SLUG

_cache: dict[Path, tuple[tuple[int, int], dict[str, Any]]] = {}
_cache_lock = threading.Lock()


def _matrix(values: Any) -> np.ndarray | None:
    if not isinstance(values, list) or len(values) != 16:
        return None
    try:
        m = np.array(values, dtype=float).reshape(4, 4).T  # column-major -> row-major
    except (TypeError, ValueError):
        return None
    return m if np.all(np.isfinite(m)) else None


def _geodetic(ecef: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    from gsgeo.crs.frames import ecef_to_geodetic

    return ecef_to_geodetic(ecef, "EPSG:4978")


def _bounds(volume: Any, m: np.ndarray) -> dict[str, float] | None:
    if not isinstance(volume, dict):
        return None
    try:
        if "region" in volume:
            w, s, e, n, lo, hi = (float(v) for v in volume["region"])
            return {"west": math.degrees(w), "south": math.degrees(s), "east": math.degrees(e),
                    "north": math.degrees(n), "min_height": lo, "max_height": hi}
        if "box" in volume:
            b = np.array(volume["box"], dtype=float)
            c, axes = b[:3], b[3:].reshape(3, 3)
            signs = np.array([[i, j, k] for i in (-1, 1) for j in (-1, 1) for k in (-1, 1)])
            local = c + signs @ axes
        elif "sphere" in volume:
            c = np.array(volume["sphere"][:3], dtype=float)
            r = float(volume["sphere"][3])
            local = c + r * np.vstack([np.eye(3), -np.eye(3)])
        else:
            return None
    except (TypeError, ValueError, KeyError, IndexError):
        return None
    ecef = local @ m[:3, :3].T + m[:3, 3]
    if not np.all(np.isfinite(ecef)):
        return None
    lon, lat, h = _geodetic(ecef)
    return {"west": float(lon.min()), "south": float(lat.min()), "east": float(lon.max()),
            "north": float(lat.max()), "min_height": float(h.min()), "max_height": float(h.max())}


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
    try:
        doc = json.loads(ts.read_text(encoding="utf-8"))
        root = doc["root"]
        m = _matrix(root.get("transform")) if "transform" in root else np.eye(4)
        if m is None:
            raise ValueError("root.transform is not 16 finite numbers")
        info["transform"] = m.T.reshape(-1).tolist()
        t = m[:3, 3]
        if np.linalg.norm(t) > 1e6:  # a geocentric translation: the scene is georeferenced
            lon, lat, h = _geodetic(t)
            info["origin"] = {"lon": float(lon), "lat": float(lat), "height": float(h)}
        info["bounds"] = _bounds(root.get("boundingVolume"), m)
        info["splat_count"] = _splat_count(scene_dir)
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as exc:
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
