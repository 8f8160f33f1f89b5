"""Suggested viewpoints for the next ray of a point: those that most reduce its predicted
uncertainty, not occluded, well spread around it.

Candidates sit on a sphere about the provisional point at the first view's distance, on a
grid of azimuths and elevations in the point's local east/north/up frame (rendered ECEF; a
frame near the geocentre, i.e. a scene not placed on the Earth, takes x, y, z as e, n, u),
each looking at the point (so the point is at its image centre) with up the local up.

Each candidate's predicted covariance is gsgeo.solve's own a-priori model: the point's rays
plus the candidate's ray through the point, solved by :func:`gsgeo.solve.core.solve_core`
with the angular model (sigma_i = sigma_px x ifov_i x range_i), all candidates at once. The
views are chosen greedily: each next one most reduces the trace of the covariance given the
rays and the views already chosen, at least MIN_SEPARATION_DEG from those. A candidate is
occluded when the splats between its camera and the point (gsgeo.aim.depth's profile of its
ray, up to a little before the point) add up to opacity 1/2; occluded candidates are chosen
only when no unoccluded one is left. Where the first ray meets flat splats (a surface with a
normal, gsgeo.aim.depth), views that see that surface at less than MIN_INCIDENCE_DEG come
after all others: the feature is a sliver there, for image matching as for a click.

For a matcher that knows the splats (``shape_views``: POST /api/scenes/{scene}/match),
where the splats about the point do not lie on one plane (an eaves corner, a pole's top,
a post with its rail: their weighted spread's thinnest axis is not much thinner than the
next, :func:`planar_about`), the views are kept within NONPLANAR_MAX_DEG of the first
ray: the matcher (gsgeo.aim.match) warps the click's patch by a plane, which is right about
a corner only for a small change of view, and a corner seen from 90 degrees round shows
other faces than the click's. Intersection at 20-35 degrees still gives the point to a
few times the pixel footprint from one such ray, better from several. Not by default: the
plain patch matcher (POST /api/match) errs in such near views, where the background
behind a corner looks alike and matches instead of it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from gsgeo.aim.camera import Camera
from gsgeo.aim.depth import HIT_OPACITY, depth_hint, ray_profile
from gsgeo.aim.foreground import BALL_PX, Foreground
from gsgeo.aim.splatindex import SplatIndex
from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, enu_rotation
from gsgeo.crs.modelmatrix import apply_points, invert_affine
from gsgeo.solve.core import solve_core
from gsgeo.solve.linalg import FloatArray

#: The candidate grid: azimuths (degrees clockwise from north) and elevations (degrees).
AZIMUTHS_DEG = np.arange(0.0, 360.0, 15.0)
ELEVATIONS_DEG = np.array([10.0, 25.0, 40.0, 55.0, 70.0])
#: Two chosen views are at least this far apart (angle between their rays, degrees).
MIN_SEPARATION_DEG = 20.0
#: Views whose line of sight meets the surface (where its splats are flat) at less than this
#: angle are chosen only when no other is left.
MIN_INCIDENCE_DEG = 20.0
#: Where the splats about the point are not one plane, views lie within this angle of the
#: first ray (degrees); the splats count as one plane when the standard deviation of their
#: centres across their thinnest axis is at most PLANAR_RATIO of that across the next one.
NONPLANAR_MAX_DEG = 35.0
PLANAR_RATIO = 0.15
#: The stretch of a candidate's ray before the point not tested for occlusion: the point's
#: own surface (a share of the range, and at least this many metres).
POINT_CLEARANCE = 0.02
POINT_CLEARANCE_M = 0.05
#: The nearest range a view is put at, metres.
MIN_RANGE_M = 1.0
#: Occlusion tests per call at most; candidates beyond that count as occluded.
MAX_OCCLUSION_TESTS = 48


@dataclass(frozen=True)
class SuggestedView:
    """A viewpoint: its camera (rendered ECEF), range (m), azimuth and elevation from the
    point (degrees, local ENU), the smallest angle to the existing rays (degrees), the
    predicted sigma sqrt(trace C) (m) with this view's ray added, and whether splats hide
    the point from it."""

    camera: Camera
    range_m: float
    azimuth_deg: float
    elevation_deg: float
    min_angle_deg: float
    predicted_sigma_m: float
    occluded: bool

    def to_json(self) -> dict[str, object]:
        return {"camera": self.camera.to_json(), "range_m": self.range_m,
                "azimuth_deg": self.azimuth_deg, "elevation_deg": self.elevation_deg,
                "min_angle_deg": self.min_angle_deg,
                "predicted_sigma_m": self.predicted_sigma_m, "occluded": self.occluded}


def local_axes(point: FloatArray) -> FloatArray:
    """Rows east, north, up at an ECEF point (identity near the geocentre)."""
    p = np.asarray(point, dtype=np.float64)
    if np.linalg.norm(p) < 1e5:
        return np.eye(3)
    lon, lat, _ = ecef_to_geodetic_closed_form(p)
    return np.asarray(enu_rotation(float(lon), float(lat)), dtype=np.float64)


def predicted_traces(origins: FloatArray, directions: FloatArray, ifov: FloatArray,
                     extra_origins: FloatArray, extra_directions: FloatArray, extra_ifov: float,
                     sigma_px: float) -> FloatArray:
    """trace of the a-priori covariance (m^2) of the point of N rays (origins, unit
    directions (N, 3), ifov (N,)) plus, for each of M candidates, one more ray (M, 3)."""
    m = extra_origins.shape[0]
    o = np.concatenate([np.broadcast_to(origins, (m, *origins.shape)), extra_origins[:, None]],
                       axis=1)
    d = np.concatenate([np.broadcast_to(directions, (m, *directions.shape)),
                        extra_directions[:, None]], axis=1)
    f = np.concatenate([np.broadcast_to(ifov, (m, ifov.size)), np.full((m, 1), extra_ifov)],
                       axis=1)
    sol = solve_core(o, d, f, sigma_px)
    tr = np.trace(sol.normal_inverse, axis1=1, axis2=2)
    return np.where(np.isfinite(tr) & (tr > 0), tr, np.inf)


def suggest_views(index: SplatIndex | None, origins: FloatArray, directions: FloatArray,
                  ifov: FloatArray | None, point: FloatArray, k: int, fovy: float,
                  width: float, height: float, sigma_px: float = 1.0,
                  model_matrix: FloatArray | None = None, shape_views: bool = False
                  ) -> list[SuggestedView]:
    """Up to ``k`` views of ``point`` (rendered ECEF), best first (module docstring); with
    ``shape_views`` those of a point whose splats are not one plane lie within
    NONPLANAR_MAX_DEG of the first ray (for a matcher that warps by the splats' shape: the
    plain patch matcher errs there, the background being alike in such near views).

    origins, directions : (N, 3) the point's rays (rendered ECEF); ifov (N,) radians, NaN
    (or None) where unknown: then the new view's own pixel angle. ``model_matrix``: the
    tileset's modelMatrix (4, 4) the rays and point are rendered under (None: identity);
    ``index`` None skips the occlusion test."""
    p = np.asarray(point, dtype=np.float64)
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    f_new = 2.0 * math.tan(fovy / 2.0) / height
    f = np.full(len(o), f_new) if ifov is None else np.asarray(ifov, dtype=np.float64).copy()
    f[~np.isfinite(f)] = f_new
    rng = max(float(np.linalg.norm(p - o[0])), MIN_RANGE_M)
    enu = local_axes(p)
    az, el = np.meshgrid(np.radians(AZIMUTHS_DEG), np.radians(ELEVATIONS_DEG))
    az, el = az.ravel(), el.ravel()
    back_enu = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=1)
    back = back_enu @ enu                                    # point -> camera, unit, ECEF
    cams = p + rng * back
    alone = predicted_traces(o, d, f, cams, -back, f_new, sigma_px)
    angles = np.degrees(np.arccos(np.clip(-back @ d.T, -1.0, 1.0))).min(axis=1)
    if shape_views and index is not None and \
            not planar_about(index, p, BALL_PX * f[0] * rng, model_matrix):
        near_first = np.degrees(np.arccos(np.clip(-back @ d[0], -1.0, 1.0))) \
            <= NONPLANAR_MAX_DEG
        alone = np.where(near_first, alone, np.inf)     # not a candidate
    occlusion = Occlusion(index, p, model_matrix, f_new)
    # a view that sees the surface at grazing incidence (or from behind) comes last: its
    # image of the feature is a sliver, for the matcher as for the operator's click
    normal = surface_at(index, o[0], d[0], f[0], model_matrix)
    grazing = (np.zeros(len(cams), dtype=bool) if normal is None
               else back @ normal < math.sin(math.radians(MIN_INCIDENCE_DEG)))
    chosen: list[int] = []
    chosen_occluded: list[bool] = []
    o_sel, d_sel, f_sel = o, d, f
    remaining = np.isfinite(alone)                 # not chosen, apart from the chosen
    hidden = np.zeros(len(cams), dtype=bool)       # known to be occluded
    tested = np.zeros(len(cams), dtype=bool)
    while len(chosen) < k and remaining.any():
        tr = predicted_traces(o_sel, d_sel, f_sel, cams, -back, f_new, sigma_px)
        ranked = np.lexsort((tr, grazing))
        order = [i for i in ranked.tolist() if remaining[i]]
        pick = first_visible(order, hidden, tested, occlusion, cams)
        pick = order[0] if pick is None else pick      # all occluded: the best of them
        chosen.append(pick)
        chosen_occluded.append(bool(hidden[pick]))
        remaining &= separated(back, [pick])
        remaining[pick] = False
        o_sel = np.vstack([o_sel, cams[pick]])
        d_sel = np.vstack([d_sel, -back[pick]])
        f_sel = np.append(f_sel, f_new)
    out = []
    up = enu[2]
    for i, occluded in zip(chosen, chosen_occluded, strict=True):
        cam = Camera.look_at(cams[i], p, up, fovy, width, height)
        out.append(SuggestedView(cam, rng, float(np.degrees(az[i]) % 360.0),
                                 float(np.degrees(el[i])), float(angles[i]),
                                 float(math.sqrt(alone[i])), occluded))
    return out


def planar_about(index: SplatIndex, point: FloatArray, radius_m: float,
                 model_matrix: FloatArray | None = None) -> bool:
    """Whether the splats whose centres lie within ``radius_m`` (metres) of ``point``
    (rendered ECEF) lie on one plane: the alpha-weighted standard deviation of the centres
    along their thinnest principal axis is at most PLANAR_RATIO of that along the middle one.
    Fewer than 4 splats there count as planar (nothing to tell)."""
    fg = Foreground.near(index, point, radius_m, model_matrix)
    if fg.count < 4:
        return True
    w = fg.alpha / float(fg.alpha.sum())
    c = fg.centres - w @ fg.centres
    lam = np.linalg.eigvalsh((c * w[:, None]).T @ c)               # ascending
    return bool(math.sqrt(max(lam[0], 0.0)) <= PLANAR_RATIO * math.sqrt(max(lam[1], 0.0)))


def surface_at(index: SplatIndex | None, origin: FloatArray, direction: FloatArray,
               ifov: float, model_matrix: FloatArray | None) -> FloatArray | None:
    """The unit normal of the flat splats the first ray meets, facing its origin (rendered
    ECEF); None without an index, where it hits nothing or the splats are not flat."""
    if index is None:
        return None
    hint = depth_hint(index, origin, direction, ifov, model_matrix)
    if not hint.hit or hint.normal is None:
        return None
    n = np.asarray(hint.normal, dtype=np.float64)
    return n / np.linalg.norm(n)


def first_visible(order: list[int], hidden: np.ndarray, tested: np.ndarray,
                  occlusion: Occlusion, cams: FloatArray) -> int | None:
    """The first candidate of ``order`` not occluded, testing those not tested yet (their
    results recorded in ``hidden`` and ``tested``); None when all are occluded."""
    for i in order:
        if not tested[i]:
            hidden[i] = occlusion.hidden(cams[i])
            tested[i] = True
        if not hidden[i]:
            return i
    return None


def separated(back: FloatArray, chosen: list[int]) -> np.ndarray:
    """Candidates at least MIN_SEPARATION_DEG from every chosen one."""
    if not chosen:
        return np.ones(len(back), dtype=bool)
    cos = back @ back[chosen].T
    return np.asarray((cos < math.cos(math.radians(MIN_SEPARATION_DEG))).all(axis=1))


class Occlusion:
    """Whether splats hide a point from camera positions (rendered ECEF)."""

    def __init__(self, index: SplatIndex | None, point: FloatArray,
                 model_matrix: FloatArray | None, ifov: float) -> None:
        self.index = index
        self.ifov = ifov
        self.tests = 0
        self.to_tileset = None if model_matrix is None else invert_affine(
            np.asarray(model_matrix, dtype=np.float64))
        self.point = self.tileset(point)

    def tileset(self, p: FloatArray) -> FloatArray:
        return p if self.to_tileset is None else apply_points(self.to_tileset, p)

    def hidden(self, camera_position: FloatArray) -> bool:
        """True when the splats between the camera and the point add up to opacity 1/2
        (or when the test budget of a call is spent)."""
        if self.index is None:
            return False
        self.tests += 1
        if self.tests > MAX_OCCLUSION_TESTS:
            return True
        c = self.tileset(np.asarray(camera_position, dtype=np.float64))
        v = self.point - c
        dist = float(np.linalg.norm(v))
        clearance = max(POINT_CLEARANCE * dist, POINT_CLEARANCE_M)
        if dist <= clearance:
            return False
        prof = ray_profile(self.index, c, v / dist, self.ifov, t_max=dist - clearance)
        return prof.opacity >= HIT_OPACITY
