"""The point schema's columns: the vocabulary shared by the measurement core and the store.

sigma_e/n/h, cov_* and the ellipse are a point's TOTAL uncertainty (its aiming plus, on a scene
georeferenced by control points, the georeference's); sigma_*_meas are the aiming alone.

RECORD_KEYS are the export columns in order (GeoPackage `points`, GeoJSON properties, CSV;
the README's CSV columns). A measured point's stored result (gsgeo.measure's
``Measurement.to_dict()``) holds them all; its record is that subset (:func:`record_of`),
derived wherever it is needed and never stored as a second copy. Imports nothing of gsgeo,
so gsgeo.store can use it without depending on gsgeo.measure.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

#: Keys of the point schema (the README's CSV columns), in order.
RECORD_KEYS = (
    "point_id", "code", "description", "easting", "northing", "height", "height_type",
    "vertical_datum", "crs", "sigma_e", "sigma_n", "sigma_h", "sigma_e_meas", "sigma_n_meas",
    "sigma_h_meas", "cov_ee", "cov_en", "cov_eh",
    "cov_nn", "cov_nh", "cov_hh", "ellipse_major_95", "ellipse_minor_95",
    "ellipse_bearing_deg", "sigma0", "n_rays", "max_angle_deg", "rms_m", "max_residual_px",
    "lon", "lat", "h_wgs84", "operation", "operation_accuracy_m", "measured_at",
)


def record_of(result: Mapping[str, Any]) -> dict[str, Any]:
    """The point-schema record (RECORD_KEYS, in order) of a stored result."""
    return {k: result.get(k) for k in RECORD_KEYS}
