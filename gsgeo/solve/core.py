"""Least-squares intersection of rays, vectorised over many points.

Frame-agnostic: every array is in one Cartesian frame chosen by the caller (metres). Each ray
contributes two observation equations, the components of the perpendicular offset of the
point from the ray; the normal matrix is sum w_i (I - d_i d_i^T), which is rotation invariant
and has rank 2 per ray, so no ray direction is privileged (the paper's printed two-row cross
product system loses rank for a ray parallel to the x-axis and is not used).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.solve.linalg import sym3_inverse, sym3_matvec

#: Iterations of the angular model at most; ranges change little after the first pass.
MAX_ITERATIONS = 20
#: Relative change of the point (to its mean range) at which the iteration stops.
CONVERGENCE = 1e-13


@dataclass
class CoreSolution:
    """Raw solution for M points of N rays each (frame of the input, centred back)."""

    points: np.ndarray  # (M, 3)
    normal_inverse: np.ndarray  # (M, 3, 3) inverse of sum w (I - d d^T); m^2 if weighted
    offsets: np.ndarray  # (M, N, 3) perpendicular offset of the point from each ray
    residuals_m: np.ndarray  # (M, N) perpendicular distances
    ranges: np.ndarray  # (M, N) distance along each ray to the foot of the perpendicular
    weights: np.ndarray | None  # (M, N) 1 / sigma_i^2 in 1/m^2, or None (unweighted)
    sigma_m: np.ndarray | None  # (M, N) a-priori metric precision of each ray
    vtpv: np.ndarray  # (M,) weighted sum of squared residuals (m^2 when unweighted)
    det: np.ndarray  # (M,) determinant of the normal matrix (scaled, for rank checks)
    iterations: int


def unit_directions(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors and the original norms of a (..., 3) array of directions."""
    norm = np.sqrt(np.einsum("...i,...i->...", directions, directions))
    with np.errstate(divide="ignore", invalid="ignore"):
        return directions / norm[..., None], norm


def _normal_system(
    origins: np.ndarray, d: np.ndarray, w: np.ndarray | None
) -> tuple[np.ndarray, np.ndarray]:
    """Normal matrix sum w (I - d d^T) (M, 3, 3) and right side sum w (o - d (d.o)) (M, 3)."""
    wd = d if w is None else d * w[..., None]
    wsum = d.shape[1] if w is None else w.sum(axis=1)
    n = -np.einsum("mki,mkj->mij", wd, d)
    n[:, 0, 0] += wsum
    n[:, 1, 1] += wsum
    n[:, 2, 2] += wsum
    do = np.einsum("mki,mki->mk", d, origins)
    wo = origins if w is None else origins * w[..., None]
    b = wo.sum(axis=1) - np.einsum("mki,mk->mi", wd, do)
    return n, b


def _solve(origins: np.ndarray, d: np.ndarray, w: np.ndarray | None):
    n, b = _normal_system(origins, d, w)
    ninv, det = sym3_inverse(n)
    x = sym3_matvec(ninv, b)
    return x, ninv, det


def solve_core(
    origins: np.ndarray,
    directions_unit: np.ndarray,
    ifov: np.ndarray | None,
    sigma_px: float,
) -> CoreSolution:
    """Intersect M x N rays; origins and unit directions (M, N, 3), ifov (M, N) or None.

    Coordinates are centred on the mean origin of each point before the normal equations are
    formed, so ECEF-sized inputs keep their precision.
    """
    centre = origins.mean(axis=1, keepdims=True)
    o = origins - centre
    d = directions_unit
    x, ninv, det = _solve(o, d, None)
    weights = sigma = None
    iterations = 1
    if ifov is not None:
        # Angular model: sigma_i = sigma_px * ifov_i * range_i; iterate because ranges depend
        # on the point.
        for iterations in range(2, MAX_ITERATIONS + 2):  # noqa: B007
            t = np.einsum("mki,mki->mk", x[:, None, :] - o, d)
            # A non-positive range means the point is behind a camera; keep the weight finite
            # here and let the caller reject the geometry.
            t_safe = np.where(t > 0, t, np.abs(t) + 1e-9)
            sigma = sigma_px * ifov * t_safe
            weights = 1.0 / (sigma * sigma)
            x_new, ninv, det = _solve(o, d, weights)
            scale = np.maximum(np.abs(t_safe).mean(axis=1), 1e-9)
            step = np.sqrt(np.einsum("mi,mi->m", x_new - x, x_new - x)) / scale
            x = x_new
            if not np.any(step > CONVERGENCE):
                break
    rel = x[:, None, :] - o
    t = np.einsum("mki,mki->mk", rel, d)
    offsets = rel - d * t[..., None]
    r2 = np.einsum("mki,mki->mk", offsets, offsets)
    res = np.sqrt(r2)
    vtpv = r2.sum(axis=1) if weights is None else (weights * r2).sum(axis=1)
    return CoreSolution(
        points=x + centre[:, 0, :],
        normal_inverse=ninv,
        offsets=offsets,
        residuals_m=res,
        ranges=t,
        weights=weights,
        sigma_m=sigma,
        vtpv=vtpv,
        det=det,
        iterations=iterations,
    )
