"""The measurement pipeline: a point's rays -> a georeferenced point in the grid.

rendered ECEF rays --(inverse of each ray's modelMatrix)--> georeferenced ECEF
--(pyproj topocentric at a provisional point)--> local ENU --gsgeo.solve.intersect-->
point and covariance in ENU --> ECEF (R^T C R) [+ the georeference's own uncertainty, when the
settings carry one: the total covariance] --to_grid--> E, N, H with covariance.

The ENU origin is the provisional intersection in ECEF, so the solved point sits within
millimetres of the origin and the ENU solution is well conditioned.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gsgeo import limits
from gsgeo.crs.frames import EnuFrame
from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.modelmatrix import rendered_to_georeferenced
from gsgeo.crs.resolve import grid_crs
from gsgeo.crs.resolve import source_crs as resolve_source
from gsgeo.crs.transformers import transformer
from gsgeo.errors import CRSError, GsgeoError, InputError
from gsgeo.measure.rays import Rays, SolveSettings
from gsgeo.measure.schema import Measurement, MeasurementFailure, now_utc
from gsgeo.solve import intersect

#: The warning of a point whose auto rays' reference click is excluded.
REFERENCE_EXCLUDED = ("the clicked ray the auto rays were matched to is excluded; they still "
                      "share its aiming error, which the covariance no longer holds: click the "
                      "feature again and auto-aim from that ray")


def _provisional(o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Unweighted least-squares point of rays (ECEF), only to place the ENU origin.

    Centred on the mean origin for precision; for degenerate (parallel) rays the mean origin
    is returned and the intersection proper reports the geometry.
    """
    c = o.mean(axis=0)
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    proj = np.eye(3)[None] - u[:, :, None] * u[:, None, :]
    n = proj.sum(axis=0)
    b = np.einsum("kij,kj->i", proj, o - c)
    try:
        x = np.linalg.solve(n, b)
    except np.linalg.LinAlgError:
        return c
    if not np.all(np.isfinite(x)) or np.linalg.cond(n) > 1e12:
        return c
    return c + x


def _exclusion_mask(exclude: Sequence[int], n: int, pid: str) -> np.ndarray:
    mask = np.zeros(n, dtype=bool)
    for k in exclude:
        if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or not 0 <= int(k) < n:
            raise InputError(f"cannot exclude ray index {k!r} of point '{pid}'; indices are "
                             f"0-based, 0..{n - 1}", field="exclude")
        mask[int(k)] = True
    if n - mask.sum() < 2:
        raise InputError(f"excluding {int(mask.sum())} of {n} rays of point '{pid}' leaves "
                         "fewer than 2", field="exclude")
    return mask


def measure_point(
    rays: Rays,
    settings: SolveSettings,
    *,
    point_id: str = "P",
    code: str = "",
    description: str = "",
    exclude: Sequence[int] = (),
) -> Measurement:
    """Measure one point: its rays in rendered ECEF -> point in ECEF and the grid.

    ``settings.crs`` None gives no grid output (record() grid fields None, WGS 84 lon/lat/h
    still set). ``exclude`` lists 0-based ray indices left out of the solution (reported as
    excluded). Raises InputError / GeometryError (the rays) or CRSError / DatumError (the CRS).
    """
    crs, vertical, geoid = settings.crs, settings.vertical, settings.geoid
    sigma_px = settings.sigma_px
    src = resolve_source(settings.source_crs or "EPSG:4978")
    o_r, d_r = rays.origins, rays.directions
    n = o_r.shape[0]
    if n < 2:
        raise InputError(f"point '{point_id}' needs at least 2 rays, has {n}", field="rays")
    ifov = rays.angular_ifov()
    mask = _exclusion_mask(exclude, n, point_id)
    keep = ~mask
    o, d, similar = rendered_to_georeferenced(o_r, d_r, [rays.model_matrix(i) for i in range(n)])
    for i in range(n):  # a model_matrix can move a sane ray out of range
        problem = limits.origin_problem(o[i]) if np.all(np.isfinite(o[i])) else "not finite"
        if problem:
            raise InputError("the georeferenced origin (after the inverse of the ray's "
                             f"model_matrix) is {problem}", field=f"rays[{i}].origin")
        if not (np.all(np.isfinite(d[i])) and np.any(d[i] != 0)):
            raise InputError("the direction cannot be georeferenced through the ray's "
                             "model_matrix", field=f"rays[{i}].direction")
    warnings: list[str] = []
    if not similar:
        warnings.append(
            "a model_matrix is not a rotation with uniform scale: angles between rays are "
            "distorted, so the angular model (ifov) is only approximate"
        )
    f_keep = None if ifov is None else ifov[keep]
    frame = EnuFrame(_provisional(o[keep], d[keep]), src.id)
    o_enu = frame.to_enu(o)
    d_enu = frame.directions_to_enu(d)
    auto = None if rays.auto is None else rays.auto[keep]
    sol = intersect(o_enu[keep], d_enu[keep], ifov=f_keep, sigma_px=sigma_px, auto=auto)
    point_ecef = frame.to_ecef(sol.point)
    cov_ecef = frame.covariance_to_ecef(sol.covariance)
    warnings += sol.warnings

    # Residuals of every ray (excluded ones too) from the solved point.
    rel = sol.point - o_enu
    t = np.einsum("ki,ki->k", rel, d_enu)
    off = rel - d_enu * t[:, None]
    res_m = np.sqrt(np.einsum("ki,ki->k", off, off))
    res_px = None if ifov is None else res_m / (ifov * np.where(t > 0, t, np.nan))
    outliers = np.zeros(n, dtype=bool)
    outliers[keep] = sol.outliers
    if mask.any():
        warnings.append(
            f"ray(s) {', '.join(str(i + 1) for i in np.flatnonzero(mask))} excluded by request"
        )
        if rays.auto is not None and mask[int(np.argmax(~rays.auto))]:
            warnings.append(REFERENCE_EXCLUDED)

    frame_cov = None if settings.frame is None else settings.frame.point_covariance(point_ecef)
    cov_total = cov_ecef if frame_cov is None else cov_ecef + frame_cov
    grid = None
    origins_grid = None
    sigma_meas = None
    if crs:
        gp = to_grid_many(point_ecef.reshape(1, 3), cov_total.reshape(1, 3, 3), crs,
                          vertical=vertical, geoid=geoid, source_crs=src.id)
        grid = gp.point(0)
        warnings += grid.warnings
        if frame_cov is not None and grid.covariance is not None:
            j = gp.jacobian[0]
            meas = grid.covariance - j @ frame_cov @ j.T  # the grid covariance is linear in C
            sigma_meas = np.sqrt(np.clip(np.diag(meas), 0.0, None))
        lon, lat, h84 = grid.lon, grid.lat, grid.h_wgs84
        try:
            gm = to_grid_many(o, None, crs, vertical=vertical, geoid=geoid, source_crs=src.id)
            origins_grid = np.stack([gm.easting, gm.northing, gm.height], axis=-1)
        except GsgeoError:
            origins_grid = None  # e.g. a camera outside the geoid grid; the point is fine
    else:
        t84 = transformer(src.id, "EPSG:4979")
        x, y, z = t84.transform(point_ecef[0], point_ecef[1], point_ecef[2], errcheck=False)
        lon, lat, h84 = float(x), float(y), float(z)

    return Measurement(
        point_id=point_id,
        code=code,
        description=description,
        solution=sol,
        enu_origin_ecef=frame.origin_ecef,
        point_ecef=point_ecef,
        cov_ecef=cov_ecef,
        cov_ecef_total=None if frame_cov is None else cov_total,
        sigma_meas=sigma_meas,
        grid=grid,
        ray_origins_ecef=o,
        ray_directions_ecef=d,
        ray_origins_grid=origins_grid,
        excluded=mask,
        measured_at=now_utc(),
        source_crs=src.id,
        residuals_m=res_m,
        residuals_px=res_px,
        outliers=outliers,
        ifov=ifov,
        lon=float(lon),
        lat=float(lat),
        h_wgs84=float(h84),
        warnings=warnings,
    )


def measure_points(
    points: Sequence[tuple[str, str, str, Rays]],
    settings: SolveSettings,
) -> list[Measurement | MeasurementFailure]:
    """Measure every (id, code, description, rays) point with the same settings.

    A point that cannot be measured (its rays, or e.g. outside the geoid grid) becomes a
    MeasurementFailure; a CRS problem of the whole set (unknown CRS, a missing geoid grid
    that fails every point alike) raises CRSError once.
    """
    resolve_source(settings.source_crs)
    if settings.crs:
        grid_crs(settings.crs, settings.vertical)
    elif settings.vertical or settings.geoid:
        raise InputError("a vertical datum (--vertical / --geoid) needs a grid CRS (--crs)")
    out: list[Measurement | MeasurementFailure] = []
    crs_errors: list[CRSError] = []
    for pid, code, description, rays in points:
        try:
            out.append(measure_point(rays, settings, point_id=pid, code=code,
                                     description=description))
        except CRSError as exc:
            # e.g. a point outside the geoid grid; the whole set failing alike (a missing
            # grid) is raised once below instead
            crs_errors.append(exc)
            out.append(MeasurementFailure(pid, str(exc)))
        except GsgeoError as exc:
            out.append(MeasurementFailure(pid, str(exc)))
    if crs_errors and len(crs_errors) == len(out) and len({str(e) for e in crs_errors}) == 1:
        raise crs_errors[0]
    return out
