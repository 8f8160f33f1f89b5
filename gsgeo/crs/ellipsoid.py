"""Geodetic <-> ECEF on one ellipsoid in closed form, and the ENU rotation. numpy only.

These are the formulas PROJ's geocentric conversion evaluates (``+proj=cart``); they hold on
a single ellipsoid, with no datum change, so they are used where the frame is WGS 84 ECEF
(EPSG:4978) by definition: the root frame of a 3D Tiles tileset and the rigid
georeference options of ``gsgeo tiles``. Importing this module does not load PROJ (about
0.1 s at start). Anything datum-aware goes through :mod:`gsgeo.crs.frames` and PROJ.

Names: the closed-form conversions here are ``geodetic_to_ecef_closed_form`` and
``ecef_to_geodetic_closed_form`` (WGS 84 unless another a, f is given); the PROJ ones, on
any geocentric source CRS's datum, are :func:`gsgeo.crs.frames.geodetic_to_ecef` and
:func:`gsgeo.crs.frames.ecef_to_geodetic`. Longitude before latitude everywhere.

Degrees for latitude and longitude, metres for heights and coordinates.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

#: WGS 84 semi-major axis (m) and flattening.
WGS84_A = 6378137.0
WGS84_F = 1.0 / 298.257223563


def enu_rotation(lon_deg: ArrayLike, lat_deg: ArrayLike) -> np.ndarray:
    """Rotation(s) ECEF -> ENU at geodetic longitude, latitude in degrees (that order, as
    everywhere in gsgeo), shape (..., 3, 3), rows east, north, up: v_enu = R v_ecef.

    The one ENU rotation of gsgeo (:mod:`gsgeo.crs.frames` and :mod:`gsgeo.tiles` use it).
    """
    lam = np.radians(np.asarray(lon_deg, dtype=np.float64))
    phi = np.radians(np.asarray(lat_deg, dtype=np.float64))
    sl, cl, sp, cp = np.sin(lam), np.cos(lam), np.sin(phi), np.cos(phi)
    z = np.zeros_like(lam)
    return np.stack([
        np.stack([-sl, cl, z], axis=-1),
        np.stack([-sp * cl, -sp * sl, cp], axis=-1),
        np.stack([cp * cl, cp * sl, sp], axis=-1),
    ], axis=-2)


def geodetic_to_ecef_closed_form(lon: ArrayLike, lat: ArrayLike, h: ArrayLike, a: float = WGS84_A,
                                 f: float = WGS84_F) -> np.ndarray:
    """ECEF (..., 3) in metres of longitude, latitude (degrees) and ellipsoidal height (m)."""
    lam = np.radians(np.asarray(lon, dtype=np.float64))
    phi = np.radians(np.asarray(lat, dtype=np.float64))
    h = np.asarray(h, dtype=np.float64)
    e2 = f * (2.0 - f)
    sp, cp = np.sin(phi), np.cos(phi)
    n = a / np.sqrt(1.0 - e2 * sp * sp)       # prime vertical radius of curvature
    return np.stack([(n + h) * cp * np.cos(lam), (n + h) * cp * np.sin(lam),
                     (n * (1.0 - e2) + h) * sp], axis=-1)


def ecef_to_geodetic_closed_form(xyz: ArrayLike, a: float = WGS84_A, f: float = WGS84_F
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Longitude, latitude (degrees) and ellipsoidal height (m) of ECEF points (..., 3).

    Bowring's iteration on the reduced latitude, three rounds: below 1e-15 rad of the exact
    latitude from the Earth's centre region out to geostationary heights. The height
    p cos(lat) + z sin(lat) - a sqrt(1 - e² sin²(lat)) has no 1/cos(lat) and holds at the poles.
    """
    p3 = np.asarray(xyz, dtype=np.float64)
    x, y, z = p3[..., 0], p3[..., 1], p3[..., 2]
    e2 = f * (2.0 - f)
    b = a * (1.0 - f)
    ep2 = e2 / (1.0 - e2)                      # second eccentricity squared
    p = np.hypot(x, y)
    beta = np.arctan2(z, (1.0 - f) * p)
    for _ in range(3):
        sb, cb = np.sin(beta), np.cos(beta)
        phi = np.arctan2(z + ep2 * b * sb ** 3, p - e2 * a * cb ** 3)
        beta = np.arctan2((1.0 - f) * np.sin(phi), np.cos(phi))
    sp, cp = np.sin(phi), np.cos(phi)
    h = p * cp + z * sp - a * np.sqrt(1.0 - e2 * sp * sp)
    return np.degrees(np.arctan2(y, x)), np.degrees(phi), h
