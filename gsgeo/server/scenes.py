"""Scenes of a data directory (DATA/scenes/<name>/tileset.json) and their georeference.

The georeference is read from the root tile's transform (column-major 4x4, ECEF metres): its
translation is the scene origin, given as WGS 84 longitude, latitude (degrees) and
ellipsoidal height (metres). Bounds come from the root bounding volume (box, region or
sphere) as a longitude/latitude/height box.

A scene is a folder whose real path (links followed) lies inside the real scenes folder
``DATA/scenes``: a linked scene folder pointing elsewhere is neither listed nor served. To keep
tilesets on another disk, make ``DATA/scenes`` itself the link. A scenes folder that is the
data directory or encloses it serves nothing, and the store's own files are never served
whatever the links (``SceneFolders.refused``).

A scene's tiles may come from a static host instead (gsgeo.server.scenehosts); its
tileset.json is still read from, and listed by, the data directory.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from gsgeo.server.scenehosts import SceneHosts
from gsgeo.service import DB_NAME
from gsgeo.service.validate import SLUG

if TYPE_CHECKING:
    from gsgeo.tiles.tileset import Tileset

#: The store file and the files SQLite keeps beside it.
STORE_SUFFIXES = ("", "-wal", "-shm", "-journal")

_cache: dict[Path, tuple[tuple[int, int, int], dict[str, Any]]] = {}
_cache_lock = threading.Lock()


def _bounds(ts: Tileset) -> dict[str, float] | None:
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


def _splat_count(tileset: Tileset) -> int | None:
    """Total number of splats of a tileset already read."""
    from gsgeo.tiles.reader import splat_count

    try:
        return splat_count(tileset)
    except Exception:  # a scene the reader cannot parse still gets listed
        return None


def scene_info(scene_dir: Path) -> dict[str, Any]:
    """Name, URL, origin (lon/lat/h), bounds and splat count of one scene directory, all
    from one read of its tileset.json (the transform and ``georef_version`` of one version)."""
    ts = scene_dir / "tileset.json"
    st = ts.stat()
    key = (st.st_ino, st.st_mtime_ns, st.st_size)
    with _cache_lock:
        hit = _cache.get(ts)
    if hit and hit[0] == key:
        return hit[1]
    info: dict[str, Any] = {"name": scene_dir.name,
                            "url": f"/scenes/{scene_dir.name}/tileset.json",
                            "origin": None, "bounds": None, "splat_count": None,
                            "transform": None, "georeferenced": None, "georef_version": None,
                            "error": None}
    from gsgeo.crs.frames import ecef_to_geodetic
    from gsgeo.errors import GsgeoError
    from gsgeo.tiles.georefhistory import scene_georef_of
    from gsgeo.tiles.tileset import Tileset, read_tileset_snapshot

    try:
        doc, key = read_tileset_snapshot(ts)  # the cache key of the version read
        tileset = Tileset(ts, doc)
        m = tileset.root_transform
        info["transform"] = m.T.reshape(-1).tolist()  # column-major, as in tileset.json
        t = m[:3, 3]
        if np.linalg.norm(t) > 1e6:  # a geocentric translation: the scene is georeferenced
            lon, lat, h = ecef_to_geodetic(t)
            info["origin"] = {"lon": float(lon), "lat": float(lat), "height": float(h)}
        state = scene_georef_of(ts, doc)
        info["georeferenced"] = state.georeferenced
        info["georef_version"] = state.version
        info["bounds"] = _bounds(tileset)
        info["splat_count"] = _splat_count(tileset)
    except (GsgeoError, OSError, ValueError, KeyError, TypeError, AttributeError,
            RecursionError) as exc:  # nested beyond the parser's depth
        info["error"] = f"tileset.json cannot be read: {exc}"
    with _cache_lock:
        _cache[ts] = (key, info)
    return info


class SceneFolders:
    """The scene folders of one data directory that may be served (module docstring).

    The data directory's real path is taken once, at first use: the store the server has
    open lives there. Everything else is resolved at each call, so a link changed while the
    server runs is judged as it is now."""

    def __init__(self, data_dir: Path):
        self.data_dir = Path(data_dir)
        self._data_real: str | None = None

    def _data(self) -> str:
        if self._data_real is None:
            self._data_real = os.path.realpath(self.data_dir)
        return self._data_real

    def root(self) -> str | None:
        """The real path of ``DATA/scenes``; None when it is missing or is (or encloses) the
        data directory."""
        try:
            root = os.path.realpath(self.data_dir / "scenes", strict=True)
        except OSError:
            return None
        data = self._data()
        if data == root or data.startswith(root.rstrip("/") + "/"):
            return None
        return root  # a file here makes every scene path fail to resolve

    def folder(self, name: str) -> Path | None:
        """The real folder of scene ``name``; None unless ``name`` is a scene name and the
        folder, links followed, lies strictly inside the real scenes folder."""
        if not SLUG.match(name):
            return None
        root = self.root()
        if root is None:
            return None
        try:
            path = os.path.realpath(os.path.join(root, name), strict=True)
        except OSError:
            return None
        if not path.startswith(root.rstrip("/") + "/"):
            return None
        return Path(path)  # a file, not a folder, serves nothing: nothing resolves inside it

    def refused(self) -> set[tuple[int, int]]:
        """(device, inode) of the store's files as they are now: never served, whatever the
        path or link that reaches them (hard links included)."""
        ids = set()
        for suffix in STORE_SUFFIXES:
            try:
                st = os.stat(self.data_dir / f"{DB_NAME}{suffix}")
            except OSError:
                continue
            ids.add((st.st_dev, st.st_ino))
        return ids

    def scenes(self) -> Iterator[Path]:
        """``DATA/scenes/<name>`` of every servable scene with a tileset.json, by name."""
        if self.root() is None:
            return
        for d in sorted((self.data_dir / "scenes").iterdir()):
            if self.folder(d.name) is not None and (d / "tileset.json").is_file():
                yield d


def list_scenes(data_dir: Path, hosts: SceneHosts | None = None) -> list[dict[str, Any]]:
    """Every servable scene of the data directory with its georeference (``scene_info``) and
    ``tiles_url``: the folder URL its tiles come from (``hosts``), None when from this server."""
    hosts = hosts or SceneHosts()
    return [{**scene_info(d), "tiles_url": hosts.folder(d.name)}
            for d in SceneFolders(data_dir).scenes()]
