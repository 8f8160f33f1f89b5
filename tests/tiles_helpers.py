"""Helpers for the tiles tests: synthetic splats, matching read-back splats to the input."""

from __future__ import annotations

import numpy as np

from gsgeo.tiles.splats import Splats, quat_to_matrix

# SPZ quantisation bounds (docs/architecture.md, "SPZ"), with a little slack for float32 arithmetic
TOL_POS_M = 0.5e-3
TOL_LOG_SCALE = 0.5 / 16 + 1e-4
TOL_ALPHA = 0.5 / 255 + 1e-5
TOL_COLOR = 0.5 / (0.15 * 255) + 1e-4
TOL_ROT_DEG = 0.25          # v3: 9-bit components of the three smallest
TOL_SH = 8 / 128 + 1 / 128  # 4-bit SH bytes (degree 2-3), per coefficient


def random_splats(rng: np.random.Generator, n: int, sh_degree: int, extent: float = 40.0,
                  centre=(0.0, 0.0, 0.0)) -> Splats:
    """Splats with known values; positions are float32-representable (as a PLY stores them)."""
    k = {0: 0, 1: 3, 2: 8, 3: 15}[sh_degree]
    pos = (np.asarray(centre) + rng.uniform(-extent, extent, (n, 3))).astype(np.float32)
    q = rng.normal(size=(n, 4)).astype(np.float32)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    return Splats(
        positions=pos.astype(np.float64),
        scales=rng.uniform(-5, -1, (n, 3)).astype(np.float32),
        rotations=q,
        opacities=rng.uniform(-4, 4, n).astype(np.float32),
        colors=rng.uniform(-1.5, 1.5, (n, 3)).astype(np.float32),
        sh=rng.uniform(-0.4, 0.4, (n, k, 3)).astype(np.float32),
    )


def match(expected: np.ndarray, got: np.ndarray) -> np.ndarray:
    """Index into `got` of the nearest point for each expected point (brute force, N < 10^4)."""
    out = np.empty(expected.shape[0], np.int64)
    for i in range(0, expected.shape[0], 512):
        d = ((expected[i:i + 512, None, :] - got[None, :, :]) ** 2).sum(axis=2)
        out[i:i + 512] = d.argmin(axis=1)
    return out


def rotation_error_deg(r_expected: np.ndarray, q_got: np.ndarray) -> np.ndarray:
    """Angle between expected splat rotation matrices (N,3,3) and read-back quaternions."""
    r = quat_to_matrix(q_got.astype(np.float64))
    rel = np.einsum("nji,njk->nik", r_expected, r)
    c = (np.trace(rel, axis1=1, axis2=2) - 1) / 2
    return np.degrees(np.arccos(np.clip(c, -1, 1)))


def sigmoid(x):
    return 1 / (1 + np.exp(-np.asarray(x, np.float64)))
