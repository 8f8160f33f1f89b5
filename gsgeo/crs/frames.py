"""Earth-centred (ECEF) and local topocentric (ENU) frames.

ENU: x east, y north, z up, origin at a point near the scene, axes from the geodetic
latitude and longitude of the origin on the source CRS's ellipsoid. Points go through PROJ
(``+proj=topocentric``), direction vectors and covariances through the rotation alone
(rows east = [-sin lon, cos lon, 0], north = [-sin lat cos lon, -sin lat sin lon, cos lat],
up = [cos lat cos lon, cos lat sin lon, sin lat]). Metres and radians inside; degrees at
the interface, longitude before latitude.

``geodetic_to_ecef`` / ``ecef_to_geodetic`` here go through PROJ on the source CRS's datum;
the closed-form WGS 84 formulas that need no PROJ are
:func:`gsgeo.crs.ellipsoid.geodetic_to_ecef_closed_form` and
:func:`gsgeo.crs.ellipsoid.ecef_to_geodetic_closed_form`.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.crs.ellipsoid import enu_rotation  # noqa: F401  (part of this module's interface)
from gsgeo.crs.resolve import source_crs
from gsgeo.crs.transformers import pipeline, transformer
from gsgeo.errors import InputError


def _rotate(r: np.ndarray, v: ArrayLike) -> np.ndarray:
    """r (3, 3) applied to vectors (..., 3); (r @ v.T).T is ~20x faster than v @ r.T here."""
    a = np.asarray(v, dtype=np.float64)
    flat = a.reshape(-1, 3)
    return np.ascontiguousarray((r @ flat.T).T).reshape(a.shape)


def ecef_to_geodetic(xyz: ArrayLike, source: str = "EPSG:4978") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Longitude, latitude (degrees) and ellipsoidal height (m) on the source CRS's datum."""
    p = np.asarray(xyz, dtype=np.float64)
    src = source_crs(source)
    t = transformer(src.id, src.geographic_3d_id)
    lon, lat, h = t.transform(p[..., 0], p[..., 1], p[..., 2], errcheck=False)
    return np.asarray(lon), np.asarray(lat), np.asarray(h)


def geodetic_to_ecef(lon: ArrayLike, lat: ArrayLike, h: ArrayLike, source: str = "EPSG:4978") -> np.ndarray:
    """ECEF (m) of longitude, latitude (degrees) and ellipsoidal height (m) on the source datum."""
    src = source_crs(source)
    t = transformer(src.geographic_3d_id, src.id)
    x, y, z = t.transform(np.asarray(lon, float), np.asarray(lat, float), np.asarray(h, float),
                          errcheck=False)
    return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)


def geodetic_jacobian(lat_deg: ArrayLike, h: np.ndarray | float, a: float,
                      f: float) -> tuple[np.ndarray, np.ndarray]:
    """Radii factors of d(lon, lat)/d(east, north) in radians per metre at latitude, height.

    Returns (1 / ((N + h) cos lat), 1 / (M + h)): dlon = e . dX / ((N + h) cos lat),
    dlat = n . dX / (M + h), dh = u . dX, with e, n, u the ENU rows at the point.
    """
    phi = np.radians(np.asarray(lat_deg, dtype=np.float64))
    e2 = f * (2.0 - f)
    s2 = np.sin(phi) ** 2
    w = np.sqrt(1.0 - e2 * s2)
    n_rad = a / w
    m_rad = a * (1.0 - e2) / w**3
    return 1.0 / ((n_rad + h) * np.cos(phi)), 1.0 / (m_rad + h)


class EnuFrame:
    """A local topocentric frame (ENU) at an origin on the source CRS's ellipsoid.

    Parameters
    ----------
    origin_ecef : (3,) origin in the source geocentric CRS, metres.
    source : the geocentric CRS ("EPSG:4978" WGS 84 by default); its ellipsoid defines the
        frame's axes.
    """

    def __init__(self, origin_ecef: ArrayLike, source: str = "EPSG:4978") -> None:
        o = np.asarray(origin_ecef, dtype=np.float64).reshape(-1)
        if o.shape != (3,) or not np.all(np.isfinite(o)):
            raise InputError("an ENU origin must be 3 finite ECEF coordinates in metres")
        if np.linalg.norm(o) < 1e5:
            raise InputError("an ENU origin must be near the Earth's surface, not the geocentre")
        self.source = source_crs(source)
        self.origin_ecef = o
        lon, lat, h = ecef_to_geodetic(o, source)
        self.lon, self.lat, self.h = float(lon), float(lat), float(h)
        self.rotation = enu_rotation(self.lon, self.lat)
        rf = 1.0 / self.source.f if self.source.f else 0.0
        self._definition = (
            f"+proj=topocentric +a={float(self.source.a):.17g} +rf={float(rf):.17g} "
            f"+X_0={float(o[0]):.17g} +Y_0={float(o[1]):.17g} +Z_0={float(o[2]):.17g}"
        )

    @classmethod
    def from_geodetic(cls, lon: float, lat: float, h: float, source: str = "EPSG:4978") -> EnuFrame:
        """Frame at longitude, latitude (degrees) and ellipsoidal height (m) on the source datum."""
        return cls(geodetic_to_ecef(lon, lat, h, source), source)

    def to_enu(self, points_ecef: ArrayLike) -> np.ndarray:
        """ECEF points (..., 3) -> ENU (..., 3), metres, through PROJ's topocentric conversion."""
        p = np.asarray(points_ecef, dtype=np.float64)
        t = pipeline(self._definition)
        e, n, u = t.transform(p[..., 0], p[..., 1], p[..., 2], errcheck=False)
        return np.stack([np.asarray(e), np.asarray(n), np.asarray(u)], axis=-1)

    def to_ecef(self, points_enu: ArrayLike) -> np.ndarray:
        """ENU points (..., 3) -> ECEF (..., 3), metres."""
        p = np.asarray(points_enu, dtype=np.float64)
        t = pipeline(self._definition)
        x, y, z = t.transform(p[..., 0], p[..., 1], p[..., 2], direction="INVERSE", errcheck=False)
        return np.stack([np.asarray(x), np.asarray(y), np.asarray(z)], axis=-1)

    def directions_to_enu(self, d_ecef: ArrayLike) -> np.ndarray:
        """Direction vectors (..., 3) ECEF -> ENU (rotation only; lengths kept)."""
        return _rotate(self.rotation, d_ecef)

    def directions_to_ecef(self, d_enu: ArrayLike) -> np.ndarray:
        """Direction vectors (..., 3) ENU -> ECEF (rotation only; lengths kept)."""
        return _rotate(self.rotation.T, d_enu)

    def covariance_to_ecef(self, cov_enu: ArrayLike) -> np.ndarray:
        """Covariance(s) (..., 3, 3) ENU -> ECEF: R^T C R (m^2)."""
        r = self.rotation
        return r.T @ np.asarray(cov_enu, dtype=np.float64) @ r

    def covariance_to_enu(self, cov_ecef: ArrayLike) -> np.ndarray:
        """Covariance(s) (..., 3, 3) ECEF -> ENU: R C R^T (m^2)."""
        r = self.rotation
        return r @ np.asarray(cov_ecef, dtype=np.float64) @ r.T
