"""Control points into the Earth's frame: ECEF positions and covariances along the project's path.

Control arrives in any CRS (a national grid with orthometric heights, geographic 3D, ECEF).
It must land in the geocentric CRS the scene's points are measured in (``settings.source_crs``)
along the very path the measured points take to the grid, run backwards, so that a fitted
scene reproduces the control's own numbers when its points are taken to the grid again:

- geocentric or geographic 3D control: straight through PROJ to ``source_crs``;
- grid control (E, N, H): E, N to the project's grid if needed (PROJ, horizontal), then the
  inverse of ``gsgeo.crs.grid.to_grid_many`` (datum operation, vertical datum or geoid) by
  Newton's method on its own Jacobian: x <- x + J^-1 (target - f(x)), converged to 0.1 mm
  in two or three steps.

Stated precisions (sigma_h horizontal, sigma_v vertical, metres) become ECEF covariances by
the local ENU rotation at each point.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, enu_rotation
from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.resolve import grid_crs, parse_crs
from gsgeo.crs.transformers import transformer
from gsgeo.errors import CRSError, InputError
from gsgeo.measure.checkpoints import check_points_in_grid
from gsgeo.measure.rays import SolveSettings
from gsgeo.solve.linalg import FloatArray

#: Newton's method on the grid path stops below this correction (metres).
INVERSE_TOLERANCE_M = 1e-5
INVERSE_ITERATIONS = 8


def enu_covariances(points_ecef: ArrayLike, sigma_h: ArrayLike, sigma_v: ArrayLike) -> FloatArray:
    """(M, 3, 3) ECEF covariances (m²) of points with horizontal / vertical sigmas (m)."""
    p = np.asarray(points_ecef, dtype=np.float64).reshape(-1, 3)
    lon, lat, _ = ecef_to_geodetic_closed_form(p)
    r = enu_rotation(lon, lat).reshape(-1, 3, 3)
    sh = np.broadcast_to(np.asarray(sigma_h, dtype=np.float64), (p.shape[0],))
    sv = np.broadcast_to(np.asarray(sigma_v, dtype=np.float64), (p.shape[0],))
    d = np.zeros((p.shape[0], 3, 3))
    d[:, 0, 0] = d[:, 1, 1] = sh**2
    d[:, 2, 2] = sv**2
    return np.einsum("nki,nkl,nlj->nij", r, d, r)


def grid_to_ecef(enh: ArrayLike, settings: SolveSettings) -> FloatArray:
    """(M, 3) ECEF on ``settings.source_crs`` of (M, 3) E, N, H in the project's grid (its
    units, its height system): the inverse of the measured points' path to the grid."""
    g = np.asarray(enh, dtype=np.float64).reshape(-1, 3)
    if settings.crs is None:
        raise CRSError("grid control needs the project's grid CRS", field="crs")
    grid = grid_crs(settings.crs, settings.vertical)
    src = parse_crs(settings.source_crs)
    geo3 = src.geodetic_crs.to_3d() if src.geodetic_crs is not None else None
    if geo3 is None:
        raise CRSError(f"{settings.source_crs} has no geographic CRS")
    lon, lat = transformer(grid.horizontal.to_wkt(), geo3.to_2d().to_wkt()).transform(
        g[:, 0], g[:, 1], errcheck=False)
    x = np.column_stack(transformer(geo3.to_wkt(), src.to_wkt()).transform(
        np.asarray(lon), np.asarray(lat), g[:, 2] * grid.vertical_unit_factor, errcheck=False))
    if not np.all(np.isfinite(x)):
        raise CRSError(f"some control points cannot be taken from {settings.crs} to "
                       f"{settings.source_crs}")
    units = np.array([grid.unit_factor, grid.unit_factor, grid.vertical_unit_factor])
    for _ in range(INVERSE_ITERATIONS):
        f = to_grid_many(x, None, settings.crs, vertical=settings.vertical,
                         geoid=settings.geoid, source_crs=settings.source_crs)
        miss = (g - np.column_stack([f.easting, f.northing, f.height])) * units
        dx = np.linalg.solve(f.jacobian, miss[:, :, None])[:, :, 0]
        x = x + dx
        if np.abs(dx).max() < INVERSE_TOLERANCE_M:
            return x
    raise CRSError("control points: the grid path could not be inverted (no convergence)")


def control_ecef(xyz: ArrayLike, crss: Sequence[str], settings: SolveSettings,
                 ids: Sequence[str]) -> FloatArray:
    """(M, 3) ECEF on ``settings.source_crs`` of control given as (M, 3) in ``crss[i]``.

    Heights are required (NaN: InputError naming the point): a similarity in 3-D needs them.
    """
    pts = np.asarray(xyz, dtype=np.float64).reshape(-1, 3)
    missing = [ids[int(i)] for i in np.flatnonzero(~np.isfinite(pts[:, 2]))]
    if missing:
        raise InputError(f"control point(s) {', '.join(missing[:5])} have no height; 3-D "
                         "control needs one", field="control")
    out = np.full(pts.shape, np.nan)
    dest = parse_crs(settings.source_crs)
    for name in sorted(set(crss)):
        idx = [i for i, c in enumerate(crss) if c == name]
        s = parse_crs(name)
        if s.is_geocentric or s.is_geographic:
            s3 = s if s.is_geocentric or len(s.axis_info) == 3 else s.to_3d()
            t = transformer(s3.to_wkt(), dest.to_wkt())
            p = pts[idx]
            out[idx] = np.column_stack(t.transform(p[:, 0], p[:, 1], p[:, 2], errcheck=False))
        else:
            enh = check_points_in_grid(pts[idx], [name] * len(idx), settings)
            out[idx] = grid_to_ecef(enh, settings)
    if not np.all(np.isfinite(out)):
        raise CRSError(f"some control points cannot be transformed to {settings.source_crs}")
    return out
