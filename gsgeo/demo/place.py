"""Where the demo scene is on the Earth, and its ground truth in ECEF and in the national grid.

The scene frame (`gsgeo.demo.scene`) is British National Grid coordinates minus
:data:`OFFSET`: x = E - 545 400, y = N - 258 100 (Parker's Piece, Cambridge, UK), z = h - 12,
h a height on the OSGB36 (Airy 1830) ellipsoid — what ``gsgeo tiles --crs EPSG:27700 --offset
545400,258100,12`` takes (about the ODN height there, within a few metres).

The ground truth of a validation point is first its ECEF position through that same PROJ path
(OSGB36 geographic 3-D -> WGS 84 geocentric, PROJ's best operation, a Helmert transformation
good to a few metres as a datum link, exact as a formula), then what gsgeo reports for a point
measured exactly there: `gsgeo.crs.to_grid` in EPSG:27700 with WGS 84 ellipsoidal heights.
The check points hold the latter, so a perfect measurement shows zero difference.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.crs.resolve import parse_crs
from gsgeo.crs.transformers import transformer
from gsgeo.demo import scene

#: National grid of the demo (British National Grid, OSGB36).
CRS = "EPSG:27700"
#: Grid coordinates of the scene origin: easting, northing (m), OSGB36 ellipsoidal height (m).
OFFSET = (545400.0, 258100.0, 12.0)
#: Where that is.
PLACE = "Parker's Piece, Cambridge, UK"


@dataclass(frozen=True)
class TruthPoint:
    """One validation point: id, code (its subset), description, ECEF (m, WGS 84) and grid
    coordinates (E, N in EPSG:27700, H = WGS 84 ellipsoidal height, m)."""

    id: str
    code: str
    description: str
    local: tuple[float, float, float]
    ecef: tuple[float, float, float]
    easting: float
    northing: float
    height: float


def local_to_ecef(local: np.ndarray) -> np.ndarray:
    """Scene-frame points (N, 3) -> ECEF (N, 3) through the grid path of ``gsgeo tiles --crs``."""
    local = np.atleast_2d(np.asarray(local, np.float64))
    grid = parse_crs(CRS)
    inv = transformer(grid, grid.geodetic_crs)
    geodetic = grid.geodetic_crs
    assert geodetic is not None  # a projected CRS has one
    to_ecef = transformer(geodetic.to_3d(), "EPSG:4978")
    lon, lat = inv.transform(local[:, 0] + OFFSET[0], local[:, 1] + OFFSET[1])
    x, y, z = to_ecef.transform(lon, lat, local[:, 2] + OFFSET[2])
    return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], -1)


def truth_points() -> list[TruthPoint]:
    """The 20 validation points with ECEF and national-grid coordinates (see module doc)."""
    from gsgeo.crs import to_grid_many

    local = scene.truth_array()
    ecef = local_to_ecef(local)
    g = to_grid_many(ecef, None, CRS)
    out = []
    for i, vp in enumerate(scene.VALIDATION_POINTS):
        out.append(TruthPoint(vp.id, vp.subset, vp.description, vp.xyz,
                              (float(ecef[i, 0]), float(ecef[i, 1]), float(ecef[i, 2])), float(g.easting[i]),
                              float(g.northing[i]), float(g.height[i])))
    return out
