"""gsgeo.solve: recovery, covariance calibration, outliers, bad input, batch against single."""

from __future__ import annotations

import numpy as np
import pytest

from gsgeo.errors import GeometryError, InputError
from gsgeo.solve import SCALE_95_3D, intersect, intersect_batch
from gsgeo.solve.simulate import TRUTH_ECEF, aim_with_noise, camera_network, perpendicular_basis

IFOV = 2 * np.tan(np.radians(30)) / 1080  # 60 degree vertical field of view on 1080 px


def _unit(v):
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v, axis=-1, keepdims=True)


# --- exact recovery ---------------------------------------------------------------------------


@pytest.mark.parametrize("ifov", [None, IFOV])
@pytest.mark.parametrize("n", [2, 3, 5, 10])
def test_noise_free_rays_recover_ecef_point(rng, n, ifov):
    o, d = camera_network(rng, 1, n)
    scale = rng.uniform(0.01, 1000.0, (1, n, 1))  # directions need not be unit length
    res = intersect(o[0], d[0] * scale[0], ifov=ifov)
    assert np.linalg.norm(res.point - TRUTH_ECEF) < 1e-6
    assert res.dof == 2 * n - 3
    assert np.all(res.residuals_m < 1e-6)
    assert not res.outliers.any()


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("ifov", [None, IFOV])
def test_ray_parallel_to_each_axis(axis, ifov):
    """A ray exactly along a coordinate axis must not lose rank (the paper's two-row form does)."""
    x = np.array([12.0, -7.0, 3.5])
    e = np.eye(3)
    dirs = np.array([e[axis], _unit(e[axis] + e[(axis + 1) % 3]), _unit(e[(axis + 2) % 3] - e[axis])])
    origins = x - 40.0 * dirs
    res = intersect(origins, dirs, ifov=ifov)
    np.testing.assert_allclose(res.point, x, atol=1e-9)
    assert np.all(np.isfinite(res.covariance))
    assert res.condition < 10


def test_two_orthogonal_axis_rays_unweighted_covariance_by_hand():
    """Two rays along x and y through the origin, one offset by 2 cm in z: hand-computed results.

    Normal matrix (I - xx^T) + (I - yy^T) = diag(1, 1, 2); the point is the mean of the two
    z offsets (0.01 m); residuals 0.01 m each; sigma0^2 = 2e-4 / 1; cov = sigma0^2 diag(1, 1, .5).
    """
    origins = np.array([[-10.0, 0.0, 0.0], [0.0, -10.0, 0.02]])
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0]])
    res = intersect(origins, dirs)
    np.testing.assert_allclose(res.point, [0.0, 0.0, 0.01], atol=1e-12)
    np.testing.assert_allclose(res.residuals_m, [0.01, 0.01], rtol=1e-9)
    assert res.dof == 1
    np.testing.assert_allclose(res.sigma0, np.sqrt(2e-4), rtol=1e-9)
    np.testing.assert_allclose(res.covariance, 2e-4 * np.diag([1.0, 1.0, 0.5]), rtol=1e-9, atol=1e-18)
    np.testing.assert_allclose(res.max_angle_deg, 90.0)


def test_angular_model_residuals_in_pixels():
    """Residual in pixels is the perpendicular distance over (ifov x range)."""
    x = np.array([0.0, 0.0, 0.0])
    origins = np.array([[-30.0, 0, 0], [0, -60.0, 0], [0, 0, 90.0]])
    dirs = x - origins
    dirs[1] += [0, 0, 0.1]  # tilt the second ray
    ifov = np.array([1e-3, 2e-3, 5e-4])
    res = intersect(origins, dirs, ifov=ifov)
    du = _unit(dirs)
    rel = res.point - origins
    t = np.einsum("ij,ij->i", rel, du)
    perp = np.linalg.norm(rel - t[:, None] * du, axis=1)
    np.testing.assert_allclose(res.residuals_m, perp, rtol=1e-9)
    np.testing.assert_allclose(res.residuals_px, perp / (ifov * t), rtol=1e-9)
    np.testing.assert_allclose(res.ranges_m, t, rtol=1e-12)


def test_unweighted_covariance_matches_formula(rng):
    o, d = camera_network(rng, 1, 6)
    d = aim_with_noise(rng, _unit(d), IFOV, 2.0)
    res = intersect(o[0], d[0])
    du = _unit(d[0])
    nmat = sum(np.eye(3) - np.outer(k, k) for k in du)
    x = np.linalg.solve(nmat, sum((np.eye(3) - np.outer(k, k)) @ p for k, p in zip(du, o[0], strict=True)))
    np.testing.assert_allclose(res.point, x, atol=1e-6)
    s0sq = np.sum(res.residuals_m**2) / (2 * 6 - 3)
    np.testing.assert_allclose(res.covariance, s0sq * np.linalg.inv(nmat), rtol=1e-6)


# --- Monte-Carlo calibration ------------------------------------------------------------------


@pytest.mark.parametrize("n", [2, 3, 5, 10])
def test_angular_covariance_is_calibrated(n):
    """The 95 % ellipsoid (scale 2.7955) holds the truth in 95 +/- 1.5 % of trials."""
    rng = np.random.default_rng(1000 + n)
    trials, sigma_px = 5000, 1.0
    o, d = camera_network(rng, trials, n)
    ifov = rng.uniform(0.5, 2.0, (trials, n)) * IFOV  # different zoom per view
    dn = aim_with_noise(rng, _unit(d), ifov, sigma_px)
    res = intersect_batch(o, dn, ifov=ifov, sigma_px=sigma_px)
    assert res.valid.all()
    err = res.points - TRUTH_ECEF
    m2 = np.einsum("mi,mij,mj->m", err, np.linalg.inv(res.covariances), err)
    coverage = np.mean(m2 <= SCALE_95_3D**2)
    assert abs(coverage - 0.95) <= 0.015, coverage
    # sigma0 estimates the ratio of observed to a-priori aiming noise: E[sigma0^2] = 1
    assert abs(np.mean(res.sigma0**2) - 1.0) < 0.05
    # a single call agrees with the batch rows (the batch is the same rule)
    for i in range(3):
        one = intersect(o[i], dn[i], ifov=ifov[i], sigma_px=sigma_px)
        np.testing.assert_allclose(one.covariance, res.covariances[i], rtol=1e-9)


def test_angular_covariance_follows_sigma_px():
    """Noise of 0.5 px aimed with sigma_px = 0.5 is as calibrated as 1 px with 1."""
    rng = np.random.default_rng(7)
    trials = 4000
    o, d = camera_network(rng, trials, 5)
    dn = aim_with_noise(rng, _unit(d), IFOV, 0.5)
    res = intersect_batch(o, dn, ifov=IFOV, sigma_px=0.5)
    err = res.points - TRUTH_ECEF
    m2 = np.einsum("mi,mij,mj->m", err, np.linalg.inv(res.covariances), err)
    assert abs(np.mean(m2 <= SCALE_95_3D**2) - 0.95) <= 0.015


# --- outliers ---------------------------------------------------------------------------------


def test_ray_aimed_20px_off_is_flagged():
    rng = np.random.default_rng(11)
    trials, hits, others = 300, 0, 0
    for _ in range(trials):
        o, d = camera_network(rng, 1, 5)
        du = aim_with_noise(rng, _unit(d[0]), IFOV, 1.0)
        bad = rng.integers(5)
        u, v = perpendicular_basis(du[bad])
        ang = rng.uniform(0, 2 * np.pi)
        du[bad] = _unit(du[bad] + np.tan(20 * IFOV) * (np.cos(ang) * u + np.sin(ang) * v))
        res = intersect(o[0], du, ifov=IFOV, sigma_px=1.0)
        hits += bool(res.outliers[bad])
        others += int(res.outliers.sum() - res.outliers[bad])
        assert any("outlier" in w for w in res.warnings) == bool(res.outliers.any())
    # With 1 px noise on the other rays a rare draw makes a good ray look as bad as the gross
    # one (here 1 in 300: removing it leaves an equally small sum of squares), so identification
    # is statistical, not certain.
    assert hits >= 0.99 * trials
    assert others <= 0.02 * trials  # and good rays are rarely dragged with it


def test_clean_five_ray_sets_rarely_flagged():
    rng = np.random.default_rng(12)
    trials, flagged = 1000, 0
    for _ in range(trials):
        o, d = camera_network(rng, 1, 5)
        du = aim_with_noise(rng, _unit(d[0]), IFOV, 1.0)
        flagged += bool(intersect(o[0], du, ifov=IFOV, sigma_px=1.0).outliers.any())
    assert flagged < 0.05 * trials


def test_unweighted_model_flags_gross_ray():
    """Without ifov the test estimates sigma from the other rays (F test)."""
    rng = np.random.default_rng(13)
    hits = 0
    for _ in range(100):
        o, d = camera_network(rng, 1, 8, rmin=50, rmax=60)
        du = aim_with_noise(rng, _unit(d[0]), IFOV, 1.0)
        u, _ = perpendicular_basis(du[3])
        du[3] = _unit(du[3] + np.tan(30 * IFOV) * u)
        res = intersect(o[0], du)
        hits += bool(res.outliers[3]) and res.outliers.sum() == 1
    assert hits >= 95


def test_flagged_ray_is_kept_in_solution(rng):
    o, d = camera_network(rng, 1, 5)
    du = aim_with_noise(rng, _unit(d[0]), IFOV, 1.0)
    u, _ = perpendicular_basis(du[0])
    du[0] = _unit(du[0] + np.tan(50 * IFOV) * u)
    res = intersect(o[0], du, ifov=IFOV)
    without = intersect(o[0][1:], du[1:], ifov=IFOV)
    assert res.outliers[0]
    assert np.linalg.norm(res.point - without.point) > 1e-4  # the ray still pulls the point
    assert any("scaled up" in w for w in res.warnings)  # and the global test noticed it


# --- bad input --------------------------------------------------------------------------------

GOOD_O = np.array([[-10.0, 0, 0], [0, -10.0, 0], [0, 0, 10.0]])
GOOD_D = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, -1.0]])


@pytest.mark.parametrize(
    ("origins", "directions", "kwargs", "exc", "words"),
    [
        (GOOD_O[:1], GOOD_D[:1], {}, GeometryError, "at least 2 rays"),
        (np.empty((0, 3)), np.empty((0, 3)), {}, GeometryError, "at least 2 rays"),
        (np.where(np.eye(3, dtype=bool), np.nan, GOOD_O), GOOD_D, {}, InputError, "NaN"),
        (GOOD_O, np.vstack([GOOD_D[:2], [np.inf, 0, 0]]), {}, InputError, "infinite"),
        (GOOD_O, np.vstack([GOOD_D[:2], [0, 0, 0]]), {}, InputError, "zero-length direction"),
        (GOOD_O[:, :2], GOOD_D[:, :2], {}, InputError, "N x 3"),
        (GOOD_O, GOOD_D[:2], {}, InputError, "N x 3"),
        ([["a", 1, 2]] * 2, GOOD_D[:2], {}, InputError, "numbers"),
        (GOOD_O, GOOD_D, {"ifov": -1e-3}, InputError, "ifov"),
        (GOOD_O, GOOD_D, {"ifov": [1e-3, 1e-3]}, InputError, "ifov"),
        (GOOD_O, GOOD_D, {"ifov": 1e-3, "sigma_px": 0}, InputError, "sigma_px"),
        (GOOD_O, GOOD_D, {"sigma_px": float("nan")}, InputError, "sigma_px"),
    ],
)
def test_bad_input_raises_clear_error(origins, directions, kwargs, exc, words):
    with pytest.raises(exc, match=words):
        intersect(origins, directions, **kwargs)


def test_parallel_rays_are_an_error():
    o = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    d = np.array([[0.0, 1, 0]] * 3)
    with pytest.raises(GeometryError, match="parallel"):
        intersect(o, d)


def test_near_parallel_rays_are_an_error_and_facing_rays_too():
    a = np.radians(0.05)  # below the 0.1 degree limit
    o = np.array([[0.0, 0, 0], [0.5, 0, 0]])
    d = np.array([[0.0, 1, 0], [-np.sin(a), np.cos(a), 0]])
    with pytest.raises(GeometryError, match="parallel"):
        intersect(o, d)
    # two cameras facing each other along one line are as degenerate
    o = np.array([[0.0, -10, 0], [0.0, 10, 0.001]])
    d = np.array([[0.0, 1, 0], [0.0, -1, 0]])
    with pytest.raises(GeometryError, match="parallel"):
        intersect(o, d)


def test_weak_geometry_is_a_warning():
    a = np.radians(1.0)
    o = np.array([[0.0, -100, 0], [100 * np.sin(a), -100 * np.cos(a), 0]])
    d = -o
    res = intersect(o, d)
    np.testing.assert_allclose(res.point, 0, atol=1e-9)
    assert any("weak geometry" in w for w in res.warnings)
    assert not any("weak" in w for w in intersect(GOOD_O, GOOD_D).warnings)


def test_point_behind_a_camera_is_an_error():
    o = np.array([[-10.0, 0, 0], [0, -10.0, 0], [0, 0, 10.0]])
    d = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1.0]])  # third camera looks away
    with pytest.raises(GeometryError, match=r"behind the camera of ray\(s\) 3"):
        intersect(o, d)


# --- batch ------------------------------------------------------------------------------------


@pytest.mark.parametrize("ifov", [None, "per-ray"])
def test_batch_equals_single(rng, ifov):
    m, n = 40, 4
    o, d = camera_network(rng, m, n)
    f = rng.uniform(0.5, 2, (m, n)) * IFOV
    dn = aim_with_noise(rng, _unit(d), f, 1.5)
    fb = None if ifov is None else f
    batch = intersect_batch(o, dn, ifov=fb, sigma_px=1.3)
    for i in range(m):
        one = intersect(o[i], dn[i], ifov=None if fb is None else f[i], sigma_px=1.3)
        np.testing.assert_allclose(
            batch.points[i] - TRUTH_ECEF, one.point - TRUTH_ECEF, rtol=1e-9, atol=1e-12
        )
        np.testing.assert_allclose(batch.covariances[i], one.covariance, rtol=1e-9, atol=1e-20)
        np.testing.assert_allclose(batch.sigma0[i], one.sigma0, rtol=1e-9)
        np.testing.assert_allclose(batch.residuals_m[i], one.residuals_m, rtol=1e-9, atol=1e-15)
        if fb is not None:
            np.testing.assert_allclose(batch.residuals_px[i], one.residuals_px, rtol=1e-9, atol=1e-12)


def test_batch_against_independent_least_squares(rng):
    """Stack the 2N observation equations per point and solve with numpy's lstsq."""
    m, n = 25, 5
    o, d = camera_network(rng, m, n)
    dn = aim_with_noise(rng, _unit(d), IFOV, 1.0)
    batch = intersect_batch(o, dn)
    for i in range(m):
        u, v = perpendicular_basis(dn[i])
        a = np.concatenate([u, v])
        rel = o[i] - TRUTH_ECEF
        b = np.concatenate([np.einsum("ij,ij->i", u, rel), np.einsum("ij,ij->i", v, rel)])
        x, *_ = np.linalg.lstsq(a, b, rcond=None)
        np.testing.assert_allclose(batch.points[i] - TRUTH_ECEF, x, atol=1e-7)


def test_batch_marks_degenerate_rows_invalid(rng):
    o, d = camera_network(rng, 3, 3)
    d = _unit(d)
    d[1] = d[1, 0]  # all three rays parallel
    o[2, 0] = TRUTH_ECEF + 5 * d[2, 0]  # point behind the first camera
    res = intersect_batch(o, d)
    assert res.valid.tolist() == [True, False, False]
    assert np.isnan(res.points[1:]).all()
    np.testing.assert_allclose(res.points[0], TRUTH_ECEF, atol=1e-6)


@pytest.mark.parametrize(
    ("mutate", "words"),
    [
        (lambda o, d: (o[:, :1], d[:, :1]), "at least 2 rays"),
        (lambda o, d: (o, d.__setitem__((2, 1), [0, 0, 0]) or d), "point 2 has a ray with a zero-length"),
        (lambda o, d: (o.__setitem__((4, 0, 0), np.nan) or o, d), "point 4 has rays with NaN"),
        (lambda o, d: (o[0], d[0]), "M x N x 3"),
    ],
)
def test_batch_bad_input(rng, mutate, words):
    o, d = camera_network(rng, 6, 3)
    with pytest.raises(InputError, match=words):
        intersect_batch(*mutate(o, d))
