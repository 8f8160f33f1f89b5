"""A local-frame scene with a known truth, for the georeferencing tests.

The truth: a site near Oxford (EPSG:27700 applies), and a similarity T from the scene's local
coordinates p (what a COLMAP-frame trainer writes) to true ECEF: y = site + E (s A p + shift),
E the ENU axes at the site, A a rotation about a tilted axis, s the scene's scale. Rays are
synthesised as a viewer would take them: from cameras around a target, in the frame the
scene is currently rendered in, with Gaussian aiming noise of sigma_px pixels.
"""

from __future__ import annotations

import numpy as np

from gsgeo.crs.ellipsoid import (
    ecef_to_geodetic_closed_form,
    enu_rotation,
    geodetic_to_ecef_closed_form,
)
from gsgeo.georef.helmert import Similarity, rotation_from_vector

SITE = (-1.2577, 51.7520, 70.0)  # lon, lat (degrees), ellipsoidal height (m)
SCALE = 2.7  # true metres per local unit
ROTVEC = (0.35, -0.25, 2.1)  # radians: rotated and tilted
SHIFT = (12.0, -7.0, 1.5)  # metres, in the site's ENU


def truth() -> Similarity:
    """Local scene coordinates -> true ECEF (WGS 84), metres."""
    e = enu_rotation(SITE[0], SITE[1]).T
    a = rotation_from_vector(ROTVEC)
    origin = geodetic_to_ecef_closed_form(*SITE)
    return Similarity(SCALE, e @ a, origin + e @ np.asarray(SHIFT))


def perpendicular(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors perpendicular to unit d (3,)."""
    a = np.array([1.0, 0, 0]) if abs(d[0]) < 0.9 else np.array([0, 1.0, 0])
    u = np.cross(d, a)
    u /= np.linalg.norm(u)
    return u, np.cross(d, u)


def aim(rng: np.random.Generator, target: np.ndarray, up: np.ndarray, distance: float,
        n: int = 4, ifov: float = 1e-3, sigma_px: float = 0.5) -> list[dict]:
    """Session-JSON rays at ``target`` (ECEF, the frame rendered now) from n cameras spread in
    azimuth, 20-50 degrees above the horizon given by ``up``, ``distance`` away; each
    direction deviates by N(0, sigma_px * ifov) radians in two perpendicular directions."""
    upn = up / np.linalg.norm(up)
    east, north = perpendicular(upn)
    rays = []
    for k in range(n):
        az = 2 * np.pi * k / n + rng.uniform(-0.3, 0.3)
        el = np.radians(rng.uniform(20, 50))
        v = np.cos(el) * (np.cos(az) * east + np.sin(az) * north) + np.sin(el) * upn
        cam = target + distance * v
        d = (target - cam) / np.linalg.norm(target - cam)
        u, w = perpendicular(d)
        d = d + rng.normal(0, sigma_px * ifov) * u + rng.normal(0, sigma_px * ifov) * w
        rays.append({"origin": cam.tolist(), "direction": d.tolist(), "ifov": ifov})
    return rays


def lon_lat_h(ecef: np.ndarray) -> np.ndarray:
    """(M, 3) WGS 84 longitude, latitude (degrees), ellipsoidal height (m): EPSG:4979 order."""
    lon, lat, h = ecef_to_geodetic_closed_form(ecef)
    return np.column_stack([lon, lat, h])
