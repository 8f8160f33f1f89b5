"""Aiming aids of a scene for the viewer: depth hint along a ray, suggested views, and the
match of a clicked feature in another rendered view (gsgeo.aim). Positions are in rendered
ECEF (metres), as the viewer's rays carry them; each ray's modelMatrix maps to the tileset.
"""

from __future__ import annotations

import struct
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from gsgeo.aim.camera import Camera
from gsgeo.aim.depth import depth_hint
from gsgeo.aim.foreground import foreground_of_click
from gsgeo.aim.images import (
    MAX_MATCH_PIXELS,
    ImageHeader,
    check_budget,
    decode_header,
    image_header,
)
from gsgeo.aim.match import View, match_feature
from gsgeo.aim.snap import snap_click
from gsgeo.aim.splatindex import SplatIndex, scene_index
from gsgeo.aim.views import suggest_views
from gsgeo.crs.modelmatrix import invert_affine, matrix4
from gsgeo.errors import GsgeoError, InputError
from gsgeo.limits import origin_problem
from gsgeo.measure import Rays
from gsgeo.store import ConflictError, NotFoundError


def tileset_of(scene_dir: Path) -> Path:
    """The tileset.json of a scene folder; NotFoundError when it has none."""
    ts = Path(scene_dir) / "tileset.json"
    if not ts.is_file():
        raise NotFoundError(f"scene {Path(scene_dir).name!r} has no tileset.json")
    return ts


def scene_splats(scene_dir: Path) -> SplatIndex:
    """The splats of a scene folder (read once per tileset version); NotFoundError without a
    tileset.json, ConflictError naming the problem when its tiles cannot be read as splats
    (not SPZ splats, truncated or corrupt files)."""
    ts = tileset_of(scene_dir)
    try:
        return scene_index(ts)
    except (GsgeoError, OSError, ValueError, KeyError, TypeError, IndexError, EOFError,
            RecursionError, struct.error, zlib.error) as exc:
        raise ConflictError(f"the splats of scene {Path(scene_dir).name!r} cannot be read: "
                            f"{exc}", field="scene") from None


def depth_on_ray(scene_dir: Path, rays: Rays) -> dict[str, Any]:
    """The depth hint of the first of ``rays`` in the scene (gsgeo.aim.depth.depth_hint), as
    the JSON of POST /api/scenes/{scene}/depth."""
    if len(rays) < 1:
        raise InputError("one ray is needed", field="ray")
    ifov = None if rays.ifov is None else float(rays.ifov[0])
    index = scene_splats(scene_dir)
    hint = depth_hint(index, rays.origins[0], rays.directions[0],
                      ifov if ifov == ifov else None, rays.model_matrix(0))
    return hint.to_json()


def checked_model_matrix(model_matrix: Any) -> np.ndarray | None:
    """A request's ``model_matrix`` (16 numbers, column-major, or None) as a 4 x 4 matrix that
    can be inverted, or None; InputError about ``model_matrix`` otherwise."""
    if model_matrix is None:
        return None
    try:
        mm = matrix4(model_matrix)
        invert_affine(mm)
    except InputError as exc:
        raise exc.at("model_matrix") from None
    return mm


#: Most points one visibility question may name (the labels of one view).
MAX_VISIBILITY_POINTS = 200
#: A point counts as hidden when the splats' surface along the ray to it is nearer than the
#: point by more than this many metres, or this fraction of its distance if more (the depth
#: hint scatters by a few centimetres on a surface, more at grazing rays past an edge).
HIDDEN_MIN_M = 0.25
HIDDEN_FRACTION = 0.02


def visibility(scene_dir: Path, origin: Any, points: Any, model_matrix: Any = None
               ) -> dict[str, Any]:
    """Whether each of ``points`` (rendered ECEF, metres) is seen from ``origin`` (the camera,
    rendered ECEF) in the scene: hidden when the depth hint along the ray to it
    (gsgeo.aim.depth.depth_hint, under ``model_matrix``, 16 numbers column-major or None)
    finds the splats' surface nearer than the point by more than HIDDEN_MIN_M or
    HIDDEN_FRACTION of its distance. The JSON of POST /api/scenes/{scene}/visible:
    {"hidden": [bool], "surface_m": [metres or null], "distance_m": [metres]}. One depth
    query per point (at most MAX_VISIBILITY_POINTS: the labels a view shows)."""
    o = np.asarray(origin, dtype=np.float64).reshape(3)
    pts = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    if not 1 <= len(pts) <= MAX_VISIBILITY_POINTS:
        raise InputError(f"give 1 to {MAX_VISIBILITY_POINTS} points", field="points")
    problem = origin_problem(o)
    if problem is not None:
        raise InputError(problem, field="origin")
    mm = checked_model_matrix(model_matrix)
    dist = np.linalg.norm(pts - o, axis=1)
    if np.any(dist < 1e-3):
        raise InputError(f"point {int(np.argmax(dist < 1e-3))} lies at the origin",
                         field="points")
    index = scene_splats(scene_dir)
    surface: list[float | None] = []
    for p in pts:
        hint = depth_hint(index, o, p - o, None, mm)
        surface.append(hint.depth_m if hint.hit else None)
    tol = np.maximum(HIDDEN_MIN_M, HIDDEN_FRACTION * dist)
    hidden = [s is not None and s < d - t for s, d, t in zip(surface, dist, tol, strict=True)]
    return {"hidden": hidden, "surface_m": surface, "distance_m": dist.tolist()}


def camera_of(doc: dict[str, Any], field: str) -> Camera:
    """The camera of a JSON object (contract: position, direction, up, fovy, width, height);
    InputError names ``<field>.<member>``."""
    return Camera.checked(doc["position"], doc["direction"], doc["up"], float(doc["fovy"]),
                          float(doc["width"]), float(doc["height"]), field)


def view_of(doc: dict[str, Any], field: str, head: ImageHeader | None = None,
            colour: bool = False) -> View:
    """A rendered view of a JSON object (image: base64 PNG/JPEG, origin, camera); ``head``:
    its image's header when already read (gsgeo.aim.images.image_header); its image grey, or
    BGR with ``colour``. The image is decoded only once its size is checked against the
    camera's canvas."""
    origin = np.asarray(doc.get("origin") or [0.0, 0.0], dtype=np.float64)
    head = head or image_header(doc["image"], f"{field}.image")
    camera = camera_of(doc["camera"], f"{field}.camera")
    h, w = head.height, head.width
    # an image in device pixels with a camera in CSS pixels would match nothing: say so
    if origin[0] < -1 or origin[1] < -1 or origin[0] + w > camera.width + 1 \
            or origin[1] + h > camera.height + 1:
        raise InputError(f"is {w}x{h} px at origin ({origin[0]:g}, {origin[1]:g}), beyond the "
                         f"{camera.width:g}x{camera.height:g} canvas of its camera: send the "
                         "view (or a crop of it) in CSS pixels, as the camera", field=f"{field}.image")
    return View(decode_header(head, colour), origin, camera)


def match_views(reference: dict[str, Any], target: dict[str, Any],
                depth: dict[str, Any], scene_dir: Path | None = None,
                model_matrix: Any = None) -> dict[str, Any]:
    """The reference click found in the target view (gsgeo.aim.match.match_feature), as the
    JSON of POST /api/match. ``depth`` holds near_m, far_m and depth_m along the reference
    ray (metres, from /depth) and optionally its normal_ecef; InputError names the field of a
    value that cannot be used. With ``scene_dir`` (POST /api/scenes/{scene}/match) the
    scene's splats about the depth hint's point weight the patches (gsgeo.aim.foreground:
    the background around an object's outline is left out); ``model_matrix`` (16 numbers,
    column-major, the tileset's at the click; None: identity) places them as rendered.
    The two images together may hold MAX_MATCH_PIXELS pixels, read from their headers
    before either is decoded."""
    near, far, hint = (float(depth[k]) for k in ("near_m", "far_m", "depth_m"))
    if not 0.0 <= near <= far:
        raise InputError("near_m must be >= 0 and <= far_m", field="depth.near_m")
    if not near <= hint <= far:
        raise InputError("depth_m must lie between near_m and far_m", field="depth.depth_m")
    normal = depth.get("normal_ecef")
    if normal is not None and not np.linalg.norm(normal) > 1e-9:
        raise InputError("must be a non-zero vector", field="depth.normal_ecef")
    # both headers first: the request's pixel budget is checked before any pixel is decoded
    heads = [image_header(reference["image"], "reference.image"),
             image_header(target["image"], "target.image")]
    check_budget(heads, MAX_MATCH_PIXELS)
    ref = view_of(reference, "reference", heads[0])
    tgt = view_of(target, "target", heads[1])
    del heads
    pixel = np.asarray(reference["pixel"], dtype=np.float64)
    foreground = None
    if scene_dir is not None:
        foreground = foreground_of_click(scene_splats(scene_dir), ref.camera, pixel, hint,
                                         checked_model_matrix(model_matrix))
    return match_feature(ref, pixel, tgt, near, far, hint,
                         None if normal is None else np.asarray(normal, dtype=np.float64),
                         foreground).to_json()


def snap_reference(reference: dict[str, Any]) -> dict[str, Any]:
    """The click of a reference view (image: base64 PNG or JPEG of the view or a crop of it,
    origin, camera, pixel: window coordinates, CSS px) snapped onto the point feature it was
    near (gsgeo.aim.snap: a target's centre, a corner, a dot), as the JSON of POST
    /api/snap: ok, pixel, moved_px, isotropy, reason. The image is budgeted like a match's
    (MAX_MATCH_PIXELS, from its header before decoding); InputError names the field."""
    head = image_header(reference["image"], "reference.image")
    check_budget([head], MAX_MATCH_PIXELS)
    ref = view_of(reference, "reference", head, colour=True)
    pixel = np.asarray(reference["pixel"], dtype=np.float64)
    return snap_click(ref.image, ref.origin, pixel).to_json()


def views_for_point(scene_dir: Path, rays: Rays, point: Any, k: int, fovy: float,
                    width: float, height: float, sigma_px: float = 1.0,
                    shape_views: bool = False) -> dict[str, Any]:
    """Up to ``k`` suggested views of the provisional ``point`` (rendered ECEF) measured by
    ``rays`` in the scene (gsgeo.aim.views.suggest_views), as the JSON of
    POST /api/scenes/{scene}/views. The point is taken to be rendered under the first ray's
    modelMatrix. ``shape_views``: views for the scene's matcher (gsgeo.aim.views)."""
    p = np.asarray(point, dtype=np.float64).reshape(3)
    problem = origin_problem(p)  # a point as far as a camera may be, no farther
    if problem is not None:
        raise InputError(problem, field="point_ecef")
    if np.linalg.norm(p - rays.origins[0]) < 1e-3:
        raise InputError("the point lies at the first ray's origin", field="point_ecef")
    index = scene_splats(scene_dir)
    views = suggest_views(index, rays.origins, rays.directions, rays.ifov, p, k, fovy, width,
                          height, sigma_px, rays.model_matrix(0), shape_views)
    return {"views": [v.to_json() for v in views]}
