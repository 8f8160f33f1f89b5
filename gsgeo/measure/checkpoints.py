"""Check points into a project's grid: the same path the measured points take.

A check point is an id with x, y, z (z may be NaN: not given) in the CRS it was surveyed in.
:func:`check_points_in_grid` gives their easting, northing and height in the grid of a
project's :class:`~gsgeo.measure.rays.SolveSettings` (or another grid CRS), so that
differences against measured points are differences of positions, never of paths.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.resolve import parse_crs, projected_crs
from gsgeo.crs.transformers import transformer
from gsgeo.errors import CRSError
from gsgeo.measure.rays import SolveSettings
from gsgeo.solve.linalg import FloatArray


def check_points_in_grid(xyz: FloatArray, crss: Sequence[str], settings: SolveSettings,
                         crs: str | None = None,
                         height_hint: FloatArray | None = None) -> FloatArray:
    """(M, 3) easting, northing, height of check points in the grid of ``settings`` (or ``crs``).

    xyz : (M, 3) coordinates as surveyed, each row in ``crss[i]`` (its units, NaN height
        when not given). settings : the project's; its ``geoid`` is a resolved file path.

    Check points in a geographic or geocentric CRS go to ECEF and then through
    gsgeo.crs.to_grid_many, the very path the measured points take (same datum operation,
    same vertical datum or geoid), so a difference is never a difference of paths. Points in a
    projected (or compound) CRS: easting/northing through PROJ when the CRS differs, heights
    as given. A missing height stays NaN; ``height_hint`` (M,) ellipsoidal heights (e.g. of the
    matched measured points) stand in for it in 3-D datum steps, where the height moves E, N
    by about 1 mm per 50 m.
    """
    coords = np.asarray(xyz, dtype=float).reshape(-1, 3)
    grid = crs or settings.crs
    if grid is None:
        raise CRSError("no grid CRS to compare check points in", field="crs")
    same_grid = grid == settings.crs
    vertical = settings.vertical if same_grid else None
    geoid = settings.geoid if same_grid else None
    out = np.full((coords.shape[0], 3), np.nan)
    target = projected_crs(grid)
    for src in sorted(set(crss)):
        idx = [i for i, c in enumerate(crss) if c == src]
        pts = coords[idx]
        s = parse_crs(src)
        if s.is_geocentric or s.is_geographic:
            has_h = np.isfinite(pts[:, 2])
            src3 = s if s.is_geocentric or len(s.axis_info) == 3 else s.to_3d()
            t = transformer(src3.to_wkt(), parse_crs(settings.source_crs).to_wkt())
            hint = np.zeros(len(idx)) if height_hint is None else \
                np.nan_to_num(np.asarray(height_hint, dtype=float)[idx])
            ecef = np.column_stack(t.transform(pts[:, 0], pts[:, 1],
                                               np.where(has_h, pts[:, 2], hint)))
            if not np.all(np.isfinite(ecef)):
                raise CRSError(f"check points in {src}: some cannot be transformed to "
                               f"{settings.source_crs}")
            g = to_grid_many(ecef, None, grid, vertical=vertical, geoid=geoid,
                             source_crs=settings.source_crs)
            e, n, h = g.easting, g.northing, np.where(has_h, g.height, np.nan)
        else:
            horiz = s.sub_crs_list[0] if s.is_compound else s
            if horiz.equals(target):
                e, n = pts[:, 0], pts[:, 1]
            else:
                e, n = transformer(horiz.to_wkt(), target.to_wkt()).transform(pts[:, 0], pts[:, 1])
            h = pts[:, 2]
        out[idx, 0], out[idx, 1], out[idx, 2] = e, n, h
    if not np.all(np.isfinite(out[:, :2])):
        raise CRSError("check points: some cannot be transformed into the project's grid CRS")
    return out
