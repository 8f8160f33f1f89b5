"""gsgeo.export: measured points, lines and polygons to GeoPackage, GeoJSON and CSV.

One schema for all formats (the README's "Point schema"); see `write_measurements`.
`gsgeo.export.features` holds the CRS-free length/area maths with propagated sigmas.
"""

from gsgeo.export.features import LineMeasures, PolygonMeasures, line_measures, polygon_measures
from gsgeo.export.writer import FORMATS, format_for, write_measurements, write_session_results

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
