"""Closed-form linear algebra on stacks of small symmetric matrices.

The normal matrices of ray intersection are 3 x 3 and symmetric; solving them with the
adjugate is several times faster over millions of points than ``numpy.linalg`` and needs no
Python loop.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

#: Arrays of float64 numbers, the type of every coordinate, covariance and residual array.
FloatArray = npt.NDArray[np.float64]
Entries6 = tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray, FloatArray]


def sym3_inverse_entries(
    n00: FloatArray, n01: FloatArray, n02: FloatArray, n11: FloatArray, n12: FloatArray, n22: FloatArray
) -> tuple[Entries6, FloatArray]:
    """The six unique entries of the inverse of symmetric 3 x 3 matrices, and the determinant.

    Each argument is one entry over any stack shape; returns
    ``(i00, i01, i02, i11, i12, i22), det``, non-finite where the determinant is zero.
    """
    c00 = n11 * n22 - n12 * n12
    c01 = n02 * n12 - n01 * n22
    c02 = n01 * n12 - n02 * n11
    c11 = n00 * n22 - n02 * n02
    c12 = n01 * n02 - n00 * n12
    c22 = n00 * n11 - n01 * n01
    det = n00 * c00 + n01 * c01 + n02 * c02
    with np.errstate(divide="ignore", invalid="ignore"):
        inv_det = 1.0 / det
    return (c00 * inv_det, c01 * inv_det, c02 * inv_det, c11 * inv_det, c12 * inv_det,
            c22 * inv_det), det


def sym3_inverse(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Inverse and determinant of a stack of symmetric 3 x 3 matrices.

    Parameters
    ----------
    a : array (..., 3, 3), symmetric.

    Returns
    -------
    inverse : array (..., 3, 3); non-finite where the determinant is zero.
    det : array (...).
    """
    (i00, i01, i02, i11, i12, i22), det = sym3_inverse_entries(
        a[..., 0, 0], a[..., 0, 1], a[..., 0, 2], a[..., 1, 1], a[..., 1, 2], a[..., 2, 2]
    )
    out = np.empty(a.shape, dtype=np.float64)
    out[..., 0, 0] = i00
    out[..., 0, 1] = out[..., 1, 0] = i01
    out[..., 0, 2] = out[..., 2, 0] = i02
    out[..., 1, 1] = i11
    out[..., 1, 2] = out[..., 2, 1] = i12
    out[..., 2, 2] = i22
    return out, det


def sym3_matvec(a: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``a @ v`` for stacks of 3 x 3 matrices (..., 3, 3) and vectors (..., 3)."""
    return np.einsum("...ij,...j->...i", a, v)


def sym2_quadratic_inverse(c: np.ndarray, e: np.ndarray) -> np.ndarray:
    """``e^T c^-1 e`` for stacks of symmetric 2 x 2 matrices (..., 2, 2) and vectors (..., 2)."""
    c00, c01, c11 = c[..., 0, 0], c[..., 0, 1], c[..., 1, 1]
    det = c00 * c11 - c01 * c01
    e0, e1 = e[..., 0], e[..., 1]
    with np.errstate(divide="ignore", invalid="ignore"):
        return (c11 * e0 * e0 - 2.0 * c01 * e0 * e1 + c00 * e1 * e1) / det
