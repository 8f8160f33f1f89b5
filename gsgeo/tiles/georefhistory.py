"""A scene's georeference as tileset.json carries it: the root transform and its history.

Georeferencing a scene changes only the root tile's ``transform`` (the tiles are not
rewritten): R_new = S R_old for a similarity S in ECEF. What was there before is kept in the
tileset's top-level ``extras.gsgeo.georef`` so that nothing is lost and every change can be
undone:

    {"version": 2, "georeferenced": true, "kind": "control",
     "frame_covariance": {...} | null,           # the fit's uncertainty (gsgeo.measure.framecov)
     "history": [{"version": 0, "kind": "tiles", "root_transform": [16], "at": "...",
                  "parent": null, "georeferenced": true, "scale": null,
                  "fit": "georef/v0.json"}, ...]}

History entries are append-only; ``version`` is the current one. An undo appends a new entry
restoring the state of the current entry's parent (and taking the parent's own parent, so
repeated undos walk back). A tileset without these extras is version 0 with its own root
transform. Writes are atomic (a temporary file in the same folder, fsync, rename), so a
reader sees the old or the new tileset.json, never a mix; every reader parses one read of
the file (:func:`gsgeo.tiles.tileset.read_tileset_snapshot`), never two.

The history stays compact: what only a report or an undo needs of a version (the fit's
``summary`` and ``frame_covariance``) is in a side file ``georef/v<N>.json`` beside
tileset.json, with who made the change (``by``: user, project, action). That file is written
and synced *before* tileset.json names version N, so a process killed between the two
writes leaves an intent that names nobody's version, and a process killed after the
tileset write leaves the author on record for whoever catches up (:meth:`SceneGeoref.record`).
Tilesets written before this keep their entries' ``summary`` and ``frame_covariance``
inline; they load and undo as they are, and the next change moves them to side files.
Temporary files left by a writer that was killed are removed by the next write.
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
from gsgeo.tiles.tileset import parse_tileset_json, read_tileset_snapshot

#: Within this many degrees of latitude 0, longitude 0 a scene counts as placed at the
#: default origin (not on the Earth).
DEFAULT_ORIGIN_TOLERANCE_DEG = 0.05
#: The folder (beside tileset.json) of the versions' side files.
FIT_DIR = "georef"
#: What a history entry keeps inline; the rest of a version is in its side file.
ENTRY_KEYS = ("version", "kind", "root_transform", "at", "parent", "restores", "georeferenced",
              "scale", "fit")
#: A temporary file whose name names no process is another writer's for this long at most.
STALE_TEMP_S = 600.0


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
    #: half the diagonal of the root bounding volume (metres, root frame); None: unknown
    extent_m: float | None = None

    def root_of(self, version: int) -> np.ndarray | None:
        """The root transform (4, 4) of a past or present version; None if unknown."""
        for h in self.history:
            if h.get("version") == version:
                return matrix4(h["root_transform"])
        return self.root_transform if version == self.version else None

    def entry(self, version: int | None = None) -> dict[str, Any] | None:
        v = self.version if version is None else version
        return next((h for h in self.history if h.get("version") == v), None)

    def record(self, version: int | None = None) -> dict[str, Any]:
        """Everything known of a version (the current one by default): ``summary`` and
        ``frame_covariance`` of its fit (None when it has none) and, when recorded, ``by``
        (user, project, action); inline in a legacy entry, else from its side file.
        InputError when the side file the entry names is missing or unreadable."""
        e = self.entry(version)
        if e is None:
            return {"summary": None, "frame_covariance": None}
        if "fit" not in e:  # a legacy entry: all inline
            return {"summary": e.get("summary"), "frame_covariance": e.get("frame_covariance")}
        side = self.path.parent / str(e["fit"])
        try:
            rec = json.loads(side.read_bytes())
        except (OSError, ValueError) as exc:
            raise InputError(f"{side}: the record of georeference version {e.get('version')} "
                             f"cannot be read ({exc})") from None
        if not isinstance(rec, dict) or rec.get("version") != e.get("version"):
            raise InputError(f"{side}: not the record of georeference version {e.get('version')}")
        return {"summary": None, "frame_covariance": None} | rec


def _dict(value: Any) -> dict[str, Any]:
    """``value`` when it is a JSON object, else a new empty one."""
    return value if isinstance(value, dict) else {}


def _tileset_path(scene: str | os.PathLike[str]) -> Path:
    p = Path(scene)
    return p / "tileset.json" if p.is_dir() else p


def _read(path: Path) -> dict[str, Any]:
    doc = read_tileset_snapshot(path)[0]
    if not isinstance(doc["root"], dict):
        raise InputError(f"{path}: the root tile must be a JSON object")
    return doc


def read_scene_georef(scene: str | os.PathLike[str]) -> SceneGeoref:
    """The georeference of a scene folder (or its tileset.json), from one read of the file."""
    path = _tileset_path(scene)
    return scene_georef_of(path, _read(path))


def scene_georef_from_bytes(path: Path, raw: bytes) -> SceneGeoref:
    """The georeference in ``raw``, the bytes of tileset.json ``path`` read once."""
    return scene_georef_of(path, parse_tileset_json(raw, path))


def scene_georef_of(path: Path, doc: dict[str, Any]) -> SceneGeoref:
    """The georeference in ``doc``, the document of tileset.json ``path`` (already read, so
    that the root transform and the version come from one version of the file)."""
    if not isinstance(doc.get("root"), dict):
        raise InputError(f"{path}: the root tile must be a JSON object")
    root = matrix4(doc["root"].get("transform", np.eye(4).reshape(-1).tolist()))
    extent = root_extent(doc["root"].get("boundingVolume"))
    g = _dict(_dict(doc.get("extras")).get("gsgeo")).get("georef")
    if not isinstance(g, dict) or not isinstance(g.get("history"), list):
        first = {"version": 0, "kind": "tiles", "root_transform": column_major(root),
                 "at": None, "parent": None, "frame_covariance": None, "summary": None}
        return SceneGeoref(path, 0, root, not at_default_origin(root), "tiles", None, [first],
                           extent)
    return SceneGeoref(path, int(g.get("version", 0)), root,
                       bool(g.get("georeferenced", not at_default_origin(root))),
                       str(g.get("kind", "tiles")), g.get("frame_covariance"),
                       list(g["history"]), extent)


def root_extent(volume: Any) -> float | None:
    """Half the diagonal of a root bounding ``box`` (or a ``sphere``'s radius), metres in the
    root frame, measured from the root frame's origin; None for a region or anything else."""
    v = _dict(volume)
    try:
        if isinstance(v.get("box"), list) and len(v["box"]) == 12:
            b = np.asarray(v["box"], dtype=np.float64)
            r = float(np.linalg.norm(b[:3]) + np.linalg.norm(b[3:].reshape(3, 3), axis=1)
                      .dot([1.0, 1.0, 1.0]))
        elif isinstance(v.get("sphere"), list) and len(v["sphere"]) == 4:
            b = np.asarray(v["sphere"], dtype=np.float64)
            r = float(np.linalg.norm(b[:3]) + abs(b[3]))
        else:
            return None
    except (TypeError, ValueError):
        return None
    return r if np.isfinite(r) else None


def initial_extras(root_transform: np.ndarray) -> dict[str, Any]:
    """``extras.gsgeo.georef`` of a freshly tiled scene (version 0)."""
    return {"version": 0, "georeferenced": not at_default_origin(root_transform),
            "kind": "tiles", "frame_covariance": None,
            "history": [{"version": 0, "kind": "tiles",
                         "root_transform": column_major(root_transform), "at": _now(),
                         "parent": None, "frame_covariance": None, "summary": None}]}


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True  # another user's process
    return True


def clean_stale_temps(folder: Path) -> list[Path]:
    """Remove the temporary files (``.tileset.*.tmp``, ``.v*.tmp``) a killed writer left in
    ``folder``: those naming a process that no longer runs, and unnamed ones older than
    :data:`STALE_TEMP_S`. Returns what was removed."""
    gone = []
    now = datetime.now(UTC).timestamp()
    for f in [*folder.glob(".tileset.*.tmp"), *folder.glob(".v*.tmp")]:
        parts = f.name.split(".")
        pid = parts[2] if len(parts) > 3 and parts[2].isdigit() else None
        try:
            stale = (not _alive(int(pid))) if pid is not None else \
                now - f.stat().st_mtime > STALE_TEMP_S
            if stale:
                f.unlink()
                gone.append(f)
        except OSError:
            continue  # gone meanwhile
    return gone


def write_atomic(path: Path, text: str, prefix: str) -> None:
    """``text`` into ``path`` through a temporary file ``<prefix><pid>.*.tmp`` in its folder,
    synced and renamed, the folder synced: a reader sees the old file or the new one."""
    fd, tmp = tempfile.mkstemp(prefix=f"{prefix}{os.getpid()}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
            f.flush()
            os.fsync(f.fileno())
        if path.exists():
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


def _write(path: Path, doc: dict[str, Any]) -> None:
    clean_stale_temps(path.parent)
    write_atomic(path, json.dumps(doc, indent=1), ".tileset.")


def _write_record(path: Path, version: int, record: dict[str, Any]) -> str:
    """Write (and sync) the side file of ``version``; its name relative to tileset.json."""
    folder = path.parent / FIT_DIR
    folder.mkdir(exist_ok=True)
    clean_stale_temps(folder)
    write_atomic(folder / f"v{version}.json", json.dumps({"version": version} | record), ".v")
    return f"{FIT_DIR}/v{version}.json"


def _compact(path: Path, entry: dict[str, Any]) -> dict[str, Any]:
    """A legacy history entry (fit inline) with its fit moved to a side file; others as
    they are."""
    if "fit" in entry or (entry.get("summary") is None and entry.get("frame_covariance") is None):
        return entry
    v = int(entry["version"])
    name = _write_record(path, v, {"summary": entry.get("summary"),
                                   "frame_covariance": entry.get("frame_covariance")})
    out = {k: entry[k] for k in ENTRY_KEYS if k in entry}
    return out | {"scale": (entry.get("summary") or {}).get("scale"), "fit": name}


def _store(path: Path, doc: dict[str, Any], state: SceneGeoref, entry: dict[str, Any],
           root: np.ndarray, georeferenced: bool, frame_cov: dict[str, Any] | None,
           record: dict[str, Any]) -> SceneGeoref:
    """Write the side file of ``entry``'s version (``record``: summary, frame_covariance,
    by) first, then tileset.json naming it."""
    entry = entry | {"fit": _write_record(path, int(entry["version"]), record),
                     "scale": (record.get("summary") or {}).get("scale")}
    history = [_compact(path, h) for h in state.history] + [entry]
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
                     expect_version: int | None = None,
                     by: dict[str, Any] | None = None) -> SceneGeoref:
    """Put the similarity (4, 4, ECEF -> ECEF) in front of the scene's root transform.

    ``expect_version``: refuse (InputError) when the scene has changed since it was read.
    ``by``: who makes the change (user, project, action), kept with the version.
    """
    path = _tileset_path(scene)
    doc = _read(path)
    state = scene_georef_of(path, doc)
    if expect_version is not None and state.version != expect_version:
        raise InputError(f"{path}: the scene's georeference changed meanwhile (version "
                         f"{state.version}, expected {expect_version}); try again")
    s = np.asarray(similarity, dtype=np.float64).reshape(4, 4)
    root = s @ state.root_transform
    entry = {"version": max(int(h.get("version", 0)) for h in state.history) + 1,
             "kind": kind, "root_transform": column_major(root), "at": _now(),
             "parent": state.version, "georeferenced": georeferenced}
    return _store(path, doc, state, entry, root, georeferenced, frame_covariance,
                  {"summary": summary, "frame_covariance": frame_covariance, "by": by,
                   "at": entry["at"]})


def undo(scene: str | os.PathLike[str], *,
         by: dict[str, Any] | None = None) -> tuple[SceneGeoref, np.ndarray]:
    """Restore the state before the current one; returns the new state and the similarity
    (4, 4) that carried the old root to the restored one. InputError when nothing to undo.
    ``by``: who makes the change (user, project, action), kept with the version."""
    path = _tileset_path(scene)
    doc = _read(path)
    state = scene_georef_of(path, doc)
    cur = state.entry()
    parent = None if cur is None else cur.get("parent")
    if parent is None:
        raise InputError(f"{path}: nothing to undo (the scene is as it was tiled)")
    prev = state.entry(int(parent))
    if prev is None:
        raise InputError(f"{path}: the history does not hold version {parent}")
    root = matrix4(prev["root_transform"])
    georeferenced = bool(prev.get("georeferenced", not at_default_origin(root)))
    fit = state.record(int(parent))
    entry = {"version": max(int(h.get("version", 0)) for h in state.history) + 1,
             "kind": "undo", "root_transform": column_major(root), "at": _now(),
             "parent": prev.get("parent"), "restores": int(parent),
             "georeferenced": georeferenced}
    sim = root @ np.linalg.inv(state.root_transform)
    new = _store(path, doc, state, entry, root, georeferenced, fit["frame_covariance"],
                 {"summary": fit["summary"], "frame_covariance": fit["frame_covariance"],
                  "by": by, "at": entry["at"]})
    return new, sim
