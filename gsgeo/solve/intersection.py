"""Multi-ray spatial intersection: one point (`intersect`) or millions (`intersect_batch`).

Two stochastic models (README, "The solver"):

Unweighted (``ifov=None``), the paper's
    Minimises sum d_i^2, d_i the perpendicular distance of the point to ray i.
    dof = 2N - 3, sigma0^2 = sum d_i^2 / dof (metres), covariance = sigma0^2 (sum(I - d d^T))^-1.
    With no a-priori precision this a-posteriori covariance is all there is; with dof = 1
    (two rays) it rests on one redundant number and is only indicative.

Angular (``ifov`` given, radians per pixel)
    Ray i has metric precision sigma_i = sigma_px * ifov_i * range_i and weight 1 / sigma_i^2,
    iterated because the ranges depend on the point. sigma0 = sqrt(sum w d^2 / dof) is the ratio
    of the observed to the a-priori aiming precision (1 when sigma_px is honest).

    Rule for the covariance: the a-priori covariance (sum w_i (I - d d^T))^-1 is reported, since
    with the few redundant observations of a point (dof = 1 for two rays, 7 for five) sigma0
    is too uncertain to rescale by. Only when the global test rejects sigma0 = 1 (chi-square,
    upper tail at 1 %) is the covariance scaled by sigma0^2, and a warning says the aiming
    scatter exceeds sigma_px. This keeps the 95 % ellipsoid calibrated when sigma_px is right
    and never optimistic when it is not.

Input checks: fewer than two rays, non-finite numbers, an origin more than
``gsgeo.limits.MAX_ORIGIN_M`` from the frame's origin, a direction that is zero or whose length
is outside [DIRECTION_MIN, DIRECTION_MAX] (too small or too large to normalise), or sigma_px /
ifov outside their ranges (gsgeo.limits) raise :class:`~gsgeo.errors.InputError`; rays whose
largest intersection angle is below ``PARALLEL_LIMIT_DEG`` (0.1 degrees, where the depth
error is 570 times the lateral one), or a point behind any camera (range <= 0), raise
:class:`~gsgeo.errors.GeometryError`; a largest intersection angle below
``WEAK_GEOMETRY_DEG`` (2 degrees) is a warning.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from gsgeo import limits
from gsgeo.errors import GeometryError, InputError
from gsgeo.solve.core import solve_core, solve_one, unit_directions
from gsgeo.solve.outliers import snoop
from gsgeo.solve.sharedaim import (
    AUTO_UNWEIGHTED,
    aim_scales,
    reference_rays,
    shared_aim_covariance,
)
from gsgeo.solve.stats import chi2_sf

#: Largest intersection angle (degrees) below which rays count as parallel: an error.
PARALLEL_LIMIT_DEG = 0.1
#: Largest intersection angle (degrees) below which the geometry is weak: a warning.
WEAK_GEOMETRY_DEG = 2.0
#: Level of the global test of sigma0 in the angular model (upper tail).
GLOBAL_TEST_ALPHA = 0.01
#: Points per chunk in `intersect_batch`: keeps the working arrays in cache.
BATCH_CHUNK = 8192


@dataclass
class IntersectionResult:
    """One intersected point, in the Cartesian frame of the input rays (metres)."""

    point: np.ndarray
    covariance: np.ndarray
    sigma0: float
    dof: int
    residuals_m: np.ndarray
    residuals_px: np.ndarray | None
    rms_m: float
    max_angle_deg: float
    condition: float
    outliers: np.ndarray
    warnings: list[str] = field(default_factory=list)
    ranges_m: np.ndarray | None = None
    outlier_ratio: np.ndarray | None = None
    model: str = "unweighted"
    iterations: int = 1

    @property
    def sigmas(self) -> np.ndarray:
        """1-sigma standard deviations along the frame's axes (metres)."""
        return np.sqrt(np.diag(self.covariance))

    def to_dict(self) -> dict:
        """Plain JSON-ready dictionary (lists and floats)."""

        def arr(a: npt.ArrayLike | None) -> object:
            return None if a is None else np.asarray(a, dtype=float).tolist()

        return {
            "point": arr(self.point),
            "covariance": arr(self.covariance),
            "sigmas": arr(self.sigmas),
            "sigma0": float(self.sigma0),
            "dof": int(self.dof),
            "residuals_m": arr(self.residuals_m),
            "residuals_px": arr(self.residuals_px),
            "rms_m": float(self.rms_m),
            "max_angle_deg": float(self.max_angle_deg),
            "condition": float(self.condition),
            "outliers": [bool(x) for x in self.outliers],
            "warnings": list(self.warnings),
            "ranges_m": arr(self.ranges_m),
            "model": self.model,
        }


@dataclass
class BatchResult:
    """M intersected points of N rays each (frame of the input, metres).

    Rows whose geometry cannot be intersected (parallel rays, a point behind a camera) are
    NaN with ``valid`` False rather than failing a million-point batch.
    """

    points: np.ndarray  # (M, 3)
    covariances: np.ndarray  # (M, 3, 3)
    sigma0: np.ndarray  # (M,)
    dof: int
    residuals_m: np.ndarray  # (M, N)
    residuals_px: np.ndarray | None  # (M, N)
    valid: np.ndarray  # (M,) bool


def _as_rays(origins: npt.ArrayLike, directions: npt.ArrayLike) -> tuple[np.ndarray, np.ndarray]:
    try:
        o = np.asarray(origins, dtype=np.float64)
        d = np.asarray(directions, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise InputError(f"ray origins and directions must be numbers: {exc}") from None
    return o, d


def _check_ifov(ifov: npt.ArrayLike | None, shape: tuple[int, ...]) -> np.ndarray | None:
    if ifov is None:
        return None
    try:
        f = np.asarray(ifov, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError("ifov must be a number (radians per pixel) or one per ray") from None
    try:
        f = np.broadcast_to(f, shape)
    except ValueError:
        raise InputError(
            f"ifov must be a scalar or one value per ray; got shape {np.shape(ifov)} "
            f"for rays of shape {shape}"
        ) from None
    if not np.all(np.isfinite(f)) or np.any(f <= 0):
        raise InputError("ifov (radians per pixel) must be positive and finite for every ray")
    if np.any(f < limits.IFOV_MIN) or np.any(f > limits.IFOV_MAX):
        raise InputError(f"ifov must be between {limits.IFOV_MIN:g} and {limits.IFOV_MAX:g} "
                         "radians per pixel for every ray")
    return f


def _check_sigma_px(sigma_px: float) -> float:
    try:
        s = float(sigma_px)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"sigma_px must be a number of pixels, got {str(sigma_px)[:40]}") from None
    return limits.sigma_px(s, minimum=limits.SOLVER_SIGMA_PX_MIN)


def _check_ranges(o: np.ndarray, d: np.ndarray, norm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Masks (...) of rays whose origin is out of range and whose direction cannot be
    normalised; o, d (..., 3) finite, ``norm`` their directions' plainly computed lengths.

    Out of these ranges the squares in the normal equations overflow or underflow, and
    would surface as a false "zero-length" or "behind the camera".
    """
    box = limits.MAX_ORIGIN_M / math.sqrt(3)  # inside this cube every origin is in range
    if o.size and max(-float(o.min()), float(o.max())) <= box:  # the usual case: two reductions
        far = np.zeros(o.shape[:-1], dtype=bool)
    else:
        far = np.abs(o).max(axis=-1) > box
        if far.any():  # the exact (scaled) length decides for the few candidates
            far[far] = np.hypot.reduce(o[far], axis=-1) > limits.MAX_ORIGIN_M
    if norm.size and norm.min() >= limits.DIRECTION_MIN and norm.max() <= limits.DIRECTION_MAX:
        return far, np.zeros(norm.shape, dtype=bool)
    return far, ~((norm >= limits.DIRECTION_MIN) & (norm <= limits.DIRECTION_MAX))


def _direction_message(d: np.ndarray, bad: np.ndarray) -> str:
    """The problem of the first bad direction (zero, too small or too large), naming the rays."""
    zero = ~np.any(d != 0, axis=-1)
    if zero.any():
        return f"ray(s) {_list(zero)} have a zero-length direction"
    first = d[np.flatnonzero(bad)[0]]
    return f"ray(s) {_list(bad)} have a direction {limits.direction_problem(first)}"


def intersection_angles(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Largest angle between two rays and largest intersection angle, in degrees.

    d : unit directions (..., N, 3). The angle between two rays is in [0, 180]; the
    intersection angle folds it to [0, 90] (rays facing each other are as weak as parallel
    ones), and is what decides whether the point is determined in depth.
    """
    g = np.clip(np.einsum("...ki,...li->...kl", d, d), -1.0, 1.0)
    n = d.shape[-2]
    iu = np.triu_indices(n, 1)
    cos_pairs = g[..., iu[0], iu[1]]
    max_angle = np.degrees(np.arccos(cos_pairs.min(axis=-1)))
    max_isect = np.degrees(np.arccos(np.abs(cos_pairs).min(axis=-1)))
    return max_angle, max_isect


_COS_PARALLEL = math.cos(math.radians(PARALLEL_LIMIT_DEG))


def _min_abs_cos(d: np.ndarray) -> np.ndarray:
    """Smallest |cos| over all pairs of rays of each point (M, N, 3) -> (M,).

    The loop runs over the N (N - 1) / 2 ray pairs, each step vectorised over all points.
    """
    dx, dy, dz = d[..., 0], d[..., 1], d[..., 2]
    n = d.shape[1]
    best = np.full(d.shape[0], np.inf)
    for i in range(n - 1):
        for j in range(i + 1, n):
            c = np.abs(dx[:, i] * dx[:, j] + dy[:, i] * dy[:, j] + dz[:, i] * dz[:, j])
            np.minimum(best, c, out=best)
    return best


def intersect(
    origins: npt.ArrayLike,
    directions: npt.ArrayLike,
    *,
    ifov: npt.ArrayLike | None = None,
    sigma_px: float = 1.0,
    auto: npt.ArrayLike | None = None,
) -> IntersectionResult:
    """Least-squares intersection of N >= 2 rays in one Cartesian frame.

    Parameters
    ----------
    origins : (N, 3) camera centres, metres.
    directions : (N, 3) ray directions in the same frame; any non-zero length.
    ifov : None for the unweighted model, or the angular size of a pixel in radians, scalar
        or one per ray, for the angular model.
    sigma_px : a-priori aiming precision in pixels (angular model only).
    auto : None, or (N,) bool: rays matched automatically to the first ray not marked auto
        (auto-aim). In the angular model they are weighted by their match precision and share
        that reference's aiming error (gsgeo.solve.sharedaim).

    Returns
    -------
    IntersectionResult: point and covariance (m, m^2) in the input frame, residuals in metres
    and (angular model) pixels, outlier flags and warnings.

    Raises
    ------
    InputError, GeometryError with a message naming the problem.
    """
    o, d = _as_rays(origins, directions)
    if o.ndim != 2 or o.shape[-1] != 3 or d.shape != o.shape:
        raise InputError(
            "origins and directions must both be N x 3 arrays "
            f"(got {o.shape} and {d.shape})"
        )
    n = o.shape[0]
    if n < 2:
        raise GeometryError(f"a point needs at least 2 rays; got {n}")
    bad = ~np.all(np.isfinite(o), axis=1) | ~np.all(np.isfinite(d), axis=1)
    if bad.any():
        raise InputError(f"ray(s) {_list(bad)} contain NaN or infinite numbers")
    du, norm = unit_directions(d)
    far, bad_d = _check_ranges(o, d, norm)
    if far.any():
        r = float(np.hypot.reduce(o[np.flatnonzero(far)[0]]))
        raise InputError(f"ray(s) {_list(far)}: origin out of range, {r:.3g} m from the frame's "
                         f"origin (more than {limits.MAX_ORIGIN_M:g} m)")
    if bad_d.any():
        raise InputError(_direction_message(d, bad_d))
    f = _check_ifov(ifov, (n,))
    s_px = _check_sigma_px(sigma_px)
    au = None if auto is None else np.asarray(auto, dtype=bool)
    if au is not None and au.shape != (n,):
        raise InputError(f"auto must give one flag per ray ({n}), got shape {au.shape}")
    scales = None if f is None else aim_scales(au, (n,), s_px)
    f_w = f if f is None or scales is None else f * scales  # weights: sigma_px x this x range

    max_angle, max_isect = intersection_angles(du)
    if max_isect < PARALLEL_LIMIT_DEG:
        raise GeometryError(
            f"the rays are (nearly) parallel: their largest intersection angle is "
            f"{max_isect:.3g} degrees, below {PARALLEL_LIMIT_DEG} degrees; aim from "
            "viewpoints further apart"
        )
    sol = solve_one(o, du, f_w, s_px)
    ranges = sol.ranges[0]
    behind = ~(ranges > 0)
    if behind.any():
        raise GeometryError(
            f"the intersection lies behind the camera of ray(s) {_list(behind)}; "
            "the rays do not aim at one feature"
        )
    dof = 2 * n - 3
    warnings: list[str] = []
    if max_isect < WEAK_GEOMETRY_DEG:
        warnings.append(
            f"weak geometry: the largest intersection angle is {max_isect:.2f} degrees "
            f"(below {WEAK_GEOMETRY_DEG:g}); the depth is poorly determined"
        )
    ninv = sol.normal_inverse[0]
    vtpv = float(sol.vtpv[0])
    sigma0 = math.sqrt(vtpv / dof)
    res_m = sol.residuals_m[0]
    res_px = None
    apriori = ninv
    if au is not None and reference_rays(au[None])[1][0]:
        if f_w is None:
            warnings.append(AUTO_UNWEIGHTED)
        else:
            apriori = shared_aim_covariance(sol.points, o[None], du[None], f_w[None], s_px,
                                            np.ones((1, n), dtype=bool), au[None],
                                            sol.normal_inverse)[0]
    if f is None:
        model = "unweighted"
        cov = sigma0**2 * ninv
        weights = sigma_m = None
    else:
        model = "angular"
        # The angular model always returns weights and a-priori sigmas.
        assert sol.weights is not None and sol.sigma_m is not None
        weights, sigma_m = sol.weights[0], sol.sigma_m[0]
        res_px = res_m / (f * ranges)
        p = float(chi2_sf(vtpv, dof))
        if p < GLOBAL_TEST_ALPHA:
            cov = sigma0**2 * apriori
            warnings.append(
                f"the aiming scatter is {sigma0:.2f} times sigma_px = {s_px:g} px "
                f"(global test p = {p:.2g}); the covariance is scaled up accordingly"
            )
        else:
            cov = apriori.copy()
    eig = np.linalg.eigvalsh(ninv)  # the inverse has the same condition number
    condition = float(eig[-1] / eig[0]) if eig[0] > 0 else math.inf
    flags, ratios = snoop(o, du, weights, sigma_m)
    if flags.any():
        warnings.append(
            f"ray(s) {_list(flags)} look like outliers (data snooping at 0.1 %); "
            "check the aim or exclude them"
        )
    return IntersectionResult(
        point=sol.points[0],
        covariance=cov,
        sigma0=sigma0,
        dof=dof,
        residuals_m=res_m,
        residuals_px=res_px,
        rms_m=float(math.sqrt(np.mean(res_m**2))),
        max_angle_deg=float(max_angle),
        condition=condition,
        outliers=flags,
        warnings=warnings,
        ranges_m=ranges,
        outlier_ratio=ratios,
        model=model,
        iterations=sol.iterations,
    )


def _list(mask: np.ndarray) -> str:
    """1-based ray numbers of a mask, as a surveyor counts them."""
    return ", ".join(str(i + 1) for i in np.flatnonzero(mask))


def _chi2_quantile(p: float, dof: int) -> float:
    """Upper quantile of chi-square(dof): the x with P(X > x) = 1 - p (bisection)."""
    lo, hi = 0.0, max(10.0, 10.0 * dof)
    while chi2_sf(hi, dof) > 1 - p:
        hi *= 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if chi2_sf(mid, dof) > 1 - p:
            lo = mid
        else:
            hi = mid
    return 0.5 * (lo + hi)


def intersect_batch(
    origins: npt.ArrayLike,
    directions: npt.ArrayLike,
    *,
    ifov: npt.ArrayLike | None = None,
    sigma_px: float = 1.0,
) -> BatchResult:
    """`intersect` vectorised over M points of N rays each, without a Python loop over points.

    Parameters
    ----------
    origins, directions : (M, N, 3) arrays in one Cartesian frame (metres).
    ifov : None, a scalar, (N,) or (M, N) radians per pixel (angular model).
    sigma_px : a-priori aiming precision in pixels.

    Returns
    -------
    BatchResult with ``points`` (M, 3), ``covariances`` (M, 3, 3), ``sigma0`` (M,),
    ``residuals_m`` and ``residuals_px`` (M, N) and ``valid`` (M,). The covariance rule is that
    of `intersect`; outlier flags are not computed in batch.

    Raises
    ------
    InputError for malformed arrays, fewer than two rays, non-finite numbers or a zero
    direction (naming the first offending point).
    """
    o, d = _as_rays(origins, directions)
    if o.ndim != 3 or o.shape[-1] != 3 or d.shape != o.shape:
        raise InputError(
            f"origins and directions must both be M x N x 3 arrays (got {o.shape} and {d.shape})"
        )
    m, n, _ = o.shape
    if n < 2:
        raise GeometryError(f"a point needs at least 2 rays; got {n}")
    f = _check_ifov(ifov, (m, n))
    s_px = _check_sigma_px(sigma_px)
    dof = 2 * n - 3
    chi2_limit = None if f is None else _chi2_quantile(1.0 - GLOBAL_TEST_ALPHA, dof)

    points = np.empty((m, 3))
    covs = np.empty((m, 3, 3))
    sigma0 = np.empty(m)
    res_m = np.empty((m, n))
    res_px = None if f is None else np.empty((m, n))
    valid = np.empty(m, dtype=bool)
    for start in range(0, m, BATCH_CHUNK):  # chunks of points, each fully vectorised
        sl = slice(start, min(start + BATCH_CHUNK, m))
        oc, dc = o[sl], d[sl]
        if not (np.isfinite(oc).all() and np.isfinite(dc).all()):
            first = start + int(np.flatnonzero(~(np.isfinite(oc) & np.isfinite(dc)).all(axis=(1, 2)))[0])
            raise InputError(f"point {first} has rays with NaN or infinite numbers")
        du, norm = unit_directions(dc)
        far, bad_d = _check_ranges(oc, dc, norm)
        if far.any():
            first = start + int(np.flatnonzero(far.any(axis=1))[0])
            raise InputError(f"point {first} has a ray whose origin is out of range (more than "
                             f"{limits.MAX_ORIGIN_M:g} m from the frame's origin)")
        if bad_d.any():
            k = int(np.flatnonzero(bad_d.any(axis=1))[0])
            first = dc[k][bad_d[k]][0]
            why = ("with a zero-length direction" if not np.any(first != 0) else
                   f"with a direction {limits.direction_problem(first)}")
            raise InputError(f"point {start + k} has a ray {why}")
        fc = None if f is None else f[sl]
        sol = solve_core(oc, du, fc, s_px)
        ok = (_min_abs_cos(du) <= _COS_PARALLEL) & np.all(sol.ranges > 0, axis=1)
        s0sq = sol.vtpv / dof
        if fc is None:
            scale = s0sq
        else:
            scale = np.where(sol.vtpv > chi2_limit, s0sq, 1.0)
            assert res_px is not None  # allocated whenever there is an ifov
            res_px[sl] = sol.residuals_m / (fc * sol.ranges)
        points[sl] = sol.points
        covs[sl] = sol.normal_inverse * scale[:, None, None]
        sigma0[sl] = np.sqrt(s0sq)
        res_m[sl] = sol.residuals_m
        valid[sl] = ok
    bad = ~valid
    if bad.any():
        points[bad] = np.nan
        covs[bad] = np.nan
        sigma0[bad] = np.nan
    return BatchResult(
        points=points,
        covariances=covs,
        sigma0=sigma0,
        dof=dof,
        residuals_m=res_m,
        residuals_px=res_px,
        valid=valid,
    )
