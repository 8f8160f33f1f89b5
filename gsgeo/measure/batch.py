"""Many points measured at once, point by point the same as :func:`gsgeo.measure.point.measure_point`.

Re-solving every stored point after a georeference change must take well under a second for
10 000 points, while the per-point pipeline costs about a millisecond a point (a few dozen
small numpy and PROJ calls each). :func:`measure_batch` runs the same pipeline on arrays:

- points are grouped by ray count, rays kept (after exclusions) and model (angular or
  unweighted); within a group the provisional points, the per-point ENU frames (the
  closed-form rotation of :func:`gsgeo.crs.ellipsoid.enu_rotation` at the origin's PROJ
  latitude and longitude: what ``+proj=topocentric`` evaluates), the intersection
  (:func:`gsgeo.solve.core.solve_core`), the global test and the data snooping of
  :mod:`gsgeo.solve.outliers` (:func:`snoop_many`) run over all points at once, and the
  solution's warnings are worded as :func:`gsgeo.solve.intersect` words them;
- the grid coordinates of all points, and of all camera centres, come from a few
  :func:`gsgeo.crs.grid.to_grid_many` calls. A call chooses its operations at the centroid of
  its points, so points are grouped by which operations' areas of use contain them, and a
  call whose centroid would decide otherwise is split into one call per point. Points outside
  the grid CRS's area of use share a call but take their warnings from a one-point call (the
  warning counts a call's points); a call that fails is halved until the failing points stand
  alone, each with the error its own call raises.

Rays under a viewer modelMatrix are georeferenced by each distinct matrix's inverse (as
:func:`gsgeo.crs.modelmatrix.rendered_to_georeferenced` does). Anything the fast path does not
cover (a singular modelMatrix, ifov on some rays only, fewer than 2 rays or an exclusion
measure_point refuses, parallel rays, a point behind a camera, an unusable ENU origin) goes
through ``measure_point`` itself, so errors and their messages are the same. What may differ:
floats by rounding (coordinates ~1e-9 m; grid covariances by the ~1e-7 relative that their
forward-difference Jacobian already moves when a point moves by one ulp),
``solution.iterations`` (the batch solver reports its group's count) and ``measured_at`` (one
time for the batch).
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from gsgeo import limits
from gsgeo.crs.confidence import ellipse_95, ellipsoid_axes_95
from gsgeo.crs.ellipsoid import enu_rotation
from gsgeo.crs.frames import ecef_to_geodetic
from gsgeo.crs.grid import GridPoint, GridPoints, to_grid_many
from gsgeo.crs.modelmatrix import (
    IDENTITY,
    apply_directions,
    apply_points,
    invert_affine,
    is_similarity,
)
from gsgeo.crs.resolve import SourceCRS, grid_crs
from gsgeo.crs.resolve import source_crs as resolve_source
from gsgeo.crs.transformers import candidates, transformer
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.measure.point import REFERENCE_EXCLUDED, measure_point, measure_points
from gsgeo.measure.rays import Rays, SolveSettings
from gsgeo.measure.schema import Measurement, MeasurementFailure, largest, now_utc
from gsgeo.solve import (
    PARALLEL_LIMIT_DEG,
    WEAK_GEOMETRY_DEG,
    IntersectionResult,
    intersection_angles,
)
from gsgeo.solve.core import CoreSolution, solve_core, unit_directions
from gsgeo.solve.intersection import GLOBAL_TEST_ALPHA
from gsgeo.solve.linalg import FloatArray, sym2_quadratic_inverse, sym3_inverse
from gsgeo.solve.outliers import ALPHA, plane_bases
from gsgeo.solve.sharedaim import (
    AUTO_UNWEIGHTED,
    aim_scales,
    reference_rays,
    shared_aim_covariance,
)
from gsgeo.solve.stats import chi2_2_quantile, chi2_sf, f2_quantile

#: One point to measure: id, code, description, its rays, 0-based indices of excluded rays.
BatchPoint = tuple[str, str, str, Rays, Sequence[int]]
#: measure_point's warning for a modelMatrix that is not a similarity.
DISTORTING_MATRIX = ("a model_matrix is not a rotation with uniform scale: angles between rays "
                     "are distorted, so the angular model (ifov) is only approximate")
#: Condition number of the provisional normal matrix above which its mean origin is used.
PROVISIONAL_MAX_CONDITION = 1e12

__all__ = ["BatchPoint", "measure_batch", "measure_batch_json", "snoop_many"]


def measure_batch(points: Sequence[BatchPoint],
                  settings: SolveSettings) -> list[Measurement | MeasurementFailure]:
    """Measure every (id, code, description, rays, exclude) point with the same settings.

    The result is, point by point, that of ``measure_point(rays, settings, point_id=id,
    code=code, description=description, exclude=exclude)``, a GsgeoError becoming a
    MeasurementFailure; the settings are checked first and a CRS problem of the whole set is
    raised once, as :func:`gsgeo.measure.point.measure_points` does. Metres, m², ECEF on
    ``settings.source_crs`` and the grid CRS's units, as there.
    """
    return cast(list[Measurement | MeasurementFailure], _measure(points, settings, as_json=False))


def measure_batch_json(points: Sequence[BatchPoint],
                       settings: SolveSettings) -> list[JSONObject | MeasurementFailure]:
    """:func:`measure_batch` with each Measurement as its ``to_dict()`` (what a project
    stores), made straight from the batch's arrays: no Measurement objects in between, which
    took as long as the measuring itself when 10 000 stored points are measured again.
    ``measured_at`` and the floats' last bits aside, the same dicts (tests compare them)."""
    return [r.to_dict() if isinstance(r, Measurement) else r
            for r in _measure(points, settings, as_json=True)]


def _measure(points: Sequence[BatchPoint], settings: SolveSettings, *, as_json: bool
             ) -> list[Measurement | JSONObject | MeasurementFailure]:
    measure_points([], settings)  # the same up-front checks of the settings
    results: list[Measurement | JSONObject | GsgeoError | None] = [None] * len(points)
    s_px = _solver_sigma_px(settings.sigma_px)
    groups: dict[tuple[int, int, bool], list[int]] = {}
    keeps: dict[int, np.ndarray] = {}
    slow: list[int] = []
    for i, (_, _, _, rays, exclude) in enumerate(points):
        n = len(rays)
        keep = _keep_mask(exclude, n) if len(exclude) else None
        if s_px is None or n < 2 or (len(exclude) and keep is None):
            slow.append(i)
            continue
        if keep is not None:
            keeps[i] = keep
        # ifov on some rays only is found in the group (measure_point's error)
        n_keep = n if keep is None else int(keep.sum())
        groups.setdefault((n, n_keep, rays.ifov is not None), []).append(i)
    solved: list[_Solved] = []
    for (n, n_keep, angular), members in groups.items():
        assert s_px is not None  # a point is grouped only with a usable sigma_px
        keep = np.ones((len(members), n), dtype=bool)
        for row, i in enumerate(members):
            if i in keeps:
                keep[row] = keeps[i]
        group = _solve_group(points, members, keep, n_keep, angular, s_px, settings)
        slow += group.fallback
        if group.solved is not None:
            solved.append(group.solved)
    if solved:
        _finish(points, _Solved.join(solved), settings, results, as_json)
    for i in slow:
        results[i] = _one(points[i], settings)
    out: list[Measurement | JSONObject | MeasurementFailure] = []
    crs_errors: list[CRSError] = []
    for (pid, *_), res in zip(points, results, strict=True):
        if isinstance(res, (Measurement, dict)):
            out.append(res)
        else:
            if isinstance(res, CRSError):
                crs_errors.append(res)
            out.append(MeasurementFailure(pid, str(res)))
    if crs_errors and len(crs_errors) == len(out) and len({str(e) for e in crs_errors}) == 1:
        raise crs_errors[0]
    return out


def _keep_mask(exclude: Sequence[int], n: int) -> np.ndarray | None:
    """The rays (n,) kept after excluding ``exclude``, or None where measure_point refuses
    the exclusion (an index that is not an int in 0..n-1, or fewer than 2 rays left)."""
    mask = np.ones(n, dtype=bool)
    for k in exclude:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= int(k) < n:
            return None
        mask[int(k)] = False
    return mask if mask.sum() >= 2 else None


def _one(point: BatchPoint, settings: SolveSettings) -> Measurement | GsgeoError:
    """The exact path: measure_point itself, its GsgeoError returned."""
    pid, code, description, rays, exclude = point
    try:
        return measure_point(rays, settings, point_id=pid, code=code, description=description,
                             exclude=exclude)
    except GsgeoError as exc:
        return exc


def _solver_sigma_px(value: float) -> float | None:
    """sigma_px as the solver checks it, or None when the solver would refuse it."""
    try:
        return limits.sigma_px(float(value), minimum=limits.SOLVER_SIGMA_PX_MIN)
    except (GsgeoError, TypeError, ValueError, OverflowError):
        return None


@dataclass
class _Solved:
    """The ENU solutions of many points: arrays over the M points, and per-point ray arrays
    (N differs between ray-count groups) as lists of rows."""

    index: np.ndarray  # (M,) positions in the input
    origin: FloatArray  # (M, 3) ENU origins, ECEF
    rotation: FloatArray  # (M, 3, 3) ECEF -> ENU
    point_enu: FloatArray  # (M, 3)
    cov_enu: FloatArray  # (M, 3, 3)
    sigma0: FloatArray
    max_angle: FloatArray
    condition: FloatArray
    rms: FloatArray
    dof: np.ndarray
    camera_rows: FloatArray  # (sum of N, 3) every point's georeferenced ray origins in turn
    counts: np.ndarray  # (M,) rays of each point
    rays: dict[str, list[np.ndarray]]  # origins, directions, ranges, residuals, flags, ...
    optional: dict[str, list[FloatArray | None]]  # pixel residuals (angular model only)
    before: list[list[str]]  # the measurement's own (a distorting modelMatrix), first
    warnings: list[list[str]]  # the solution's
    notes: list[list[str]]  # the measurement's own (exclusions), after the solution's
    model: list[str]
    iterations: list[int]

    @staticmethod
    def join(parts: list[_Solved]) -> _Solved:
        """The parts' points one after the other."""
        if len(parts) == 1:
            return parts[0]

        def cat(name: str) -> np.ndarray:
            return np.concatenate([getattr(p, name) for p in parts])

        return _Solved(
            cat("index"), cat("origin"), cat("rotation"), cat("point_enu"), cat("cov_enu"),
            cat("sigma0"), cat("max_angle"), cat("condition"), cat("rms"), cat("dof"),
            cat("camera_rows"), cat("counts"),
            {k: [a for p in parts for a in p.rays[k]] for k in parts[0].rays},
            {k: [a for p in parts for a in p.optional[k]] for k in parts[0].optional},
            [w for p in parts for w in p.before], [w for p in parts for w in p.warnings],
            [w for p in parts for w in p.notes],
            [x for p in parts for x in p.model],
            [x for p in parts for x in p.iterations])


class _Group:
    """A ray-count group's outcome: the solved points and those left to measure_point."""

    def __init__(self, solved: _Solved | None, fallback: list[int]) -> None:
        self.solved = solved
        self.fallback = fallback


def _provisional(o: FloatArray, u: FloatArray) -> FloatArray:
    """measure_point's provisional point for M points at once: o (M, N, 3) ECEF, u unit.

    The unweighted least-squares point, centred on the mean origin; the mean origin itself
    where the normal matrix is singular or worse conditioned than PROVISIONAL_MAX_CONDITION.
    """
    c = o.mean(axis=1)
    proj = np.eye(3)[None, None] - u[..., :, None] * u[..., None, :]
    n = proj.sum(axis=1)
    b = np.einsum("mkij,mkj->mi", proj, o - c[:, None])
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        cond = np.linalg.cond(n)
    ok = np.isfinite(cond) & (cond <= PROVISIONAL_MAX_CONDITION)
    out = c.copy()
    if ok.any():
        x = np.linalg.solve(n[ok], b[ok][..., None])[..., 0]
        good = np.all(np.isfinite(x), axis=1)
        rows = np.flatnonzero(ok)[good]
        out[rows] += x[good]
    return out


def _solve_group(points: Sequence[BatchPoint], members: list[int], keep: np.ndarray,
                 n_keep: int, angular: bool, s_px: float, settings: SolveSettings) -> _Group:
    """Intersect a group of points of n rays each, ``keep`` (M, n) with n_keep rays kept in
    every row, in their own ENU frames."""
    idx = np.asarray(members)
    m, n = keep.shape
    # concatenate + reshape: several times faster than np.stack on thousands of small arrays
    o = np.concatenate([points[i][3].origins for i in members]).reshape(m, n, 3)
    d_r = np.concatenate([points[i][3].directions for i in members]).reshape(m, n, 3)
    f = None
    if angular:
        f = np.concatenate([points[i][3].ifov for i in members]).reshape(m, n)
    autos = [points[i][3].auto for i in members]
    au = None if all(a is None for a in autos) else np.concatenate(
        [np.zeros(n, dtype=bool) if a is None else a for a in autos]).reshape(m, n)
    matrices = [points[i][3].model_matrices for i in members]
    o, d, similar, ok = _georeferenced(o, d_r, None if all(x is None for x in matrices) else
                                       np.concatenate([np.full((n, 4, 4), np.nan) if x is None
                                                       else x for x in matrices]).reshape(
                                                           m, n, 4, 4))
    src = resolve_source(settings.source_crs or "EPSG:4978")
    origin = _provisional(_kept(o, keep, n_keep), _kept(d, keep, n_keep))
    ok &= np.all(np.isfinite(origin), axis=1) & (np.linalg.norm(origin, axis=1) >= 1e5)
    if f is not None:  # NaN (ifov on some rays only) fails this too
        ok &= np.all((f >= limits.IFOV_MIN) & (f <= limits.IFOV_MAX), axis=1)
    origin = np.where(ok[:, None], origin, o[:, 0])  # the rows not ok go to measure_point
    lon, lat, _ = ecef_to_geodetic(origin, src.id)
    rot = enu_rotation(lon, lat)
    o_enu = np.einsum("mij,mkj->mki", rot, o - origin[:, None])
    d_enu = np.einsum("mij,mkj->mki", rot, d)
    du, norm = unit_directions(d_enu)
    ok &= np.all((norm >= limits.DIRECTION_MIN) & (norm <= limits.DIRECTION_MAX), axis=1)
    ok &= np.all(np.abs(o_enu) <= limits.MAX_ORIGIN_M / math.sqrt(3), axis=(1, 2))
    max_angle, max_isect = intersection_angles(_kept(du, keep, n_keep))
    ok &= ~(max_isect < PARALLEL_LIMIT_DEG)  # the error and its message: measure_point's
    fallback = idx[~ok].tolist()
    scales = None if f is None else aim_scales(au, (m, n), s_px)
    f_w = f if f is None or scales is None else f * scales  # weights: sigma_px x this x range
    if ok.any():
        sol = solve_core(_kept(o_enu[ok], keep[ok], n_keep), _kept(du[ok], keep[ok], n_keep),
                         None if f_w is None else _kept(f_w[ok], keep[ok], n_keep), s_px)
        front = np.all(sol.ranges > 0, axis=1)  # behind a camera: measure_point's error
        fallback += idx[ok][~front].tolist()
        rows = np.flatnonzero(ok)[front]
    else:
        rows = np.zeros(0, dtype=np.int64)
    if rows.size == 0:
        return _Group(None, fallback)
    if not front.all():
        sol = CoreSolution(sol.points[front], sol.normal_inverse[front],
                           sol.residuals_m[front], sol.ranges[front],
                           None if sol.weights is None else sol.weights[front],
                           None if sol.sigma_m is None else sol.sigma_m[front],
                           sol.vtpv[front], sol.iterations)
    idx, keep, o, d, o_enu, du, origin, rot, similar = (
        a[rows] for a in (idx, keep, o, d, o_enu, du, origin, rot, similar))
    au = None if au is None else au[rows]
    max_angle, max_isect = max_angle[rows], max_isect[rows]
    f = None if f is None else f[rows]
    f_w = None if f_w is None else f_w[rows]
    m = rows.size
    dof = 2 * n_keep - 3
    s0sq = sol.vtpv / dof
    sigma0 = np.sqrt(s0sq)
    warnings: list[list[str]] = [[] for _ in range(m)]
    for k in np.flatnonzero(max_isect < WEAK_GEOMETRY_DEG).tolist():
        warnings[k].append(
            f"weak geometry: the largest intersection angle is {float(max_isect[k]):.2f} degrees "
            f"(below {WEAK_GEOMETRY_DEG:g}); the depth is poorly determined")
    ninv = sol.normal_inverse
    res_px_sol = None
    f_keep = None if f is None else _kept(f, keep, n_keep)
    apriori = ninv
    if au is not None:
        au_keep = _kept(au, keep, n_keep)
        grouped = reference_rays(au_keep)[1]
        if f_w is None:
            for k in np.flatnonzero(grouped).tolist():
                warnings[k].append(AUTO_UNWEIGHTED)
        elif grouped.any():
            apriori = shared_aim_covariance(sol.points, _kept(o_enu, keep, n_keep),
                                            _kept(du, keep, n_keep), _kept(f_w, keep, n_keep),
                                            s_px, np.ones((m, n_keep), dtype=bool), au_keep, ninv)
    if f_keep is None:
        model = "unweighted"
        cov = ninv * s0sq[:, None, None]
    else:
        model = "angular"
        res_px_sol = sol.residuals_m / (f_keep * sol.ranges)
        scaled = _global_test(sol.vtpv, dof)
        cov = apriori.copy()
        cov[scaled] *= s0sq[scaled][:, None, None]
        p_all = np.full(m, np.nan)
        if scaled.any():
            p_all[scaled] = chi2_sf(sol.vtpv[scaled], dof)
        for k in np.flatnonzero(scaled).tolist():
            warnings[k].append(
                f"the aiming scatter is {float(sigma0[k]):.2f} times sigma_px = {s_px:g} px "
                f"(global test p = {float(p_all[k]):.2g}); the covariance is scaled up "
                "accordingly")
    eig = np.linalg.eigvalsh(ninv)
    with np.errstate(divide="ignore", invalid="ignore"):
        condition = np.where(eig[:, 0] > 0, eig[:, -1] / eig[:, 0], math.inf)
    flags, ratios = snoop_many(_kept(o_enu, keep, n_keep), _kept(du, keep, n_keep),
                               sol.weights, sol.sigma_m)
    for k in np.flatnonzero(flags.any(axis=1)).tolist():
        warnings[k].append(  # ray numbers among the kept rays, as intersect sees them
            f"ray(s) {_ray_list(flags[k])} look like outliers (data snooping at 0.1 %); "
            "check the aim or exclude them")
    before: list[list[str]] = [[] if ok_k else [DISTORTING_MATRIX] for ok_k in similar.tolist()]
    notes: list[list[str]] = [[] for _ in range(m)]  # the Measurement's, after the solution's
    for k in np.flatnonzero(~keep.all(axis=1)).tolist():
        notes[k].append(f"ray(s) {_ray_list(np.logical_not(keep[k]))} excluded by request")
        if au is not None and au[k].any() and not keep[k, int(np.argmax(~au[k]))]:
            notes[k].append(REFERENCE_EXCLUDED)
    all_flags = np.zeros((m, n), dtype=bool)
    all_flags[keep] = flags.reshape(-1)
    # residuals of every ray (excluded ones too) from the solved point, as measure_point has
    rel = sol.points[:, None, :] - o_enu
    t = np.einsum("mki,mki->mk", rel, du)
    off = rel - du * t[..., None]
    res_m = np.sqrt(np.einsum("mki,mki->mk", off, off))
    res_px = None
    if f is not None:
        with np.errstate(invalid="ignore", divide="ignore"):
            res_px = res_m / (f * np.where(t > 0, t, np.nan))
    rays = {"origins": list(o), "directions": list(d), "sol_res_m": list(sol.residuals_m),
            "ranges": list(sol.ranges), "sol_flags": list(flags), "flags": list(all_flags),
            "ratios": list(ratios), "res_m": list(res_m),
            "excluded": list(np.logical_not(keep))}
    optional = {"sol_res_px": _rows(res_px_sol, m), "res_px": _rows(res_px, m)}
    rms = np.sqrt(np.mean(sol.residuals_m**2, axis=1))
    return _Group(_Solved(idx, origin, rot, sol.points, cov, sigma0, max_angle, condition, rms,
                          np.full(m, dof), o.reshape(-1, 3), np.full(m, n), rays, optional,
                          before, warnings, notes, [model] * m, [sol.iterations] * m), fallback)


def _georeferenced(o: FloatArray, d: FloatArray, matrices: FloatArray | None
                   ) -> tuple[FloatArray, FloatArray, np.ndarray, np.ndarray]:
    """:func:`gsgeo.crs.modelmatrix.rendered_to_georeferenced` for M points of N rays.

    o, d (M, N, 3) rendered ECEF; matrices (M, N, 4, 4), NaN where a ray has none, or None.
    Returns georeferenced origins and unit directions, whether each point's matrices are all
    similarities, and whether the point is fit for the fast path (its matrices invertible,
    its origins and directions usable afterwards; otherwise measure_point reports it).
    Each distinct matrix is inverted once.
    """
    m = o.shape[0]
    go = o.copy()
    gd = d / np.linalg.norm(d, axis=2, keepdims=True)
    similar = np.ones(m, dtype=bool)
    ok = np.ones(m, dtype=bool)
    if matrices is None:
        return go, gd, similar, ok
    has = ~np.all(np.isnan(matrices), axis=(2, 3))
    pr, kr = np.nonzero(has)
    if pr.size == 0:
        return go, gd, similar, ok
    flat = matrices[pr, kr].reshape(-1, 16)
    if np.all(flat == flat[0]):  # the usual case: one modelMatrix for the whole scene
        distinct, which = flat[:1], np.zeros(flat.shape[0], dtype=np.int64)
    else:
        distinct, which = np.unique(flat, axis=0, return_inverse=True)
        which = which.reshape(-1)
    inverses = np.zeros((distinct.shape[0], 4, 4))
    moves = np.zeros(distinct.shape[0], dtype=bool)  # not the identity: the ray is mapped
    singular = np.zeros(distinct.shape[0], dtype=bool)
    similarity = np.ones(distinct.shape[0], dtype=bool)
    for u, row in enumerate(distinct):  # a handful of matrices, not one per point
        mat = row.reshape(4, 4)
        if np.array_equal(mat, IDENTITY):
            continue
        moves[u] = True
        try:
            inverses[u] = invert_affine(mat)
        except InputError:
            singular[u] = True
            continue
        similarity[u] = is_similarity(mat)
    ok[pr[singular[which]]] = False
    similar[pr[moves[which] & ~singular[which] & ~similarity[which]]] = False
    for u in np.flatnonzero(moves & ~singular).tolist():  # the same arithmetic as per point
        p_u, k_u = pr[which == u], kr[which == u]
        go[p_u, k_u] = apply_points(inverses[u], o[p_u, k_u])
        gd[p_u, k_u] = apply_directions(inverses[u], d[p_u, k_u])
    with np.errstate(invalid="ignore", over="ignore"):
        ok &= np.all(np.isfinite(go), axis=(1, 2)) & np.all(np.isfinite(gd), axis=(1, 2))
        ok &= np.all(np.linalg.norm(go, axis=2) <= limits.MAX_ORIGIN_M, axis=1)
    return go, gd, similar, ok


def _kept(a: np.ndarray, keep: np.ndarray, n_keep: int) -> np.ndarray:
    """The kept rays' rows of a per-ray array a (M, N, ...), as (M, n_keep, ...)."""
    if n_keep == keep.shape[1]:
        return a
    return a[keep].reshape((a.shape[0], n_keep) + a.shape[2:])


def _rows(a: FloatArray | None, m: int) -> list[FloatArray | None]:
    """The rows of an (M, N) array, or M times None."""
    return [None] * m if a is None else list(a)


def _global_test(vtpv: FloatArray, dof: int) -> np.ndarray:
    """Points whose angular-model global test rejects sigma0 = 1 (p < GLOBAL_TEST_ALPHA).

    chi2_sf is evaluated only above a bound below which p is surely larger than the level;
    the decision itself is the per-point test's, p < GLOBAL_TEST_ALPHA.
    """
    lo, hi = 0.0, float(dof)
    while float(chi2_sf(hi, dof)) > 2 * GLOBAL_TEST_ALPHA:
        lo, hi = hi, 2 * hi
    for _ in range(40):  # the largest x found with p(x) > 2 alpha: a safe lower bound
        mid = 0.5 * (lo + hi)
        if float(chi2_sf(mid, dof)) > 2 * GLOBAL_TEST_ALPHA:
            lo = mid
        else:
            hi = mid
    out = np.zeros(vtpv.shape, dtype=bool)
    cand = np.flatnonzero(~(vtpv <= lo))
    if cand.size:
        out[cand] = chi2_sf(vtpv[cand], dof) < GLOBAL_TEST_ALPHA
    return out


def _ray_list(mask: np.ndarray) -> str:
    """1-based ray numbers of a mask, as a surveyor counts them."""
    return ", ".join(str(i + 1) for i in np.flatnonzero(mask))


def _leave_one_out_many(o: FloatArray, d: FloatArray, w: FloatArray, sigma: FloatArray | None,
                        active: np.ndarray) -> FloatArray:
    """Each active ray's snooping statistic over its critical value, M points at once.

    o (M, N, 3) centred origins, d unit directions, w (M, N) weights, sigma (M, N) a-priori
    ray sigmas (angular model) or None (unweighted), active (M, N) the rays still in the test.
    """
    n_rays = d.shape[1]
    eye2 = np.eye(2)
    proj = np.eye(3)[None, None] - d[..., :, None] * d[..., None, :]
    wp = proj * (w * active)[..., None, None]
    n_full = wp.sum(axis=1)
    b_full = np.einsum("mkij,mkj->mi", wp, o)
    n_loo = n_full[:, None] - wp
    b_loo = b_full[:, None] - np.einsum("mkij,mkj->mki", wp, o)
    q_loo, det = sym3_inverse(n_loo)
    x_loo = np.einsum("mkij,mkj->mki", q_loo, b_loo)
    basis = plane_bases(d)
    e = np.einsum("mkai,mki->mka", basis, x_loo - o)
    bqb = np.einsum("mkai,mkij,mkbj->mkab", basis, q_loo, basis)
    if sigma is not None:
        c = bqb + (sigma * sigma)[..., None, None] * eye2
        ratio = sym2_quadratic_inverse(c, e) / chi2_2_quantile(1.0 - ALPHA)
    else:
        rel = x_loo[:, :, None, :] - o[:, None, :, :]  # (m, i, k, 3)
        along = np.einsum("mikj,mkj->mik", rel, d)
        off = rel - along[..., None] * d[:, None]
        r2 = np.einsum("mikj,mikj->mik", off, off) * active[:, None, :]
        r2[:, np.arange(n_rays), np.arange(n_rays)] = 0.0
        dof_loo = 2 * (active.sum(axis=1) - 1) - 3
        s2 = r2.sum(axis=2) / dof_loo[:, None]
        with np.errstate(divide="ignore", invalid="ignore"):
            stat = sym2_quadratic_inverse(bqb + eye2, e) / (2.0 * s2)
        ratio = stat / np.asarray(f2_quantile(1.0 - ALPHA, dof_loo))[:, None]
    scale = np.abs(n_full).max(axis=(1, 2))
    singular = ~(np.abs(det) > 1e-12 * scale[:, None] ** 3)
    return np.where(active & ~singular & np.isfinite(ratio), ratio, np.nan)


def snoop_many(origins: FloatArray, directions_unit: FloatArray, weights: FloatArray | None,
               sigma_m: FloatArray | None) -> tuple[np.ndarray, FloatArray]:
    """:func:`gsgeo.solve.outliers.snoop` for M points of N rays at once (no loop over points).

    origins, directions_unit (M, N, 3) in one Cartesian frame per point (metres), weights and
    sigma_m (M, N) or None. Returns the flags (M, N) and the first pass's test ratios (M, N).
    """
    m, n_rays = directions_unit.shape[:2]
    flags = np.zeros((m, n_rays), dtype=bool)
    ratios = np.full((m, n_rays), np.nan)
    if n_rays < 3 or m == 0:
        return flags, ratios
    o = origins - origins.mean(axis=1, keepdims=True)
    w = np.ones((m, n_rays)) if weights is None else weights
    active = np.ones((m, n_rays), dtype=bool)
    run = np.arange(m)
    first = True
    while run.size:
        ratio = _leave_one_out_many(o[run], directions_unit[run], w[run],
                                    None if sigma_m is None else sigma_m[run], active[run])
        if first:
            ratios = ratio.copy()
            first = False
        significant = np.any(ratio > 1.0, axis=1)
        run, ratio = run[significant], ratio[significant]
        worst = np.where(np.isnan(ratio), -np.inf, ratio).argmax(axis=1)
        flags[run, worst] = True
        active[run, worst] = False
        run = run[active[run].sum(axis=1) >= 3]
    return flags, ratios


def _finish(points: Sequence[BatchPoint], s: _Solved, settings: SolveSettings,
            results: list[Measurement | JSONObject | GsgeoError | None], as_json: bool) -> None:
    """ENU -> ECEF -> grid for the solved points, and their Measurements (or, ``as_json``,
    those Measurements' to_dict()) into ``results``."""
    src = resolve_source(settings.source_crs or "EPSG:4978")
    m = s.index.shape[0]
    rt = np.swapaxes(s.rotation, 1, 2)
    point_ecef = np.einsum("mij,mj->mi", rt, s.point_enu) + s.origin
    cov_ecef = rt @ s.cov_enu @ s.rotation
    frame_cov = None if settings.frame is None else settings.frame.point_covariances(point_ecef)
    cov_total = cov_ecef if frame_cov is None else cov_ecef + frame_cov
    grid: list[GridPoint | GsgeoError | None] = [None] * m
    sigma_meas: list[FloatArray | None] = [None] * m
    origins_grid: list[FloatArray | None] = [None] * m
    if settings.crs:
        gl = _grid_many(point_ecef, cov_total, np.ones(m, dtype=np.int64), settings, src,
                        per_point_warnings=True)
        og = _grid_many(s.camera_rows, None, s.counts, settings, src,
                        per_point_warnings=False)
        origins_grid = og.row_blocks()
        if as_json:
            _finish_json(points, s, src.id, point_ecef, cov_ecef, frame_cov, cov_total,
                         gl.grid_rows(frame_cov), origins_grid, None, results)
            return
        grid, sigma_meas = gl.grid_points(frame_cov)
        lon = np.array([np.nan if not isinstance(g, GridPoint) else g.lon for g in grid])
        lat = np.array([np.nan if not isinstance(g, GridPoint) else g.lat for g in grid])
        h84 = np.array([np.nan if not isinstance(g, GridPoint) else g.h_wgs84 for g in grid])
    else:
        t84 = transformer(src.id, "EPSG:4979")
        x, y, z = t84.transform(point_ecef[:, 0], point_ecef[:, 1], point_ecef[:, 2],
                                errcheck=False)
        lon, lat, h84 = np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)
        if as_json:
            _finish_json(points, s, src.id, point_ecef, cov_ecef, frame_cov, cov_total,
                         [None] * m, origins_grid, (lon, lat, h84), results)
            return
    measured_at = now_utc()
    lons, lats, hs = lon.tolist(), lat.tolist(), h84.tolist()
    sigma0, max_angle = s.sigma0.tolist(), s.max_angle.tolist()
    condition, rms, dof = s.condition.tolist(), s.rms.tolist(), s.dof.tolist()
    r = s.rays
    for k, i in enumerate(s.index.tolist()):
        g = grid[k]
        if isinstance(g, GsgeoError):
            results[i] = g
            continue
        pid, code, description, rays, _ = points[i]
        sol = IntersectionResult(
            point=s.point_enu[k], covariance=s.cov_enu[k], sigma0=sigma0[k], dof=dof[k],
            residuals_m=r["sol_res_m"][k], residuals_px=s.optional["sol_res_px"][k], rms_m=rms[k],
            max_angle_deg=max_angle[k], condition=condition[k], outliers=r["sol_flags"][k],
            warnings=s.warnings[k], ranges_m=r["ranges"][k], outlier_ratio=r["ratios"][k],
            model=s.model[k], iterations=s.iterations[k])
        warnings = s.before[k] + s.warnings[k] + s.notes[k]
        if g is not None:
            warnings += g.warnings
        results[i] = Measurement(
            point_id=pid, code=code, description=description, solution=sol,
            enu_origin_ecef=s.origin[k], point_ecef=point_ecef[k], cov_ecef=cov_ecef[k],
            cov_ecef_total=None if frame_cov is None else cov_total[k],
            sigma_meas=sigma_meas[k], grid=g, ray_origins_ecef=r["origins"][k],
            ray_directions_ecef=r["directions"][k], ray_origins_grid=origins_grid[k],
            excluded=r["excluded"][k], measured_at=measured_at, source_crs=src.id,
            residuals_m=r["res_m"][k], residuals_px=s.optional["res_px"][k], outliers=r["flags"][k],
            ifov=rays.ifov, lon=lons[k], lat=lats[k], h_wgs84=hs[k], warnings=warnings)


#: A grid point as _finish_json reads it: (call constants, E, N, H, sigmas E, N, H, ellipse
#: major, minor, bearing, ellipsoid axes, covariance, lon, lat, h_wgs84, measurement-only
#: sigmas or None, warnings), each as plain Python values.
GridRow = tuple[tuple[str, str, str, str, float | None], float, float, float, list[float],
                float, float, float, list[list[float]], list[list[float]], float, float, float,
                list[float] | None, list[str]]


def _finish_json(points: Sequence[BatchPoint], s: _Solved, source: str, point_ecef: FloatArray,
                 cov_ecef: FloatArray, frame_cov: FloatArray | None, cov_total: FloatArray,
                 grid: Sequence[GridRow | GsgeoError | None],
                 origins_grid: Sequence[FloatArray | None],
                 geodetic: tuple[FloatArray, FloatArray, FloatArray] | None,
                 results: list[Measurement | JSONObject | GsgeoError | None]) -> None:
    """The solved points as Measurement.to_dict() gives them (keys in its order), into
    ``results``: whole arrays turned into lists once, each point's dict made from them.
    ``geodetic``: lon, lat, h_wgs84 without a grid CRS (with one they come from the grid)."""
    measured_at = now_utc()
    r = s.rays
    p_ecef, c_ecef = point_ecef.tolist(), cov_ecef.tolist()
    c_total = c_ecef if frame_cov is None else cov_total.tolist()
    origin, p_enu, c_enu = s.origin.tolist(), s.point_enu.tolist(), s.cov_enu.tolist()
    sigma0, max_angle = s.sigma0.tolist(), s.max_angle.tolist()
    rms, dof = s.rms.tolist(), s.dof.tolist()
    geo = None if geodetic is None else [a.tolist() for a in geodetic]
    ends = np.cumsum(s.counts).tolist()
    bounds = list(zip([0, *ends[:-1]], ends, strict=True))
    none3 = [None] * 3
    no_grid: tuple[Any, ...] = ((None,) * 5, None, None, None, none3, None, None, None, None,
                                [none3] * 3, None, None, None, None, [])  # GridRow without a grid

    def per_point(rows: Sequence[np.ndarray]) -> list[list]:
        """Each point's rows as lists, from one tolist() of them all."""
        flat = np.concatenate(rows).tolist() if rows else []
        return [flat[a:b] for a, b in bounds]

    origins, directions = per_point(r["origins"]), per_point(r["directions"])
    res_m, flags, excluded_all = per_point(r["res_m"]), per_point(r["flags"]), per_point(r["excluded"])
    px_rows, sol_rows = s.optional["res_px"], s.optional["sol_res_px"]
    pxs = [a for a in px_rows if a is not None]
    px_all = per_point(pxs) if len(pxs) == len(px_rows) else None
    # the largest pixel residual of each solution, NaN where any is NaN (as np.max gives it)
    given = [a for a in sol_rows if a is not None]
    sol_max: list[float | None]
    if sol_rows and len(given) == len(sol_rows):
        starts = np.concatenate([[0], np.cumsum([a.shape[0] for a in given])[:-1]])
        sol_max = np.maximum.reduceat(np.concatenate(given), starts).tolist()
    else:
        sol_max = [None if a is None else largest(a.tolist()) for a in sol_rows]
    grids = [a for a in origins_grid if a is not None]
    grid_all = per_point(grids) if len(grids) == len(origins_grid) else None
    ifovs = [f for f in (points[i][3].ifov for i in s.index.tolist()) if f is not None]
    ifov_all = per_point(ifovs) if len(ifovs) == s.index.shape[0] else None
    for k, i in enumerate(s.index.tolist()):
        g = grid[k]
        if isinstance(g, GsgeoError):
            results[i] = g
            continue
        pid, code, description, rays, _ = points[i]
        excluded = excluded_all[k]
        n = len(excluded)
        res_px = s.optional["res_px"][k]
        px = (px_all[k] if px_all is not None else
              res_px.tolist() if res_px is not None else [None] * n)
        og = origins_grid[k]
        row: tuple[Any, ...] = no_grid if g is None else g
        ((crs, height_type, vdatum, op, acc), e, nn, h, sig, major, minor, bearing, axes, c,
         lon, lat, hw, meas, g_warnings) = row
        if g is None and geo is not None:
            lon, lat, hw = geo[0][k], geo[1][k], geo[2][k]
        sm = sig if meas is None else meas
        warnings = s.before[k] + s.warnings[k] + s.notes[k] + g_warnings
        rec: JSONObject = {  # Measurement.record()'s keys, in their order
            "point_id": pid, "code": code, "description": description,
            "easting": e, "northing": nn, "height": h, "height_type": height_type,
            "vertical_datum": vdatum, "crs": crs, "sigma_e": sig[0], "sigma_n": sig[1],
            "sigma_h": sig[2], "sigma_e_meas": sm[0], "sigma_n_meas": sm[1],
            "sigma_h_meas": sm[2], "cov_ee": c[0][0], "cov_en": c[0][1], "cov_eh": c[0][2],
            "cov_nn": c[1][1], "cov_nh": c[1][2], "cov_hh": c[2][2],
            "ellipse_major_95": major, "ellipse_minor_95": minor,
            "ellipse_bearing_deg": bearing, "sigma0": sigma0[k], "n_rays": n - sum(excluded),
            "max_angle_deg": max_angle[k], "rms_m": rms[k], "max_residual_px": sol_max[k],
            "lon": lon, "lat": lat, "h_wgs84": hw, "operation": op,
            "operation_accuracy_m": acc, "measured_at": measured_at}
        ifov = (ifov_all[k] if ifov_all is not None else
                rays.ifov.tolist() if rays.ifov is not None else [None] * n)
        og_rows = (grid_all[k] if grid_all is not None else
                   og.tolist() if og is not None else [None] * n)
        rec["rays"] = [{"index": j, "origin_ecef": o, "direction_ecef": d, "origin_grid": og_j,
                        "ifov": f, "residual_px": rp, "residual_m": rm, "outlier": ol,
                        "excluded": ex}
                       for j, (o, d, og_j, f, rp, rm, ol, ex) in enumerate(zip(
                           origins[k], directions[k],
                           og_rows, ifov, px,
                           res_m[k], flags[k], excluded, strict=True))]
        rec["warnings"] = warnings
        rec["source_crs"] = source
        rec["ellipsoid_axes_95"] = axes
        rec["point_ecef"] = p_ecef[k]
        rec["cov_ecef"] = c_ecef[k]
        rec["cov_ecef_total"] = c_total[k]
        rec["enu"] = {"origin_ecef": origin[k], "point": p_enu[k], "covariance": c_enu[k],
                      "model": s.model[k], "dof": int(dof[k])}
        results[i] = rec


@dataclass
class _CallValues:
    """One to_grid_many call's units (their indices) and rows, with the values every grid
    point of it needs: covariances (k, 3, 3) m², sigmas, the 95 % ellipse as lists, the 95 %
    ellipsoid's axes (k, 3, 3) and the measurement-only sigmas (k, 3) or None."""

    gp: GridPoints
    units: list[int]
    rows: np.ndarray
    cov: FloatArray
    sigmas: list[list[float]]
    major: list[float]
    minor: list[float]
    bearing: list[float]
    axes: FloatArray
    meas: FloatArray | None
    warnings: list[str]


class _GridCalls:
    """Units (runs of rows) transformed by to_grid_many: which call and where each unit is."""

    def __init__(self, starts: np.ndarray, counts: np.ndarray) -> None:
        u = starts.shape[0]
        self.starts, self.counts = starts, counts
        self.calls: list[GridPoints] = []
        self.warnings: list[list[str]] = []  # each call's, as a one-unit call gives them
        self.call = np.full(u, -1)  # index into calls; -1: the unit failed
        self.offset = np.zeros(u, dtype=np.int64)  # the unit's first row in its call
        self.errors: dict[int, GsgeoError] = {}

    def _calls(self, frame_cov: FloatArray | None) -> Iterator[_CallValues]:
        """Each successful call's units and their grid values (sigmas, 95 % ellipse and
        ellipsoid, the measurement-only sigmas when a frame covariance was added)."""
        for c, gp in enumerate(self.calls):
            units = np.flatnonzero(self.call == c)
            rows = self.offset[units]
            assert gp.covariance is not None  # the points' call carries covariances
            cov = gp.covariance[rows]
            meas = None
            if frame_cov is not None:
                j = gp.jacobian[rows]
                mc = cov - j @ frame_cov[units] @ np.swapaxes(j, 1, 2)
                meas = np.sqrt(np.clip(np.einsum("mii->mi", mc), 0.0, None))
            major, minor, bearing = (a.tolist() for a in ellipse_95(cov[:, :2, :2]))
            yield _CallValues(
                gp=gp, units=units.tolist(), rows=rows, cov=cov,
                sigmas=np.sqrt(np.maximum(np.einsum("mii->mi", cov), 0.0)).tolist(),
                major=major, minor=minor, bearing=bearing, axes=ellipsoid_axes_95(cov),
                meas=meas, warnings=self.warnings[c])

    def grid_points(self, frame_cov: FloatArray | None
                    ) -> tuple[list[GridPoint | GsgeoError | None], list[FloatArray | None]]:
        """Per one-row unit: its GridPoint (GridPoint.build's values) or its error, and the
        measurement-only sigmas (E, N, H) when a frame covariance was added."""
        u = self.call.shape[0]
        out: list[GridPoint | GsgeoError | None] = [None] * u
        sig_meas: list[FloatArray | None] = [None] * u
        for u_i, exc in self.errors.items():
            out[u_i] = exc
        for v in self._calls(frame_cov):
            gp, rows, sig = v.gp, v.rows, v.sigmas
            e, n, h = gp.easting[rows].tolist(), gp.northing[rows].tolist(), gp.height[rows].tolist()
            lon, lat = gp.lon[rows].tolist(), gp.lat[rows].tolist()
            hw, he = gp.h_wgs84[rows].tolist(), gp.h_ellipsoidal[rows].tolist()
            for k, u_i in enumerate(v.units):
                if v.meas is not None:
                    sig_meas[u_i] = v.meas[k]
                out[u_i] = GridPoint(
                    easting=e[k], northing=n[k], height=h[k], covariance=v.cov[k], crs=gp.crs,
                    height_type=gp.height_type, vertical_datum=gp.vertical_datum,
                    operation=gp.operation, operation_accuracy_m=gp.operation_accuracy_m,
                    lon=lon[k], lat=lat[k], h_wgs84=hw[k], h_ellipsoidal=he[k],
                    sigma_e=sig[k][0], sigma_n=sig[k][1], sigma_h=sig[k][2],
                    ellipse_major_95=v.major[k], ellipse_minor_95=v.minor[k],
                    ellipse_bearing_deg=v.bearing[k], ellipsoid_axes_95=v.axes[k],
                    warnings=list(v.warnings))
        return out, sig_meas

    def grid_rows(self, frame_cov: FloatArray | None) -> list[GridRow | GsgeoError | None]:
        """Per one-row unit: :func:`grid_points`' values as a GridRow of plain Python values
        (lists made from whole arrays at once), or its error."""
        out: list[GridRow | GsgeoError | None] = [None] * self.call.shape[0]
        for u_i, exc in self.errors.items():
            out[u_i] = exc
        for v in self._calls(frame_cov):
            gp, rows = v.gp, v.rows
            e, n, h = gp.easting[rows].tolist(), gp.northing[rows].tolist(), gp.height[rows].tolist()
            lon, lat, hw = gp.lon[rows].tolist(), gp.lat[rows].tolist(), gp.h_wgs84[rows].tolist()
            axes, covs = v.axes.tolist(), v.cov.tolist()
            meas = [None] * len(v.units) if v.meas is None else v.meas.tolist()
            const = (gp.crs, gp.height_type, gp.vertical_datum, gp.operation,
                     gp.operation_accuracy_m)
            for k, u_i in enumerate(v.units):
                out[u_i] = (const, e[k], n[k], h[k], v.sigmas[k], v.major[k], v.minor[k],
                            v.bearing[k], axes[k], covs[k], lon[k], lat[k], hw[k], meas[k],
                            list(v.warnings))
        return out

    def row_blocks(self) -> list[FloatArray | None]:
        """Per unit: its rows' (E, N, H) as (count, 3), None where its call failed."""
        out: list[FloatArray | None] = [None] * self.call.shape[0]
        for c, gp in enumerate(self.calls):
            enh = np.stack([gp.easting, gp.northing, gp.height], axis=-1)
            units = np.flatnonzero(self.call == c)
            for u_i, off, cnt in zip(units.tolist(), self.offset[units].tolist(),
                                     self.counts[units].tolist(), strict=True):
                out[u_i] = enh[off:off + cnt]
        return out


def _area_masks(areas: list[object], lon: FloatArray, lat: FloatArray) -> np.ndarray:
    """(len(areas), M) whether each (lon, lat) lies in each area of use (None: everywhere),
    the test of :func:`gsgeo.crs.transformers.in_area` on arrays."""
    out = np.ones((len(areas), lon.shape[0]), dtype=bool)
    for k, a in enumerate(areas):
        if a is None:
            continue
        w, s, e, n = (float(getattr(a, name)) for name in ("west", "south", "east", "north"))
        in_lon = (lon >= w) & (lon <= e) if w <= e else (lon >= w) | (lon <= e)
        out[k] = (lat >= s) & (lat <= n) & in_lon
    return out


def _grid_many(rows: FloatArray, covs: FloatArray | None, counts: np.ndarray,
               settings: SolveSettings, src: SourceCRS, *, per_point_warnings: bool
               ) -> _GridCalls:
    """Units of ``counts`` rows each into the grid by as few to_grid_many calls as give each
    unit what its own call would: the same operations (chosen at the centroid of a call's
    points) and, with ``per_point_warnings``, the same warnings."""
    assert settings.crs is not None
    g = grid_crs(settings.crs, settings.vertical)
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(np.int64)
    calls = _GridCalls(starts, counts)
    lon, lat, _ = ecef_to_geodetic(rows, src.id)
    ulon = np.add.reduceat(lon, starts) / counts
    ulat = np.add.reduceat(lat, starts) / counts

    def rows_of(units: np.ndarray) -> np.ndarray:
        c = counts[units]
        first = np.repeat(starts[units] - np.concatenate([[0], np.cumsum(c)[:-1]]), c)
        return first + np.arange(int(c.sum()))

    # The decisions of a call: each candidate operation's area of use at its centroid
    # (horizontal, and vertical through PROJ), and per point the grid CRS's own area.
    areas: list[object] = [t.area_of_use for t in
                           candidates(src.geographic_3d_id, g.id).available]
    comp = None
    if g.vertical is not None and settings.geoid is None:
        comp = _compound_text(rows, counts, settings, src)
        if comp is not None:
            areas += [t.area_of_use for t in candidates(src.geographic_3d_id, comp).available]

    def key_at(lon_: FloatArray, lat_: FloatArray) -> np.ndarray:
        return _area_masks(areas, lon_, lat_)

    def run(units: np.ndarray, outside: bool) -> None:
        """One call for these units (all with one key), split where it cannot stand for
        each unit's own call. ``outside``: they lie outside the grid CRS's area of use,
        whose warning counts a call's points, so the warnings come from a one-unit call."""
        rr = rows_of(units)
        if units.size > 1 and (comp is None and g.vertical is not None and settings.geoid is None
                               or not np.array_equal(
                                   key_at(np.array([np.mean(lon[rr])]),
                                          np.array([np.mean(lat[rr])]))[:, 0],
                                   key_at(ulon[units[:1]], ulat[units[:1]])[:, 0])):
            for u_i in units.tolist():  # its centroid would choose other operations
                run(np.array([u_i]), outside)
            return
        try:
            gp = to_grid_many(rows[rr], None if covs is None else covs[rr], settings.crs or "",
                              vertical=settings.vertical, geoid=settings.geoid,
                              source_crs=src.id)
            warnings = gp.warnings
            if outside and units.size > 1:
                one = rows_of(units[:1])
                warnings = to_grid_many(rows[one], None if covs is None else covs[one],
                                        settings.crs or "", vertical=settings.vertical,
                                        geoid=settings.geoid, source_crs=src.id).warnings
        except GsgeoError as exc:
            if units.size == 1:
                calls.errors[int(units[0])] = exc
                return
            half = units.size // 2
            run(units[:half], outside)
            run(units[half:], outside)
            return
        calls.call[units] = len(calls.calls)
        calls.offset[units] = np.concatenate([[0], np.cumsum(counts[units])[:-1]])
        calls.calls.append(gp)
        calls.warnings.append(warnings)

    key = key_at(ulon, ulat)
    outside = np.zeros(counts.shape[0], dtype=bool)
    if per_point_warnings and g.horizontal.area_of_use is not None:
        outside = ~_area_masks([g.horizontal.area_of_use], ulon, ulat)[0]
    key = np.vstack([key, outside[None]])
    if np.all(key == key[:, :1]):  # the usual case: one scene, one area
        inverse = np.zeros(counts.shape[0], dtype=np.int64)
    else:
        _, inverse = np.unique(key, axis=1, return_inverse=True)
        inverse = inverse.reshape(-1)
    for k in range(int(inverse.max()) + 1):
        units = np.flatnonzero(inverse == k)
        run(units, bool(outside[units[0]]))
    return calls


def _compound_text(rows: FloatArray, counts: np.ndarray, settings: SolveSettings,
                   src: SourceCRS) -> str | None:
    """The compound CRS text to_grid_many chooses vertical operations for (its result's
    ``crs``), from a call on the first unit that can be transformed; None if none can."""
    start = 0
    for c in counts.tolist()[:3]:
        try:
            gp = to_grid_many(rows[start:start + c], None, settings.crs or "",
                              vertical=settings.vertical, geoid=settings.geoid,
                              source_crs=src.id)
        except GsgeoError:
            start += c
            continue
        return gp.crs
    return None
