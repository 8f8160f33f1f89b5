"""Least-squares intersection of rays, vectorised over many points.

Frame-agnostic: every array is in one Cartesian frame chosen by the caller (metres). Each ray
contributes two observation equations, the components of the perpendicular offset of the
point from the ray; the normal matrix is sum w_i (I - d_i d_i^T), which is rotation invariant
and has rank 2 per ray, so no ray direction is privileged (the paper's printed two-row cross
product system loses rank for a ray parallel to the x-axis and is not used).

The arithmetic runs on per-component arrays laid out rays-major, (N, M), rather than (M, N, 3)
stacks: sums over the rays become N contiguous row additions, and with a closed-form 3 x 3
inverse this is several times faster than einsum and ``numpy.linalg`` over millions of points.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gsgeo.solve.linalg import FloatArray, sym3_inverse_entries

#: One array per Cartesian component (x, y, z).
Components = Sequence[FloatArray]

#: Iterations of the angular model at most; ranges change little after the first pass.
MAX_ITERATIONS = 20
#: Change of the point, relative to its mean range, at which a point stops iterating
#: (0.1 micrometre at 100 m; each pass shrinks the change about a thousandfold).
CONVERGENCE = 1e-9


@dataclass
class CoreSolution:
    """Raw solution for M points of N rays each (frame of the input)."""

    points: np.ndarray  # (M, 3)
    normal_inverse: np.ndarray  # (M, 3, 3) inverse of sum w (I - d d^T); m^2 if weighted
    residuals_m: np.ndarray  # (M, N) perpendicular distances
    ranges: np.ndarray  # (M, N) distance along each ray to the foot of the perpendicular
    weights: np.ndarray | None  # (M, N) 1 / sigma_i^2 in 1/m^2, or None (unweighted)
    sigma_m: np.ndarray | None  # (M, N) a-priori metric precision of each ray
    vtpv: np.ndarray  # (M,) weighted sum of squared residuals (m^2 when unweighted)
    iterations: int


def unit_directions(directions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Unit vectors and the original norms of a (..., 3) array of directions."""
    norm = np.sqrt(np.einsum("...i,...i->...", directions, directions))
    with np.errstate(divide="ignore", invalid="ignore"):
        return directions / norm[..., None], norm


def _solve(
    o: Components, d: Components, do: FloatArray, w: FloatArray | None
) -> tuple[Components, Components]:
    """Solve the normal equations for component arrays o = (ox, oy, oz), d = (dx, dy, dz), (N, M).

    Returns the point components (each (M,)) and the six unique entries of the inverse normal
    matrix (00, 01, 02, 11, 12, 22). ``do`` is d . o per ray, constant over the iterations.
    """
    ox, oy, oz = o
    dx, dy, dz = d
    if w is None:
        wsum = float(dx.shape[0])
        wdx, wdy, wdz = dx, dy, dz
        wox, woy, woz = ox, oy, oz
    else:
        wsum = w.sum(axis=0)
        wdx, wdy, wdz = w * dx, w * dy, w * dz
        wox, woy, woz = w * ox, w * oy, w * oz
    n00 = wsum - (wdx * dx).sum(axis=0)
    n11 = wsum - (wdy * dy).sum(axis=0)
    n22 = wsum - (wdz * dz).sum(axis=0)
    n01 = -(wdx * dy).sum(axis=0)
    n02 = -(wdx * dz).sum(axis=0)
    n12 = -(wdy * dz).sum(axis=0)
    b0 = wox.sum(axis=0) - (wdx * do).sum(axis=0)
    b1 = woy.sum(axis=0) - (wdy * do).sum(axis=0)
    b2 = woz.sum(axis=0) - (wdz * do).sum(axis=0)
    q, _ = sym3_inverse_entries(n00, n01, n02, n11, n12, n22)
    x = q[0] * b0 + q[1] * b1 + q[2] * b2
    y = q[1] * b0 + q[3] * b1 + q[4] * b2
    z = q[2] * b0 + q[4] * b1 + q[5] * b2
    return (x, y, z), q


def _ranges(p: Components, o: Components, d: Components) -> FloatArray:
    return (
        (p[0] - o[0]) * d[0] + (p[1] - o[1]) * d[1] + (p[2] - o[2]) * d[2]
    )


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
    centre = origins.mean(axis=1)
    o = tuple(np.ascontiguousarray(origins[..., k].T - centre[:, k]) for k in range(3))
    d = tuple(np.ascontiguousarray(directions_unit[..., k].T) for k in range(3))
    do = d[0] * o[0] + d[1] * o[1] + d[2] * o[2]
    p, q = _solve(o, d, do, None)
    weights = sigma = None
    iterations = 1
    if ifov is not None:
        f = np.ascontiguousarray(ifov.T)
        # Angular model: sigma_i = sigma_px * ifov_i * range_i; iterate because the ranges
        # depend on the point. Points that have converged drop out of later passes.
        p = [c.copy() for c in p]
        q = [c.copy() for c in q]
        weights = np.empty_like(f)
        sigma = np.empty_like(f)
        idx = np.arange(f.shape[1])
        for iterations in range(2, MAX_ITERATIONS + 2):  # noqa: B007
            full = idx.size == f.shape[1]
            oi = o if full else tuple(c[:, idx] for c in o)
            di = d if full else tuple(c[:, idx] for c in d)
            doi = do if full else do[:, idx]
            pi = p if full else [c[idx] for c in p]
            t = _ranges(pi, oi, di)
            # A non-positive range means the point is behind a camera; keep the weight finite
            # here and let the caller reject the geometry.
            t_safe = np.where(t > 0, t, np.abs(t) + 1e-9)
            s_i = sigma_px * (f if full else f[:, idx]) * t_safe
            w_i = 1.0 / (s_i * s_i)
            p_new, q_new = _solve(oi, di, doi, w_i)
            step2 = (p_new[0] - pi[0]) ** 2 + (p_new[1] - pi[1]) ** 2 + (p_new[2] - pi[2]) ** 2
            scale = np.maximum(t_safe.mean(axis=0), 1e-9)
            sigma[:, idx] = s_i
            weights[:, idx] = w_i
            for k in range(3):
                p[k][idx] = p_new[k]
            for k in range(6):
                q[k][idx] = q_new[k]
            idx = idx[step2 > (CONVERGENCE * scale) ** 2]
            if idx.size == 0:
                break
    t = _ranges(p, o, d)
    rx = p[0] - o[0] - t * d[0]
    ry = p[1] - o[1] - t * d[1]
    rz = p[2] - o[2] - t * d[2]
    r2 = rx * rx + ry * ry + rz * rz
    vtpv = r2.sum(axis=0) if weights is None else (weights * r2).sum(axis=0)
    m = centre.shape[0]
    ninv = np.empty((m, 3, 3))
    ninv[:, 0, 0], ninv[:, 0, 1], ninv[:, 0, 2] = q[0], q[1], q[2]
    ninv[:, 1, 0], ninv[:, 1, 1], ninv[:, 1, 2] = q[1], q[3], q[4]
    ninv[:, 2, 0], ninv[:, 2, 1], ninv[:, 2, 2] = q[2], q[4], q[5]
    return CoreSolution(
        points=np.stack(p, axis=1) + centre,
        normal_inverse=ninv,
        residuals_m=np.sqrt(r2).T,
        ranges=t.T,
        weights=None if weights is None else weights.T,
        sigma_m=None if sigma is None else sigma.T,
        vtpv=vtpv,
        iterations=iterations,
    )


def solve_one(
    origins: np.ndarray,
    directions_unit: np.ndarray,
    ifov: np.ndarray | None,
    sigma_px: float,
) -> CoreSolution:
    """`solve_core` for a single point, origins and unit directions (N, 3), ifov (N,) or None.

    Written with 3 x 3 matrix products instead of per-component arrays: for one point the
    number of numpy calls, not the arithmetic, sets the latency. The same model and stopping
    rule as `solve_core`; the batch tests check that the two agree.
    """
    centre = origins.mean(axis=0)
    o = origins - centre
    d = directions_unit
    eye = np.eye(3)
    do = np.einsum("ij,ij->i", d, o)

    def solve(w: FloatArray | None) -> tuple[FloatArray, FloatArray]:
        wd = d if w is None else d * w[:, None]
        wo = o if w is None else o * w[:, None]
        wsum = d.shape[0] if w is None else w.sum()
        nmat = wsum * eye - wd.T @ d
        b = wo.sum(axis=0) - wd.T @ do
        ninv = np.linalg.inv(nmat)
        return ninv @ b, ninv

    x, ninv = solve(None)
    weights = sigma = None
    iterations = 1
    if ifov is not None:
        for iterations in range(2, MAX_ITERATIONS + 2):  # noqa: B007
            t = np.einsum("ij,ij->i", x - o, d)
            t_safe = np.where(t > 0, t, np.abs(t) + 1e-9)
            sigma = sigma_px * ifov * t_safe
            weights = 1.0 / (sigma * sigma)
            x_new, ninv = solve(weights)
            step2 = float((x_new - x) @ (x_new - x))
            scale = max(float(t_safe.mean()), 1e-9)
            x = x_new
            if not step2 > (CONVERGENCE * scale) ** 2:
                break
    rel = x - o
    t = np.einsum("ij,ij->i", rel, d)
    r = rel - t[:, None] * d
    r2 = np.einsum("ij,ij->i", r, r)
    vtpv = r2.sum() if weights is None else (weights * r2).sum()
    return CoreSolution(
        points=(x + centre)[None],
        normal_inverse=ninv[None],
        residuals_m=np.sqrt(r2)[None],
        ranges=t[None],
        weights=None if weights is None else weights[None],
        sigma_m=None if sigma is None else sigma[None],
        vtpv=np.array([vtpv]),
        iterations=iterations,
    )
