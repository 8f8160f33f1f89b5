"""The viewer's modelMatrix: rendered ECEF <-> georeferenced ECEF, for points and directions.

CesiumJS draws a tileset at ``modelMatrix x (tileset transforms) x p``; the tileset's own
root transform carries the georeference, so a rendered point r maps back to the
georeferenced point g = M^-1 r. Directions go through the linear part L^-1 alone and are
re-normalised: if M scales (uniformly), angles between rays are unchanged and a ray's ifov
(an angle per pixel) stays valid, while ranges and hence metric sigmas follow the
georeferenced frame. A non-uniform scale or shear distorts angles; `is_similarity` lets the
caller warn.
"""

from __future__ import annotations

from collections.abc import Iterable

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import InputError

IDENTITY = np.eye(4)


def matrix4(m16: ArrayLike) -> np.ndarray:
    """4 x 4 matrix from 16 numbers in column-major order (3D Tiles, glTF, CesiumJS)."""
    if m16 is None:
        return IDENTITY.copy()
    a = np.asarray(m16, dtype=np.float64).reshape(-1)
    if a.shape != (16,) or not np.all(np.isfinite(a)):
        raise InputError("a 4x4 matrix needs 16 finite numbers in column-major order")
    return a.reshape(4, 4).T


def column_major(m: np.ndarray) -> list[float]:
    """16 numbers in column-major order of a 4 x 4 matrix."""
    return [float(v) for v in np.asarray(m, dtype=np.float64).T.reshape(-1)]


def invert_affine(m: np.ndarray) -> np.ndarray:
    """Inverse of an affine 4 x 4 matrix; InputError if singular."""
    lin = m[:3, :3]
    det = np.linalg.det(lin)
    if not np.isfinite(det) or abs(det) < 1e-12 * max(1.0, np.abs(lin).max() ** 3):
        raise InputError("the model matrix is singular (its 3x3 part has no inverse)")
    if m[3, 3] != 1.0 or np.any(m[3, :3] != 0):
        m = m / m[3, 3]
    inv = np.eye(4)
    li = np.linalg.inv(m[:3, :3])
    inv[:3, :3] = li
    inv[:3, 3] = -li @ m[:3, 3]
    return inv


def apply_points(m: np.ndarray, p: ArrayLike) -> np.ndarray:
    """Affine matrix (4, 4) applied to points (..., 3)."""
    p = np.asarray(p, dtype=np.float64)
    return p @ m[:3, :3].T + m[:3, 3]


def apply_directions(m: np.ndarray, d: ArrayLike, normalise: bool = True) -> np.ndarray:
    """Linear part of m applied to direction vectors (..., 3), unit length if `normalise`."""
    out = np.asarray(d, dtype=np.float64) @ m[:3, :3].T
    if normalise:
        out = out / np.linalg.norm(out, axis=-1, keepdims=True)
    return out


def is_similarity(m: np.ndarray, tol: float = 1e-6) -> bool:
    """Whether the linear part is a rotation times a uniform scale (angles preserved)."""
    lin = np.asarray(m, dtype=np.float64)[:3, :3]
    g = lin.T @ lin
    s = np.trace(g) / 3.0
    return bool(s > 0 and np.abs(g - s * np.eye(3)).max() <= tol * s)


def rendered_to_georeferenced(origins: ArrayLike, directions: ArrayLike,
                              model_matrices: Iterable[ArrayLike | None]
                              ) -> tuple[np.ndarray, np.ndarray, bool]:
    """Rays in rendered ECEF -> georeferenced ECEF, each ray with its own modelMatrix.

    origins, directions : (N, 3); model_matrices : sequence of N matrices ((4, 4), 16 numbers
    column-major, or None for identity). Returns origins, unit directions and whether every
    matrix is a similarity. Rays sharing a matrix (the usual case) share one inversion.
    """
    o = np.asarray(origins, dtype=np.float64).reshape(-1, 3)
    d = np.asarray(directions, dtype=np.float64).reshape(-1, 3)
    go = o.copy()
    gd = d / np.linalg.norm(d, axis=1, keepdims=True)
    groups: dict[bytes, list[int]] = {}
    mats: dict[bytes, np.ndarray] = {}
    for i, mm in enumerate(model_matrices):
        if mm is None:
            continue
        m = np.asarray(mm, dtype=np.float64)
        m = m if m.shape == (4, 4) else matrix4(m)
        key = m.tobytes()
        groups.setdefault(key, []).append(i)
        mats[key] = m
    similar = True
    for key, idx in groups.items():
        m = mats[key]
        if np.array_equal(m, IDENTITY):
            continue
        inv = invert_affine(m)
        go[idx] = apply_points(inv, o[idx])
        gd[idx] = apply_directions(inv, d[idx])
        similar &= is_similarity(m)
    return go, gd, similar
