"""Outlier tests for the rays of one point: iterated data snooping by leave-one-out.

For ray i the point is solved from the other rays; the perpendicular offset e_i of that point
from ray i (two components in the plane normal to the ray) is compared with its predicted
covariance C_i = sigma_i^2 I + B_i Q_(-i) B_i^T, where Q_(-i) is the cofactor matrix of the
leave-one-out solution and B_i a basis of the plane. This is Baarda's data snooping for a
two-dimensional observation group:

- angular model (a-priori precision known): T_i = e^T C^-1 e ~ chi2(2);
- unweighted model: sigma is estimated from the other rays, so T_i / 2 ~ F(2, dof_(-i)).

Each ray is tested at ``ALPHA`` = 0.001 (Baarda's classic level); with 5 clean rays fewer than
1 % of sets raise a flag. The worst significant ray is flagged, then the remaining rays are
tested again while at least three remain, so one gross error does not drag good rays with it.
Flagged rays stay in the solution: gsgeo never drops a ray silently.
"""

from __future__ import annotations

import numpy as np

from gsgeo.solve.linalg import sym2_quadratic_inverse, sym3_inverse
from gsgeo.solve.stats import chi2_2_quantile, f2_quantile

#: Significance level of each ray's test.
ALPHA = 0.001


def plane_bases(d: np.ndarray) -> np.ndarray:
    """Orthonormal bases (..., 2, 3) of the planes normal to unit directions d (..., 3)."""
    a = np.eye(3)[np.argmin(np.abs(d), axis=-1)]  # the axis least aligned with each ray
    u = a - d * np.einsum("...i,...i->...", a, d)[..., None]
    u /= np.sqrt(np.einsum("...i,...i->...", u, u))[..., None]
    out = np.empty(d.shape[:-1] + (2, 3))
    out[..., 0, :] = u
    # v = d x u, written out: np.cross costs more than the rest of this function
    out[..., 1, 0] = d[..., 1] * u[..., 2] - d[..., 2] * u[..., 1]
    out[..., 1, 1] = d[..., 2] * u[..., 0] - d[..., 0] * u[..., 2]
    out[..., 1, 2] = d[..., 0] * u[..., 1] - d[..., 1] * u[..., 0]
    return out


def _leave_one_out(
    o: np.ndarray,
    d: np.ndarray,
    w: np.ndarray,
    sigma: np.ndarray | None,
    active: np.ndarray,
) -> np.ndarray:
    """Test statistic of each active ray divided by its critical value (> 1: significant)."""
    n_rays = d.shape[0]
    proj = np.eye(3)[None] - np.einsum("ki,kj->kij", d, d)
    wp = proj * (w * active)[:, None, None]
    n_full = wp.sum(axis=0)
    b_full = np.einsum("kij,kj->i", wp, o)
    n_loo = n_full[None] - wp
    b_loo = b_full[None] - np.einsum("kij,kj->ki", wp, o)
    q_loo, det = sym3_inverse(n_loo)
    x_loo = np.einsum("kij,kj->ki", q_loo, b_loo)
    basis = plane_bases(d)
    e = np.einsum("kai,ki->ka", basis, x_loo - o)
    bqb = np.einsum("kai,kij,kbj->kab", basis, q_loo, basis)
    m = int(active.sum())
    if sigma is not None:
        c = bqb + (sigma * sigma)[:, None, None] * np.eye(2)[None]
        stat = sym2_quadratic_inverse(c, e)
        ratio = stat / chi2_2_quantile(1.0 - ALPHA)
    else:
        # sigma^2 from the other active rays about the leave-one-out point
        rel = x_loo[:, None, :] - o[None, :, :]  # (i, k, 3)
        along = np.einsum("ikj,kj->ik", rel, d)
        off = rel - along[..., None] * d[None]
        r2 = np.einsum("ikj,ikj->ik", off, off) * active[None, :]
        r2[np.arange(n_rays), np.arange(n_rays)] = 0.0
        dof_loo = 2 * (m - 1) - 3
        s2 = r2.sum(axis=1) / dof_loo
        c = bqb + np.eye(2)[None]
        with np.errstate(divide="ignore", invalid="ignore"):
            stat = sym2_quadratic_inverse(c, e) / (2.0 * s2)
        ratio = stat / f2_quantile(1.0 - ALPHA, dof_loo)
    scale = np.abs(n_full).max()
    singular = ~(np.abs(det) > 1e-12 * scale**3)
    ratio = np.where(active & ~singular & np.isfinite(ratio), ratio, np.nan)
    return ratio


def snoop(
    origins: np.ndarray,
    directions_unit: np.ndarray,
    weights: np.ndarray | None,
    sigma_m: np.ndarray | None,
) -> tuple[np.ndarray, np.ndarray]:
    """Flag outlying rays of one point (arrays (N, 3), weights and sigmas (N,) or None).

    Returns the flags (N,) and each ray's test ratio from the first pass (statistic over its
    critical value; NaN where the ray could not be tested).
    """
    n_rays = directions_unit.shape[0]
    flags = np.zeros(n_rays, dtype=bool)
    ratios = np.full(n_rays, np.nan)
    if n_rays < 3:
        return flags, ratios
    o = origins - origins.mean(axis=0)
    w = np.ones(n_rays) if weights is None else weights
    active = np.ones(n_rays, dtype=bool)
    first = True
    while active.sum() >= 3:
        ratio = _leave_one_out(o, directions_unit, w, sigma_m, active)
        if first:
            ratios = ratio.copy()
            first = False
        if not np.any(ratio > 1.0):
            break
        worst = int(np.nanargmax(ratio))
        flags[worst] = True
        active[worst] = False
    return flags, ratios
