"""Error ellipses and ellipsoids of covariances in a grid frame (E, N, H), vectorised."""

from __future__ import annotations

import numpy as np

from gsgeo.solve import SCALE_95_2D, SCALE_95_3D


def ellipse_95(cov_en: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """95 % horizontal error ellipse of (..., 2, 2) covariances in (E, N), m^2.

    Returns semi-major, semi-minor axes (m) and the bearing of the major axis in degrees
    clockwise from grid north, in [0, 180).
    """
    c = np.asarray(cov_en, dtype=np.float64)
    ee, nn, en = c[..., 0, 0], c[..., 1, 1], c[..., 0, 1]
    mean = 0.5 * (ee + nn)
    rad = np.sqrt((0.5 * (ee - nn)) ** 2 + en**2)
    lmax = mean + rad
    lmin = np.maximum(mean - rad, 0.0)
    # Major axis direction (dE, dN) at angle t from the E axis: tan 2t = 2 en / (ee - nn).
    t = 0.5 * np.arctan2(2.0 * en, ee - nn)
    bearing = np.degrees(np.pi / 2 - t) % 180.0
    return SCALE_95_2D * np.sqrt(lmax), SCALE_95_2D * np.sqrt(lmin), bearing


def ellipsoid_axes_95(cov: np.ndarray) -> np.ndarray:
    """Semi-axis vectors of the 95 % error ellipsoid, (..., 3, 3), rows largest first (m)."""
    w, v = np.linalg.eigh(np.asarray(cov, dtype=np.float64))
    w = np.maximum(w, 0.0)[..., ::-1]
    v = v[..., :, ::-1]
    axes = np.swapaxes(v, -1, -2) * (SCALE_95_3D * np.sqrt(w))[..., None]
    # Deterministic sign: each axis points into the upper half (positive H, then N, then E).
    ref = np.where(np.abs(axes[..., 2]) > 1e-12 * np.abs(axes).max(axis=-1) + 0.0,
                   axes[..., 2], np.where(np.abs(axes[..., 1]) > 0, axes[..., 1], axes[..., 0]))
    return axes * np.where(ref < 0, -1.0, 1.0)[..., None]
