"""The in-memory splat record and the rotation algebra shared by readers and writers.

A :class:`Splats` holds N Gaussians in one Cartesian frame (metres):

- ``positions`` (N, 3) float64, centres;
- ``scales`` (N, 3) float32, natural logarithms of the standard deviations along the splat axes;
- ``rotations`` (N, 4) float32, unit quaternions **x, y, z, w** (the order of SPZ and glTF)
  turning splat axes into the frame;
- ``opacities`` (N,) float32, logits (sigmoid gives alpha);
- ``colors`` (N, 3) float32, SH degree-0 coefficients ``f_dc`` (RGB = 0.5 + C0 * f_dc);
- ``sh`` (N, K, 3) float32, higher-degree SH coefficients, coefficient-major with the colour
  channel innermost (K = 0, 3, 8 or 15 for degree 0..3).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SH_C0 = 0.28209479177387814
#: Number of higher-order SH coefficients per channel for degree 0..3.
SH_COEFFS = {0: 0, 1: 3, 2: 8, 3: 15}
SH_DEGREE_OF = {v: k for k, v in SH_COEFFS.items()}


@dataclass
class Splats:
    positions: np.ndarray
    scales: np.ndarray
    rotations: np.ndarray
    opacities: np.ndarray
    colors: np.ndarray
    sh: np.ndarray

    @property
    def count(self) -> int:
        return int(self.positions.shape[0])

    @property
    def sh_degree(self) -> int:
        return SH_DEGREE_OF[int(self.sh.shape[1])]

    def take(self, idx: np.ndarray | slice) -> Splats:
        return Splats(self.positions[idx], self.scales[idx], self.rotations[idx],
                      self.opacities[idx], self.colors[idx], self.sh[idx])

    @staticmethod
    def concatenate(parts: list[Splats]) -> Splats:
        return Splats(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in ("positions", "scales", "rotations", "opacities",
                                  "colors", "sh")))

    def finite_mask(self) -> np.ndarray:
        """True for splats whose every value is finite (and whose rotation is not zero)."""
        # A row sum is NaN/inf when any term is; finite values overflow a float32 sum only
        # beyond 1e37, far outside any meaningful splat attribute.
        with np.errstate(over="ignore", invalid="ignore"):
            ok = np.isfinite(_row_sums(self.positions))
            ok &= np.isfinite(_row_sums(self.scales))
            r2 = np.einsum("ij,ij->i", self.rotations, self.rotations)
            ok &= np.isfinite(r2) & (r2 > 0)
            ok &= np.isfinite(self.opacities)
            ok &= np.isfinite(_row_sums(self.colors))
            if self.sh.shape[1]:
                # (N, K, 3) is often a transposed view of channel-major (N, 3, K) rows
                n = self.count
                cm = self.sh.transpose(0, 2, 1)
                flat = cm.reshape(n, -1) if cm.strides[2] == cm.itemsize else \
                    self.sh.reshape(n, -1)
                ok &= np.isfinite(_row_sums(flat))
        return ok


def _row_sums(a: np.ndarray) -> np.ndarray:
    """Sums of the rows of a 2-D array. numpy's axis=1 reductions loop per row, slow for
    narrow rows: a few columns are added one by one, wide ones with a matrix-vector product."""
    if a.shape[1] <= 4:
        out = a[:, 0].copy()
        for i in range(1, a.shape[1]):
            out += a[:, i]
        return out
    return a @ np.ones(a.shape[1], a.dtype)


# --- quaternions (x, y, z, w) -------------------------------------------------------------

def quat_multiply(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product a * b of quaternions (..., 4) in x, y, z, w order."""
    ax, ay, az, aw = np.moveaxis(a, -1, 0)
    bx, by, bz, bw = np.moveaxis(b, -1, 0)
    return np.stack([
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    ], axis=-1)


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) x, y, z, w (normalised here)."""
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = np.moveaxis(q, -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) x, y, z, w of rotation matrices (..., 3, 3); w >= 0."""
    m = np.asarray(m, dtype=np.float64)
    t = np.stack([
        1 + m[..., 0, 0] - m[..., 1, 1] - m[..., 2, 2],
        1 - m[..., 0, 0] + m[..., 1, 1] - m[..., 2, 2],
        1 - m[..., 0, 0] - m[..., 1, 1] + m[..., 2, 2],
        1 + m[..., 0, 0] + m[..., 1, 1] + m[..., 2, 2],
    ], axis=-1)
    # Take the largest of |x|,|y|,|z|,|w| from the diagonal and the others from off-diagonals:
    # well-conditioned for every rotation.
    k = np.argmax(t, axis=-1)
    s = np.sqrt(np.maximum(np.take_along_axis(t, k[..., None], -1)[..., 0], 1e-300)) * 2
    q = np.empty(m.shape[:-2] + (4,))
    d21, d02, d10 = m[..., 2, 1] - m[..., 1, 2], m[..., 0, 2] - m[..., 2, 0], m[..., 1, 0] - m[..., 0, 1]
    s01, s02, s12 = m[..., 0, 1] + m[..., 1, 0], m[..., 0, 2] + m[..., 2, 0], m[..., 1, 2] + m[..., 2, 1]
    cand = [
        np.stack([s / 4, s01 / s, s02 / s, d21 / s], -1),
        np.stack([s01 / s, s / 4, s12 / s, d02 / s], -1),
        np.stack([s02 / s, s12 / s, s / 4, d10 / s], -1),
        np.stack([d21 / s, d02 / s, d10 / s, s / 4], -1),
    ]
    for i in range(4):
        sel = k == i
        q[sel] = cand[i][sel]
    q *= np.where(q[..., 3:4] < 0, -1.0, 1.0)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def rotation_angle(m: np.ndarray) -> float:
    """Angle (radians) of a 3x3 rotation matrix."""
    return float(np.arccos(np.clip((np.trace(m) - 1) / 2, -1.0, 1.0)))


# --- spherical harmonics ---------------------------------------------------------------------

def sh_basis(d: np.ndarray) -> np.ndarray:
    """The 15 real SH functions of degree 1..3 at unit directions (M, 3), with the constants
    and signs of the INRIA 3DGS renderer (its eval_sh), so coefficients mean the same here."""
    x, y, z = d[:, 0], d[:, 1], d[:, 2]
    xx, yy, zz = x * x, y * y, z * z
    c1 = 0.4886025119029199
    c2 = (1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
          0.5462742152960396)
    c3 = (-0.5900435899266435, 2.890611442640554, -0.4570457994644658, 0.3731763325901154,
          -0.4570457994644658, 1.445305721320277, -0.5900435899266435)
    return np.stack([
        -c1 * y, c1 * z, -c1 * x,
        c2[0] * x * y, c2[1] * y * z, c2[2] * (2 * zz - xx - yy), c2[3] * x * z,
        c2[4] * (xx - yy),
        c3[0] * y * (3 * xx - yy), c3[1] * x * y * z, c3[2] * y * (4 * zz - xx - yy),
        c3[3] * z * (2 * zz - 3 * xx - 3 * yy), c3[4] * x * (4 * zz - xx - yy),
        c3[5] * z * (xx - yy), c3[6] * x * (xx - 3 * yy),
    ], axis=1)


def sh_rotation(r: np.ndarray, k: int = 15) -> np.ndarray:
    """Matrix D (k, k) turning SH coefficients (degree 1..3, first k) by the rotation r (3, 3).

    A splat whose view-dependent colour is f(d) in the old frame has f(rᵀ d') in the new one;
    with coefficients c (k, 3) the new ones are D @ c. Each degree band is closed under
    rotation, so D is found exactly by least squares on sample directions.
    """
    if k == 0:
        return np.zeros((0, 0))
    rng = np.random.default_rng(0)
    d = rng.normal(size=(256, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b_new = sh_basis(d)[:, :k]
    b_old = sh_basis(d @ np.asarray(r, dtype=np.float64))[:, :k]  # rows: rᵀ d
    out = np.zeros((k, k))
    for lo, hi in ((0, 3), (3, 8), (8, 15)):
        if lo >= k:
            break
        out[lo:hi, lo:hi] = np.linalg.lstsq(b_new[:, lo:hi], b_old[:, lo:hi], rcond=None)[0]
    return out


def sh_eval(sh: np.ndarray, d: np.ndarray) -> np.ndarray:
    """View-dependent colour term sum_j B_j(d) c_j of degree 1..3 at unit directions: (N, 3)."""
    b = sh_basis(d)[:, : sh.shape[1]]
    return np.einsum("nk,nkc->nc", b, sh)
