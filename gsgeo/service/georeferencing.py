"""Scene georeference for the project service: ray provenance, the fit from a project, apply.

A project's points are measured in its scene's frame, which a georeference change moves
(gsgeo.tiles.georefhistory). Each stored point keeps the frame its rays were taken under
(``PointRecord.frame``: version and root transform); measuring maps its rays from that frame
into the scene's current one, R_now R_then^-1 (a similarity, so ifov stays valid), and adds
the current georeference's own uncertainty (gsgeo.measure.framecov). Rays themselves are never
rewritten: nothing measured is lost, and an undo brings every point back exactly.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gsgeo.crs.modelmatrix import column_major, matrix4
from gsgeo.errors import GsgeoError, InputError
from gsgeo.georef.fit import Measured, Reference
from gsgeo.jsontypes import JSONObject
from gsgeo.measure import Rays
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.solve.linalg import FloatArray
from gsgeo.store.records import CheckPointRecord, ConflictError, PointRecord
from gsgeo.tiles.georefhistory import SceneGeoref, scene_georef_from_bytes, scene_georef_of
from gsgeo.tiles.tileset import read_tileset_snapshot

_lock = threading.Lock()
_cache: dict[Path, tuple[tuple[int, int, int], SceneGeoref]] = {}


@dataclass(frozen=True)
class SceneFrame:
    """The scene frame points are measured in now: version, root transform (4, 4) and the
    georeference's uncertainty (None: taken as exact)."""

    version: int
    root: FloatArray
    frame: FrameCovariance | None
    state: SceneGeoref


def scene_path(data_dir: Path | None, scene: str | None) -> Path | None:
    """DATA/scenes/SCENE/tileset.json when both are known and it exists, else None."""
    if data_dir is None or not scene:
        return None
    path = Path(data_dir) / "scenes" / scene / "tileset.json"
    return path if path.is_file() else None


def scene_frame(data_dir: Path | None, scene: str | None) -> SceneFrame | None:
    """The current frame of a project's scene (cached on the file's identity: inode,
    modification time and size, taken from the very read the frame is parsed from)."""
    path = scene_path(data_dir, scene)
    if path is None:
        return None
    try:
        st = path.stat()
    except OSError:
        return None
    key = (st.st_ino, st.st_mtime_ns, st.st_size)
    with _lock:
        hit = _cache.get(path)
    if hit is not None and hit[0] == key:
        state = hit[1]
    else:
        doc, key = read_tileset_snapshot(path)
        state = scene_georef_of(path, doc)
        with _lock:
            _cache[path] = (key, state)
    return frame_of(state)


def frame_of(state: SceneGeoref) -> SceneFrame:
    """The scene frame of a georeference state."""
    frame = None if state.frame_covariance is None else \
        FrameCovariance.from_json(state.frame_covariance)
    return SceneFrame(state.version, state.root_transform, frame, state)


def scene_frame_and_bytes(path: Path) -> tuple[SceneFrame, bytes]:
    """The scene frame of tileset.json ``path`` and the bytes it was read from (one read:
    what a change puts back on failure is what its frame was taken from)."""
    raw = path.read_bytes()
    return frame_of(scene_georef_from_bytes(path, raw)), raw


def frame_record(ctx: SceneFrame | None, version: int | None = None) -> JSONObject | None:
    """What a new point stores as its rays' frame: the scene's current version, or the
    ``version`` the client says it took the rays under (InputError if the scene never had
    it)."""
    if ctx is None:
        if version not in (None, 0):
            raise InputError(f"the project has no scene with georeference version {version}",
                             field="georef_version")
        return None
    v = ctx.version if version is None else int(version)
    root = ctx.state.root_of(v)
    if root is None:
        raise InputError(f"the scene has no georeference version {v} (now {ctx.version})",
                         field="georef_version")
    return {"version": v, "root_transform": column_major(root)}


#: A point farther than this many scene extents (plus MARGIN_M) from the scene's centre in
#: the frame its rays are said to be of, yet within the scene in another version's frame,
#: was taken under that other version.
EXTENTS = 3.0
MARGIN_M = 100.0


def check_stated_frame(ctx: SceneFrame | None, stated: int | None,
                       point_ecef: FloatArray | None) -> None:
    """Refuse (ConflictError about ``georef_version``) a point whose rays, said to be taken
    under georeference version ``stated``, put it outside the scene while another version
    of the scene's frame puts it inside: the client built its rays from another version
    than it states (e.g. a transform and a version read from two files). ``point_ecef``:
    the point as measured now (the scene's current frame). Nothing is said where it cannot
    be told (no scene, no bounds, no point, the point outside the scene in every frame)."""
    if ctx is None or stated is None or point_ecef is None or ctx.state.extent_m is None:
        return
    then = ctx.state.root_of(int(stated))
    if then is None:
        return
    limit = EXTENTS * ctx.state.extent_m + MARGIN_M
    y = np.append(np.asarray(point_ecef, dtype=np.float64), 1.0)
    y_stated = then @ np.linalg.solve(ctx.root, y)  # the point in the stated version's frame

    def off(root: FloatArray) -> float:
        return float(np.linalg.norm(np.linalg.solve(root, y_stated)[:3]))

    if off(then) <= limit:
        return
    fits = [int(h["version"]) for h in ctx.state.history
            if isinstance(h.get("version"), int) and off(matrix4(h["root_transform"])) <= limit]
    if fits:
        raise ConflictError(
            f"the rays put the point {off(then):.0f} m from the scene in georeference version "
            f"{stated}, but inside it in version {fits[-1]}: they were taken under version "
            f"{fits[-1]} (the scene is now at version {ctx.version}); state the version the "
            "rays' scene transform came from", field="georef_version")


def carry(frame: JSONObject | None, ctx: SceneFrame | None) -> FloatArray | None:
    """The similarity (4, 4) from the frame a point's rays were taken under into the scene's
    current one; None when they agree or either is unknown."""
    if ctx is None or frame is None:
        return None
    then = matrix4(frame.get("root_transform"))  # type: ignore[arg-type]
    if np.array_equal(then, ctx.root):
        return None
    return ctx.root @ np.linalg.inv(then)


def rays_now(rays: Rays, frame: JSONObject | None, ctx: SceneFrame | None) -> Rays:
    """A point's rays carried from the frame they were taken under into the scene's current
    one (unchanged when the frames agree or either is unknown)."""
    m = carry(frame, ctx)
    return rays if m is None else rays.mapped(m)


def measured_from(points: Sequence[PointRecord]) -> Measured:
    """The solved points' ECEF positions and measurement covariances (current frame)."""
    ok = [q for q in points if q.result is not None and q.result.get("point_ecef") is not None]
    ecef = np.array([q.result["point_ecef"] for q in ok if q.result is not None],
                    dtype=float).reshape(-1, 3)
    cov = np.array([q.result["cov_ecef"] for q in ok if q.result is not None],
                   dtype=float).reshape(-1, 3, 3)
    return Measured([q.id for q in ok], ecef, cov)


def reference_from(cps: Sequence[CheckPointRecord]) -> Reference:
    """Control and check records as the fit takes them."""
    def num(v: float | None) -> float:
        return np.nan if v is None else float(v)

    return Reference(
        ids=[c.id for c in cps],
        xyz=np.array([[c.x, c.y, num(c.z)] for c in cps], dtype=float).reshape(-1, 3),
        crss=[c.crs for c in cps],
        sigma_h=np.array([num(c.sigma_h) for c in cps], dtype=float),
        sigma_v=np.array([num(c.sigma_v) for c in cps], dtype=float),
        roles=[c.role for c in cps])


def restore_on_failure(path: Path, before: bytes, exc: BaseException) -> None:
    """Put tileset.json back as it was when the store could not follow a georeference change
    (the store's transaction is rolled back by the caller)."""
    tmp = path.with_name(f".tileset.{os.getpid()}.restore{threading.get_ident()}.tmp")
    try:
        tmp.write_bytes(before)
        tmp.replace(path)
    except OSError as err:
        raise GsgeoError(f"{path}: the georeference change failed ({exc}) and the previous "
                         f"tileset.json could not be restored ({err})") from exc
