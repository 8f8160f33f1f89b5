"""gsgeo.measure: the measurement core between the geodesy (gsgeo.crs, gsgeo.solve) and
everything that reads input or keeps and shows results (gsgeo.session, gsgeo.export,
gsgeo.service); it imports none of them.

- ``rays``: the typed input, Rays (a point's aims, rendered ECEF, validated once) and
  SolveSettings;
- ``point``: a point's rays (rendered ECEF) -> Measurement in ECEF and the grid CRS;
- ``schema``: Measurement, its point-schema record (RECORD_KEYS), MeasurementFailure;
- ``features``: lengths, areas and perimeters of lines and polygons with propagated sigmas
  (plain (N, 3) / (N, 3, 3) arrays in grid units, no CRS);
- ``checkpoints``: check points into a project's grid by the measured points' own path;
- ``accuracy``: measured minus check statistics (RMSE, ME, SD).
"""

from gsgeo.measure.features import LineMeasures, PolygonMeasures, line_measures, polygon_measures
from gsgeo.measure.point import measure_point, measure_points
from gsgeo.measure.rays import Rays, SolveSettings
from gsgeo.measure.schema import RECORD_KEYS, Measurement, MeasurementFailure

__all__ = [
    "RECORD_KEYS",
    "LineMeasures",
    "Measurement",
    "MeasurementFailure",
    "PolygonMeasures",
    "line_measures",
    "Rays",
    "SolveSettings",
    "measure_point",
    "measure_points",
    "polygon_measures",
]
