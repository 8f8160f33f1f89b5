"""Synthetic ray networks with known truth: aiming noise in pixels around a known point.

Used by the tests, the benchmarks and the accuracy experiment; independent of the solver.
"""

from __future__ import annotations

import numpy as np

#: A point in ECEF (metres) near London: ECEF-sized coordinates stress the centring.
TRUTH_ECEF = np.array([3978560.282, -9849.538, 4968501.546])


def perpendicular_basis(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (..., 3) perpendicular to unit d and to each other (independent of the
    solver's own basis: built from the world z axis, falling back to x)."""
    ref = np.broadcast_to(np.array([0.0, 0.0, 1.0]), d.shape).copy()
    near = np.abs(d[..., 2]) > 0.9
    ref[near] = [1.0, 0.0, 0.0]
    u = np.cross(d, ref)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(d, u)
    return u, v


def camera_network(
    rng: np.random.Generator, m: int, n: int, truth: np.ndarray = TRUTH_ECEF,
    rmin: float = 20.0, rmax: float = 150.0,
) -> tuple[np.ndarray, np.ndarray]:
    """Camera centres (m, n, 3) on random directions above the point, and unit directions to it.

    Cameras sit at ranges rmin..rmax, at elevations 15..85 degrees in a local frame whose up is
    the radial direction of ``truth`` (so the geometry looks like a drone survey around it).
    """
    up = truth / np.linalg.norm(truth)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    az = rng.uniform(0, 2 * np.pi, (m, n))
    el = np.radians(rng.uniform(15, 85, (m, n)))
    rng_m = rng.uniform(rmin, rmax, (m, n))
    local = np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], axis=-1)
    offsets = local @ np.stack([east, north, up])
    origins = truth + offsets * rng_m[..., None]
    directions = -offsets
    return origins, directions


def aim_with_noise(
    rng: np.random.Generator, directions: np.ndarray, ifov: np.ndarray | float, sigma_px: float
) -> np.ndarray:
    """Perturb unit directions by Gaussian aiming noise of sigma_px pixels of size ifov (rad)."""
    u, v = perpendicular_basis(directions)
    a = np.asarray(ifov) * sigma_px
    du = rng.normal(size=directions.shape[:-1]) * a
    dv = rng.normal(size=directions.shape[:-1]) * a
    # a pixel offset is a tangent-plane offset: d' = d + tan(angle) along u and v
    out = directions + np.tan(du)[..., None] * u + np.tan(dv)[..., None] * v
    return out / np.linalg.norm(out, axis=-1, keepdims=True)
