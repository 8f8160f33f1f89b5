"""The point schema: a measured point (Measurement) and its record, one row of every export.

RECORD_KEYS are the export columns in order (GeoPackage `points`, GeoJSON properties, CSV).
A Measurement holds the solution in the local ENU frame, the georeferenced ECEF point and
its covariance (metres, m²) and, with a grid CRS, the grid point (E, N, H in the CRS's units,
covariance in m²).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from datetime import UTC, datetime

import numpy as np

from gsgeo.crs.grid import GridPoint
from gsgeo.jsontypes import JSONObject
from gsgeo.pointschema import RECORD_KEYS, record_of
from gsgeo.solve import IntersectionResult
from gsgeo.solve.linalg import FloatArray

__all__ = ["RECORD_KEYS", "Measurement", "MeasurementFailure", "largest", "now_utc", "record_of"]

def now_utc() -> str:
    """The current time, ISO 8601 UTC to the second ('2026-11-24T15:00:00Z')."""
    return datetime.now(UTC).isoformat(timespec="seconds").replace("+00:00", "Z")


def largest(values: list[float]) -> float:
    """max() of a few floats as np.max gives it (NaN when any is NaN), without numpy's
    per-call overhead: a re-measure asks it for every stored point."""
    top = max(values)
    return top if all(v == v for v in values) else float("nan")


@dataclass
class Measurement:
    """A measured point: the ENU solution, the georeferenced ECEF point and the grid point."""

    point_id: str
    code: str
    description: str
    solution: IntersectionResult  # in the local ENU frame
    enu_origin_ecef: FloatArray  # (3,)
    point_ecef: FloatArray  # (3,) georeferenced ECEF on source_crs, m
    cov_ecef: FloatArray  # (3, 3) m^2, the aiming alone (measurement-only)
    grid: GridPoint | None  # its covariance is the total (cov_ecef_total when given)
    ray_origins_ecef: FloatArray  # (N, 3) georeferenced
    ray_directions_ecef: FloatArray  # (N, 3) georeferenced, unit
    ray_origins_grid: FloatArray | None  # (N, 3) E, N, H of the camera centres
    excluded: np.ndarray  # (N,) bool
    measured_at: str
    source_crs: str = "EPSG:4978"
    residuals_m: FloatArray | None = None  # (N,) every ray, excluded ones too
    residuals_px: FloatArray | None = None  # (N,) angular model only
    outliers: np.ndarray | None = None  # (N,) bool; excluded rays False
    ifov: FloatArray | None = None  # (N,)
    lon: float | None = None  # WGS 84, degrees
    lat: float | None = None
    h_wgs84: float | None = None
    warnings: list[str] = field(default_factory=list)
    # with a georeference's uncertainty: (3, 3) ECEF total covariance, m^2, and the
    # measurement-only grid sigmas (E, N, H), m; None when the frame is taken as exact
    cov_ecef_total: FloatArray | None = None
    sigma_meas: FloatArray | None = None

    @property
    def n_rays(self) -> int:
        """Rays used in the solution (excluded ones not counted)."""
        return int(self.excluded.shape[0]) - int(np.count_nonzero(self.excluded))

    def record(self) -> JSONObject:
        """The point-schema row, keys in order; grid fields None without a grid."""
        g = self.grid
        s = self.solution
        rec = dict.fromkeys(RECORD_KEYS)
        rec.update(point_id=self.point_id, code=self.code, description=self.description,
                   sigma0=float(s.sigma0), n_rays=self.n_rays,
                   max_angle_deg=float(s.max_angle_deg), rms_m=float(s.rms_m),
                   max_residual_px=(None if s.residuals_px is None
                                    else largest(s.residuals_px.tolist())),
                   lon=self.lon, lat=self.lat, h_wgs84=self.h_wgs84,
                   measured_at=self.measured_at)
        if g is not None:
            rec.update(
                easting=g.easting, northing=g.northing, height=g.height,
                height_type=g.height_type, vertical_datum=g.vertical_datum, crs=g.crs,
                sigma_e=g.sigma_e, sigma_n=g.sigma_n, sigma_h=g.sigma_h,
                ellipse_major_95=g.ellipse_major_95, ellipse_minor_95=g.ellipse_minor_95,
                ellipse_bearing_deg=g.ellipse_bearing_deg, operation=g.operation,
                operation_accuracy_m=g.operation_accuracy_m,
            )
            if self.sigma_meas is None:
                rec.update(sigma_e_meas=g.sigma_e, sigma_n_meas=g.sigma_n, sigma_h_meas=g.sigma_h)
            else:
                rec.update(sigma_e_meas=float(self.sigma_meas[0]),
                           sigma_n_meas=float(self.sigma_meas[1]),
                           sigma_h_meas=float(self.sigma_meas[2]))
            c = g.covariance  # a measured point's grid point always carries one
            if c is not None:
                rec.update(
                    cov_ee=float(c[0, 0]), cov_en=float(c[0, 1]), cov_eh=float(c[0, 2]),
                    cov_nn=float(c[1, 1]), cov_nh=float(c[1, 2]), cov_hh=float(c[2, 2]))
        return rec

    def to_dict(self) -> JSONObject:
        """record() plus rays, warnings, 95 % ellipsoid axes and the ENU solution (JSON-ready)."""
        out = self.record()
        n = int(self.excluded.shape[0])
        none: list[None] = [None] * n

        def col(a: np.ndarray | None) -> list:  # one tolist() per array, not per ray
            return none if a is None else a.tolist()

        rays = [{"index": i, "origin_ecef": o, "direction_ecef": d, "origin_grid": g,
                 "ifov": f, "residual_px": rp, "residual_m": rm, "outlier": bool(ol),
                 "excluded": bool(ex)}
                for i, (o, d, g, f, rp, rm, ol, ex) in enumerate(zip(
                    col(self.ray_origins_ecef), col(self.ray_directions_ecef),
                    col(self.ray_origins_grid), col(self.ifov), col(self.residuals_px),
                    col(self.residuals_m),
                    col(self.outliers) if self.outliers is not None else [False] * n,
                    col(self.excluded), strict=True))]
        out["rays"] = rays
        out["warnings"] = list(self.warnings)
        out["source_crs"] = self.source_crs
        out["ellipsoid_axes_95"] = (None if self.grid is None or self.grid.ellipsoid_axes_95 is None
                                    else self.grid.ellipsoid_axes_95.tolist())
        out["point_ecef"] = self.point_ecef.tolist()
        out["cov_ecef"] = self.cov_ecef.tolist()
        out["cov_ecef_total"] = (self.cov_ecef.tolist() if self.cov_ecef_total is None
                                 else self.cov_ecef_total.tolist())
        out["enu"] = {
            "origin_ecef": self.enu_origin_ecef.tolist(),
            "point": self.solution.point.tolist(),
            "covariance": self.solution.covariance.tolist(),
            "model": self.solution.model,
            "dof": int(self.solution.dof),
        }
        return out


@dataclass
class MeasurementFailure:
    """A point that could not be measured, with the reason."""

    point_id: str
    error: str

    def to_dict(self) -> dict[str, str]:
        """The failure as JSON: point_id and error."""
        return {"point_id": self.point_id, "error": self.error}
