"""gsgeo.export: measured points, lines and polygons to GeoPackage, GeoJSON and CSV.

One schema for all formats (the README's "Point schema"); see `write_measurements`.
The CRS-free length/area maths with propagated sigmas is gsgeo.measure.features (re-exported
here for the writers' users).
"""

from gsgeo.export.writer import FORMATS, format_for, write_measurements, write_session_results
from gsgeo.measure.features import LineMeasures, PolygonMeasures, line_measures, polygon_measures

__all__ = [
    "FORMATS",
    "LineMeasures",
    "PolygonMeasures",
    "format_for",
    "line_measures",
    "polygon_measures",
    "write_measurements",
    "write_session_results",
]
