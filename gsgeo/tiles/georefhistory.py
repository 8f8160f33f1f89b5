"""A scene's georeference as tileset.json carries it: the root transform and its history.

Georeferencing a scene changes only the root tile's ``transform`` (the tiles are not
rewritten): R_new = S R_old for a similarity S in ECEF. What was there before is kept in the
tileset's top-level ``extras.gsgeo.georef`` so that nothing is lost and every change can be
undone:

    {"version": 2, "georeferenced": true, "kind": "control",
     "frame_covariance": {...} | null,           # the fit's uncertainty (gsgeo.measure.framecov)
     "history": [{"version": 0, "kind": "tiles", "root_transform": [16], "at": "...",
                  "parent": null, "frame_covariance": null, "summary": null}, ...]}

History entries are append-only; ``version`` is the current one. An undo appends a new entry
restoring the state of the current entry's parent (and taking the parent's own parent, so
repeated undos walk back). A tileset without these extras is version 0 with its own root
transform. Writes are atomic (a temporary file in the same folder, fsync, rename), so a
reader sees the old or the new tileset.json, never a mix.
"""

from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form
from gsgeo.crs.modelmatrix import column_major, matrix4
from gsgeo.errors import InputError
from gsgeo.tiles.tileset import read_tileset_json

#: Within this many degrees of latitude 0, longitude 0 a scene counts as placed at the
#: default origin (not on the Earth).
DEFAULT_ORIGIN_TOLERANCE_DEG = 0.05


def _now() -> str:
    return datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def at_default_origin(root_transform: np.ndarray) -> bool:
    """Whether a root transform puts the scene's origin at (or near) lat 0, lon 0."""
    t = np.asarray(root_transform, dtype=np.float64)[:3, 3]
    if np.linalg.norm(t) < 1e6:
        return True  # not geocentric at all
    lon, lat, _ = ecef_to_geodetic_closed_form(t)
    return bool(abs(float(lon)) < DEFAULT_ORIGIN_TOLERANCE_DEG
                and abs(float(lat)) < DEFAULT_ORIGIN_TOLERANCE_DEG)


@dataclass
class SceneGeoref:
    """The georeference of one scene (see the module docstring)."""

    path: Path  # the tileset.json
    version: int
    root_transform: np.ndarray  # (4, 4)
    georeferenced: bool
    kind: str
    frame_covariance: dict[str, Any] | None
    history: list[dict[str, Any]] = field(default_factory=list)

    def root_of(self, version: int) -> np.ndarray | None:
        """The root transform (4, 4) of a past or present version; None if unknown."""
        for h in self.history:
            if h.get("version") == version:
                return matrix4(h["root_transform"])
        return self.root_transform if version == self.version else None

    def entry(self, version: int | None = None) -> dict[str, Any] | None:
        v = self.version if version is None else version
        return next((h for h in self.history if h.get("version") == v), None)


def _dict(value: Any) -> dict[str, Any]:
    """``value`` when it is a JSON object, else a new empty one."""
    return value if isinstance(value, dict) else {}


def _tileset_path(scene: str | os.PathLike[str]) -> Path:
    p = Path(scene)
    return p / "tileset.json" if p.is_dir() else p


def _read(path: Path) -> dict[str, Any]:
    doc = read_tileset_json(path)
    if not isinstance(doc["root"], dict):
        raise InputError(f"{path}: the root tile must be a JSON object")
    return doc


def read_scene_georef(scene: str | os.PathLike[str]) -> SceneGeoref:
    """The georeference of a scene folder (or its tileset.json)."""
    path = _tileset_path(scene)
    doc = _read(path)
    root = matrix4(doc["root"].get("transform", np.eye(4).reshape(-1).tolist()))
    g = _dict(_dict(doc.get("extras")).get("gsgeo")).get("georef")
    if not isinstance(g, dict) or not isinstance(g.get("history"), list):
        first = {"version": 0, "kind": "tiles", "root_transform": column_major(root),
                 "at": None, "parent": None, "frame_covariance": None, "summary": None}
        return SceneGeoref(path, 0, root, not at_default_origin(root), "tiles", None, [first])
    return SceneGeoref(path, int(g.get("version", 0)), root,
                       bool(g.get("georeferenced", not at_default_origin(root))),
                       str(g.get("kind", "tiles")), g.get("frame_covariance"),
                       list(g["history"]))


def initial_extras(root_transform: np.ndarray) -> dict[str, Any]:
    """``extras.gsgeo.georef`` of a freshly tiled scene (version 0)."""
    return {"version": 0, "georeferenced": not at_default_origin(root_transform),
            "kind": "tiles", "frame_covariance": None,
            "history": [{"version": 0, "kind": "tiles",
                         "root_transform": column_major(root_transform), "at": _now(),
                         "parent": None, "frame_covariance": None, "summary": None}]}


def _write(path: Path, doc: dict[str, Any]) -> None:
    text = json.dumps(doc, indent=1)
    fd, tmp = tempfile.mkstemp(prefix=".tileset.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(tmp, path.stat().st_mode & 0o777)
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        raise
    dfd = os.open(path.parent, os.O_RDONLY)
    try:
        os.fsync(dfd)
    finally:
        os.close(dfd)


def _store(path: Path, doc: dict[str, Any], state: SceneGeoref, entry: dict[str, Any],
           root: np.ndarray, georeferenced: bool, frame_cov: dict[str, Any] | None) -> SceneGeoref:
    history = list(state.history) + [entry]
    g = {"version": entry["version"], "georeferenced": georeferenced, "kind": entry["kind"],
         "frame_covariance": frame_cov, "history": history}
    doc["root"]["transform"] = column_major(root)
    extras = _dict(doc.get("extras"))
    gs = _dict(extras.get("gsgeo"))
    gs["georef"] = g
    extras["gsgeo"] = gs
    doc["extras"] = extras
    _write(path, doc)
    return SceneGeoref(path, entry["version"], root, georeferenced, entry["kind"], frame_cov,
                       history)


def apply_similarity(scene: str | os.PathLike[str], similarity: np.ndarray, *, kind: str,
                     frame_covariance: dict[str, Any] | None, summary: dict[str, Any] | None,
                     georeferenced: bool = True,
                     expect_version: int | None = None) -> SceneGeoref:
    """Put the similarity (4, 4, ECEF -> ECEF) in front of the scene's root transform.

    ``expect_version``: refuse (InputError) when the scene has changed since it was read.
    """
    path = _tileset_path(scene)
    doc = _read(path)
    state = read_scene_georef(path)
    if expect_version is not None and state.version != expect_version:
        raise InputError(f"{path}: the scene's georeference changed meanwhile (version "
                         f"{state.version}, expected {expect_version}); try again")
    s = np.asarray(similarity, dtype=np.float64).reshape(4, 4)
    root = s @ state.root_transform
    entry = {"version": max(int(h.get("version", 0)) for h in state.history) + 1,
             "kind": kind, "root_transform": column_major(root), "at": _now(),
             "parent": state.version, "frame_covariance": frame_covariance,
             "summary": summary, "georeferenced": georeferenced}
    return _store(path, doc, state, entry, root, georeferenced, frame_covariance)


def undo(scene: str | os.PathLike[str]) -> tuple[SceneGeoref, np.ndarray]:
    """Restore the state before the current one; returns the new state and the similarity
    (4, 4) that carried the old root to the restored one. InputError when nothing to undo."""
    path = _tileset_path(scene)
    doc = _read(path)
    state = read_scene_georef(path)
    cur = state.entry()
    parent = None if cur is None else cur.get("parent")
    if parent is None:
        raise InputError(f"{path}: nothing to undo (the scene is as it was tiled)")
    prev = state.entry(int(parent))
    if prev is None:
        raise InputError(f"{path}: the history does not hold version {parent}")
    root = matrix4(prev["root_transform"])
    georeferenced = bool(prev.get("georeferenced", not at_default_origin(root)))
    entry = {"version": max(int(h.get("version", 0)) for h in state.history) + 1,
             "kind": "undo", "root_transform": column_major(root), "at": _now(),
             "parent": prev.get("parent"), "restores": int(parent),
             "frame_covariance": prev.get("frame_covariance"), "summary": prev.get("summary"),
             "georeferenced": georeferenced}
    sim = root @ np.linalg.inv(state.root_transform)
    new = _store(path, doc, state, entry, root, georeferenced, prev.get("frame_covariance"))
    return new, sim
