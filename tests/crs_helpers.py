"""Synthetic viewer rays for crs tests: cameras around a known point, aimed with angular noise."""

from __future__ import annotations

import numpy as np

from gsgeo.crs.frames import EnuFrame


def rotation(axis, angle_rad: float) -> np.ndarray:
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + np.sin(angle_rad) * k + (1 - np.cos(angle_rad)) * k @ k


def model_matrix(centre_ecef, *, angle_deg=0.7, scale=1.0005, shift=(3.0, -2.0, 1.5)) -> np.ndarray:
    """A non-identity tileset modelMatrix: rotation + uniform scale about the scene, then a shift."""
    c = np.asarray(centre_ecef, dtype=float)
    lin = scale * rotation([0.3, -0.5, 0.8], np.radians(angle_deg))
    m = np.eye(4)
    m[:3, :3] = lin
    m[:3, 3] = c - lin @ c + np.asarray(shift)
    return m


def camera_origins(point_ecef, n: int, rng, *, dist=(20.0, 45.0)) -> np.ndarray:
    """n camera centres (ECEF) around a point, 10..40 degrees above its horizon."""
    fr = EnuFrame(point_ecef)
    az = np.linspace(0, 2 * np.pi, n, endpoint=False) + rng.uniform(0, 2 * np.pi)
    el = np.radians(rng.uniform(10, 40, n))
    r = rng.uniform(*dist, n)
    enu = np.stack([r * np.cos(el) * np.sin(az), r * np.cos(el) * np.cos(az), r * np.sin(el)], -1)
    return fr.to_ecef(enu)


def noisy_directions(origins, target, sigma_rad: float, rng) -> np.ndarray:
    """Unit directions from origins (..., 3) to target, each tilted by N(0, sigma) per axis."""
    d = target - origins
    d = d / np.linalg.norm(d, axis=-1, keepdims=True)
    # two unit vectors perpendicular to each direction
    helper = np.where(np.abs(d[..., 2:3]) < 0.9, np.array([0.0, 0, 1]), np.array([1.0, 0, 0]))
    u = np.cross(d, helper)
    u /= np.linalg.norm(u, axis=-1, keepdims=True)
    v = np.cross(d, u)
    e = rng.normal(0, sigma_rad, d.shape[:-1] + (2,))
    out = d + e[..., :1] * u + e[..., 1:] * v
    return out / np.linalg.norm(out, axis=-1, keepdims=True)


def render(m: np.ndarray, origins, directions) -> tuple[np.ndarray, np.ndarray]:
    """Georeferenced rays -> what the viewer reports (rendered = M x georeferenced)."""
    o = origins @ m[:3, :3].T + m[:3, 3]
    d = directions @ m[:3, :3].T
    return o, d / np.linalg.norm(d, axis=-1, keepdims=True)
