"""The 7-parameter similarity (3-D Helmert) by weighted least squares, both sides uncertain.

A scene's frame x (ECEF as the scene is placed now) maps to the Earth's y (ECEF) by

    y = s R x + t        (s scale, R rotation, t translation; metres)

Control points give pairs (x_i, y_i) with covariances C_x,i (the measured point) and C_y,i (the
control's stated precision). The fit minimises sum v_i^T S_i^-1 v_i, v_i = y_i - (s R x_i + t),
S_i = C_y,i + s^2 R C_x,i R^T (the errors of both sides mapped into y; to first order this is
the Gauss-Helmert adjustment). It starts from the closed-form weighted solution (Umeyama's SVD
of the cross-covariance) and iterates Gauss-Newton steps on a perturbation of the fitted frame
about the weighted centre c of the control (gsgeo.measure.framecov):

    y = y0 + dt + dw x (y0 - c) + ds (y0 - c)

whose 7 x 7 covariance (dt m, dw rad, ds) is the inverse normal matrix with the a-priori
variance factor 1 (the stated sigmas are taken as honest; sigma0 and a global test say whether
they are).

Each control point's residual is tested on its own (Baarda's data snooping in 3-D): under the
null hypothesis T_i = v_i^T Q_vv,i^-1 v_i is chi-square with 3 degrees of freedom, Q_vv,i =
S_i - J_i N^-1 J_i^T the cofactor of its residual.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import GeometryError, InputError
from gsgeo.measure.framecov import frame_jacobian
from gsgeo.solve.linalg import FloatArray
from gsgeo.solve.stats import chi2_sf

#: Largest ratio of the second to the first singular value of the centred control below
#: which the points count as collinear (the rotation about their line is undetermined).
COLLINEAR_RATIO = 1e-3
#: Gauss-Newton stops when the update moves no control point by more than this (metres):
#: far below any survey precision, above the rounding of ECEF coordinates (~1e-9 m).
STEP_TOLERANCE_M = 1e-7
MAX_ITERATIONS = 30


def rotation_from_vector(w: ArrayLike) -> FloatArray:
    """Rotation matrix (3, 3) of a rotation vector w (radians; axis w / |w|), Rodrigues."""
    v = np.asarray(w, dtype=np.float64).reshape(3)
    a = float(np.linalg.norm(v))
    k = np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])
    if a < 1e-12:
        return np.eye(3) + k + 0.5 * k @ k
    return np.eye(3) + math.sin(a) / a * k + (1.0 - math.cos(a)) / a**2 * k @ k


@dataclass(frozen=True, eq=False)
class Similarity:
    """y = scale * rotation @ x + translation (ECEF to ECEF, metres)."""

    scale: float
    rotation: FloatArray
    translation: FloatArray

    def apply(self, points: ArrayLike) -> FloatArray:
        """Points (..., 3) mapped, metres."""
        p = np.asarray(points, dtype=np.float64)
        return self.scale * p @ self.rotation.T + self.translation

    def matrix(self) -> FloatArray:
        """The 4 x 4 affine matrix (row-major numpy)."""
        m = np.eye(4)
        m[:3, :3] = self.scale * self.rotation
        m[:3, 3] = self.translation
        return m

    def inverse(self) -> Similarity:
        r = self.rotation.T
        return Similarity(1.0 / self.scale, r, -(r @ self.translation) / self.scale)

    @classmethod
    def from_matrix(cls, m: ArrayLike) -> Similarity:
        """The similarity of a 4 x 4 affine matrix whose linear part is s R (InputError if not)."""
        a = np.asarray(m, dtype=np.float64).reshape(4, 4)
        lin = a[:3, :3]
        det = float(np.linalg.det(lin))
        if not det > 0:
            raise InputError("the matrix mirrors or collapses space (determinant <= 0)")
        s = det ** (1.0 / 3.0)
        u, _, vt = np.linalg.svd(lin / s)
        r = u @ vt
        if not np.allclose(lin / s, r, atol=1e-6):
            raise InputError("the matrix is not a rotation with a uniform scale")
        return cls(s, r, a[:3, 3].copy())


def closed_form(src: FloatArray, dst: FloatArray, weights: FloatArray) -> Similarity:
    """Weighted closed-form similarity src -> dst (Umeyama): (N, 3) points, (N,) weights."""
    w = weights / weights.sum()
    ms, md = w @ src, w @ dst
    xs, yd = src - ms, dst - md
    cross = (yd * w[:, None]).T @ xs
    u, d, vt = np.linalg.svd(cross)
    fix = np.diag([1.0, 1.0, float(np.sign(np.linalg.det(u) * np.linalg.det(vt)) or 1.0)])
    r = u @ fix @ vt
    var_s = float(w @ np.einsum("ij,ij->i", xs, xs))
    s = float(np.trace(np.diag(d) @ fix)) / var_s
    return Similarity(s, r, md - s * r @ ms)


@dataclass
class SimilarityFit:
    """A fitted similarity with its uncertainty and the control's residuals.

    residuals (N, 3): measured-and-mapped minus control, ECEF metres. residual_cofactor (N, 3, 3)
    Q_vv,i; combined (N, 3, 3) S_i. test (N,) T_i (NaN where a residual cannot be tested,
    e.g. with 3 points), p (N,) its chi-square(3) upper-tail probability.
    """

    similarity: Similarity
    centre: FloatArray  # (3,) c in the new frame
    covariance: FloatArray  # (7, 7) of (dt, dw, ds) about centre
    residuals: FloatArray
    residual_cofactor: FloatArray
    combined: FloatArray
    test: FloatArray
    p: FloatArray
    vtpv: float
    dof: int
    iterations: int

    @property
    def sigma0(self) -> float:
        return math.sqrt(self.vtpv / self.dof) if self.dof > 0 else math.nan

    @property
    def global_p(self) -> float:
        return float(chi2_sf(self.vtpv, self.dof)) if self.dof > 0 else math.nan

    def scale_sigma(self) -> float:
        return self.similarity.scale * math.sqrt(max(self.covariance[6, 6], 0.0))

    def rotation_sigma_rad(self) -> FloatArray:
        return np.sqrt(np.clip(np.diag(self.covariance)[3:6], 0.0, None))


def check_layout(dst: FloatArray, what: str = "control points") -> None:
    """GeometryError unless there are >= 3 points not on one line."""
    n = dst.shape[0]
    if n < 3:
        raise GeometryError(f"a similarity needs at least 3 {what} (scale, rotation and "
                            f"translation); {n} usable")
    sv = np.linalg.svd(dst - dst.mean(axis=0), compute_uv=False)
    if not sv[0] > 0 or sv[1] / sv[0] < COLLINEAR_RATIO:
        raise GeometryError(f"the {n} {what} lie (nearly) on one line: the rotation about "
                            "it is undetermined; add points off that line")


def fit_similarity(src: ArrayLike, dst: ArrayLike, cov_src: ArrayLike,
                   cov_dst: ArrayLike) -> SimilarityFit:
    """Weighted LS similarity from src (N, 3) to dst (N, 3), covariances (N, 3, 3) m².

    Raises GeometryError for fewer than 3 points or a (nearly) collinear layout and
    InputError for non-finite input or a covariance that is not positive definite.
    """
    x = np.asarray(src, dtype=np.float64).reshape(-1, 3)
    y = np.asarray(dst, dtype=np.float64).reshape(-1, 3)
    cx = np.asarray(cov_src, dtype=np.float64).reshape(-1, 3, 3)
    cy = np.asarray(cov_dst, dtype=np.float64).reshape(-1, 3, 3)
    n = x.shape[0]
    if not (y.shape[0] == n == cx.shape[0] == cy.shape[0]):
        raise InputError("src, dst and their covariances must have one row per point")
    if not (np.isfinite(x).all() and np.isfinite(y).all() and np.isfinite(cx).all()
            and np.isfinite(cy).all()):
        raise InputError("control coordinates and covariances must be finite")
    check_layout(y)
    check_layout(x, "measured control points")
    w0 = 1.0 / np.maximum(np.trace(cy, axis1=1, axis2=2) + np.trace(cx, axis1=1, axis2=2),
                          1e-12)
    sim = closed_form(x, y, w0)
    c = (w0 / w0.sum()) @ y
    it = 0
    for it in range(1, MAX_ITERATIONS + 1):  # noqa: B007 (reported)
        y0, weights, j, normal, rhs, combined = _system(sim, x, y, cx, cy, c)
        try:
            step = np.linalg.solve(normal, rhs)
        except np.linalg.LinAlgError:
            raise GeometryError("the control points do not determine the similarity "
                                "(singular normal equations)") from None
        rot = rotation_from_vector(step[3:6])
        k = 1.0 + step[6]
        sim = Similarity(sim.scale * k, rot @ sim.rotation,
                         k * rot @ (sim.translation - c) + c + step[:3])
        reach = float(np.abs(y0 - c).max())
        moved = (np.abs(step[:3]).max() + (np.linalg.norm(step[3:6]) + abs(step[6])) * reach)
        if moved < STEP_TOLERANCE_M:
            break
    y0, weights, j, normal, _, combined = _system(sim, x, y, cx, cy, c)
    cov = np.linalg.inv(normal)
    cov = 0.5 * (cov + cov.T)
    v = y0 - y
    vtpv = float(np.einsum("ni,nij,nj->", v, weights, v))
    q = combined - np.einsum("nik,kl,njl->nij", j, cov, j)
    test = np.full(n, math.nan)
    for i in range(n):  # N is small (control points)
        ev = np.linalg.eigvalsh(q[i])
        if ev[0] > 1e-6 * ev[-1]:
            test[i] = float(v[i] @ np.linalg.solve(q[i], v[i]))
    p = np.where(np.isfinite(test), chi2_sf(np.nan_to_num(test), 3), np.nan)
    return SimilarityFit(sim, c, cov, v, q, combined, test, p, vtpv, 3 * n - 7, it)


def _system(sim: Similarity, x: FloatArray, y: FloatArray, cx: FloatArray, cy: FloatArray,
            c: FloatArray) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray, FloatArray,
                                    FloatArray]:
    """Mapped points, weights, Jacobian, normal matrix, right-hand side, combined covariance."""
    y0 = sim.apply(x)
    a = sim.scale * sim.rotation
    combined = cy + np.einsum("ik,nkl,jl->nij", a, cx, a)
    weights = np.linalg.inv(combined)
    j = frame_jacobian(y0, c)
    jw = np.einsum("nki,nkl->nil", j, weights)
    normal = np.einsum("nil,nlj->ij", jw, j)
    rhs = np.einsum("nil,nl->i", jw, y - y0)
    return y0, weights, j, normal, rhs, combined
