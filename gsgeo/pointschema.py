"""The export schema's columns: the vocabulary shared by the measurement core, the exports and
the store (points, their provenance, the surfaces of buildings).

sigma_e/n/h, cov_* and the ellipse are a point's TOTAL uncertainty (its aiming plus, on a scene
georeferenced by control points, the georeference's); sigma_*_meas are the aiming alone.

RECORD_KEYS are the export columns in order (GeoPackage `points`, GeoJSON properties, CSV;
the README's CSV columns). A measured point's stored result (gsgeo.measure's
``Measurement.to_dict()``) holds them all; its record is that subset (:func:`record_of`),
derived wherever it is needed and never stored as a second copy. Imports nothing of gsgeo,
so gsgeo.store can use it without depending on gsgeo.measure.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
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


#: Columns every point export and view has after RECORD_KEYS: who measured the point (a user's
#: name, "local" for the operator on loopback; None when not known) and how many of its rays
#: were aimed by a click and how many matched automatically (excluded rays included). They
#: come from the stored point (its rays and measured_by), not from its measured result.
PROVENANCE_KEYS = ("measured_by", "n_rays_clicked", "n_rays_auto")
#: Every column of a point in an export (GeoPackage ``points``, GeoJSON, CSV) and a view.
EXPORT_KEYS = RECORD_KEYS + PROVENANCE_KEYS


def provenance(rays: Sequence[Mapping[str, Any]], measured_by: str | None) -> dict[str, Any]:
    """The PROVENANCE_KEYS values of a point with these session-JSON rays (a ray with
    ``"auto": true`` was matched automatically, any other was clicked)."""
    auto = sum(1 for r in rays if r.get("auto") is True)
    return {"measured_by": measured_by, "n_rays_clicked": len(rays) - auto, "n_rays_auto": auto}


#: The columns of a building surface (GeoPackage ``buildings``, the PostGIS buildings view, the
#: OGC collection), in order: 'str', 'int' or 'float'. One row per surface of a building's LoD2
#: solid: its semantic type and the building's measures (m^3, m^2, heights H in the CRS's
#: vertical units, sigmas 1 sigma).
BUILDING_MEASURES: tuple[str, ...] = (
    "volume", "sigma_volume", "footprint_area", "sigma_footprint_area", "ground_height",
    "sigma_ground_height", "eaves_height", "sigma_eaves_height", "ridge_height",
    "sigma_ridge_height", "measured_height", "sigma_measured_height")
BUILDING_TYPES: dict[str, str] = {"building_id": "str", "surface_index": "int",
                                  "surface_type": "str", "roof_type": "str",
                                  **dict.fromkeys(BUILDING_MEASURES, "float")}
