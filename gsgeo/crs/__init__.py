"""gsgeo.crs: frames (ECEF <-> ENU), the tileset transform chain, grid output with covariance,
vertical datums and the measurement pipeline. Knows PROJ, never HTTP.

PROJ never uses the network from gsgeo (PROJ_NETWORK=OFF on import).
"""

from gsgeo.crs.frames import EnuFrame, ecef_to_geodetic, enu_rotation, geodetic_to_ecef
from gsgeo.crs.grid import GridPoint, GridPoints, analytic_jacobian, to_grid, to_grid_many
from gsgeo.crs.pipeline import Measurement, MeasurementFailure, measure_point, measure_session
from gsgeo.crs.resolve import disable_network, grid_crs, parse_crs, source_crs
from gsgeo.crs.tileset import Tileset

__all__ = [
    "EnuFrame",
    "GridPoint",
    "GridPoints",
    "Measurement",
    "MeasurementFailure",
    "Tileset",
    "analytic_jacobian",
    "disable_network",
    "ecef_to_geodetic",
    "enu_rotation",
    "geodetic_to_ecef",
    "grid_crs",
    "measure_point",
    "measure_session",
    "parse_crs",
    "source_crs",
    "to_grid",
    "to_grid_many",
]
