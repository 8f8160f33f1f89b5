"""Confidence scales and the few distribution quantiles the solver needs, in closed form."""

from __future__ import annotations

import math

import numpy as np

#: Scale of a 1-sigma interval to 95 % in one dimension (sqrt of chi2(1) at 0.95).
SCALE_95_1D = 1.959963984540054
#: Scale of a 1-sigma ellipse to the 95 % ellipse in two dimensions (sqrt(-2 ln 0.05)).
SCALE_95_2D = 2.447746830680816
#: Scale of a 1-sigma ellipsoid to the 95 % ellipsoid in three dimensions (sqrt chi2(3) 0.95).
SCALE_95_3D = 2.7954834829151074


def chi2_2_quantile(p: float) -> float:
    """Quantile of the chi-square distribution with 2 degrees of freedom at probability p."""
    return -2.0 * math.log1p(-p)


def f2_quantile(p: float, m: np.ndarray | float) -> np.ndarray | float:
    """Quantile of Fisher's F(2, m) at probability p (m may be an array).

    Uses the closed form of the F(2, m) distribution: P(F <= f) = 1 - (1 + 2 f / m) ** (-m / 2).
    """
    m = np.asarray(m, dtype=np.float64)
    return (m / 2.0) * ((1.0 - p) ** (-2.0 / m) - 1.0)


def chi2_sf(x: np.ndarray | float, dof: np.ndarray | int) -> np.ndarray:
    """Upper tail probability of chi-square(dof) at x, for integer dof >= 1.

    Closed-form series (exact for integer dof), vectorised over x and dof.
    """
    x = np.asarray(x, dtype=np.float64)
    dof = np.asarray(dof, dtype=np.int64)
    x, dof = np.broadcast_arrays(x, dof)
    out = np.empty(x.shape, dtype=np.float64)
    half = 0.5 * x
    even = dof % 2 == 0
    # even dof: exp(-x/2) * sum_{k < dof/2} (x/2)^k / k!
    # odd dof: erfc(sqrt(x/2)) + exp(-x/2) * sum_{k=0}^{(dof-3)/2} (x/2)^(k+1/2) / Gamma(k+3/2)
    flat_x = half.ravel()
    flat_d = dof.ravel()
    flat_e = even.ravel()
    res = out.ravel()
    for i in range(flat_x.size):  # called on a handful of values per point, never per splat
        h, d = float(flat_x[i]), int(flat_d[i])
        if flat_e[i]:
            term, s = 1.0, 1.0
            for k in range(1, d // 2):
                term *= h / k
                s += term
            res[i] = math.exp(-h) * s
        else:
            s = math.erfc(math.sqrt(h))
            term = math.sqrt(h) / math.gamma(1.5)
            acc = 0.0
            for k in range((d - 1) // 2):
                if k > 0:
                    term *= h / (k + 0.5)
                acc += term
            res[i] = s + math.exp(-h) * acc
    return out
