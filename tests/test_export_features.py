"""gsgeo.measure.features: lengths, areas, perimeters and their propagated sigmas."""

from __future__ import annotations

import numpy as np
import pytest

from gsgeo.errors import GeometryError, InputError
from gsgeo.measure.features import line_measures, polygon_measures, ring_self_intersection

E0, N0 = 530_000.0, 180_000.0  # national-grid sized coordinates


def _random_cov(rng, n, scale=0.02):
    a = rng.normal(size=(n, 3, 3)) * scale
    return a @ np.swapaxes(a, 1, 2) + np.eye(3) * (0.2 * scale) ** 2


def _sample(rng, xyz, cov, trials):
    ch = np.linalg.cholesky(cov)  # (N, 3, 3)
    z = rng.normal(size=(trials, xyz.shape[0], 3))
    return xyz + np.einsum("nij,tnj->tni", ch, z)


def _lengths(pts, dims):
    d = np.diff(pts[..., :dims], axis=-2)
    return np.sqrt((d**2).sum(-1)).sum(-1)


def _shoelace(pts):
    x, y = pts[..., 0], pts[..., 1]
    return 0.5 * np.abs((x * np.roll(y, -1, -1) - np.roll(x, -1, -1) * y).sum(-1))


def test_line_lengths_hand_computed():
    xyz = np.array([[E0, N0, 10.0], [E0 + 3, N0 + 4, 10.0], [E0 + 3, N0 + 4, 22.0]])
    m = line_measures(xyz)
    assert m.n_points == 3
    assert m.length_2d == pytest.approx(5.0, abs=1e-9)
    assert m.length_3d == pytest.approx(17.0, abs=1e-9)
    assert m.sigma_length_2d is None and m.sigma_length_3d is None


def test_line_sigma_hand_computed():
    # Two points 10 m apart along E, isotropic 1 cm: sigma_L = sqrt(2) cm.
    xyz = np.array([[E0, N0, 0.0], [E0 + 10, N0, 0.0]])
    cov = np.repeat(np.eye(3)[None] * 1e-4, 2, axis=0)
    m = line_measures(xyz, cov)
    assert m.sigma_length_2d == pytest.approx(np.sqrt(2) * 0.01, rel=1e-9)
    assert m.sigma_length_3d == pytest.approx(np.sqrt(2) * 0.01, rel=1e-9)


def test_line_unknown_height_and_feet():
    xyz = np.array([[0.0, 0.0, np.nan], [3.0, 4.0, 1.0]])
    cov = np.repeat(np.eye(3)[None] * 1e-4, 2, axis=0)
    cov[0, 2, 2] = np.nan
    m = line_measures(xyz, cov, unit_m=0.3048)
    assert m.length_2d == pytest.approx(5 * 0.3048)
    assert m.length_3d is None and m.sigma_length_3d is None
    assert np.isfinite(m.sigma_length_2d)


@pytest.mark.parametrize("trials", [40_000])
def test_line_sigma_monte_carlo(rng, trials):
    xyz = np.array([[E0, N0, 20.0], [E0 + 7, N0 + 2, 21.0], [E0 + 9, N0 + 11, 25.0],
                    [E0 + 2, N0 + 15, 24.0]])
    cov = _random_cov(rng, 4)
    m = line_measures(xyz, cov)
    pts = _sample(rng, xyz, cov, trials)
    # Standard error of a sample std is ~ 1/sqrt(2 trials) = 0.35 %; 2 % leaves room for
    # the linearisation (sigmas of centimetres against segments of metres).
    assert np.std(_lengths(pts, 2)) == pytest.approx(m.sigma_length_2d, rel=0.02)
    assert np.std(_lengths(pts, 3)) == pytest.approx(m.sigma_length_3d, rel=0.02)
    tol = 3 * m.sigma_length_2d / np.sqrt(trials) + 1e-3
    assert np.mean(_lengths(pts, 2)) == pytest.approx(m.length_2d, abs=tol)


def test_polygon_square_hand_computed():
    xyz = np.array([[E0, N0, 5.0], [E0 + 10, N0, 5.0], [E0 + 10, N0 + 10, 5.0], [E0, N0 + 10, 5.0]])
    m = polygon_measures(xyz)
    assert (m.area_2d, m.perimeter_2d, m.n_points, m.counterclockwise) == (100.0, 40.0, 4, True)
    m2 = polygon_measures(xyz[::-1])
    assert m2.area_2d == 100.0 and not m2.counterclockwise
    # An explicitly closed ring gives the same.
    m3 = polygon_measures(np.vstack([xyz, xyz[:1]]))
    assert m3.area_2d == 100.0 and m3.n_points == 4
    # A square of side a with isotropic sigma s per coordinate: dA/dx_i = +-a/2 on two
    # coordinates of each corner -> var = 4 corners * 2 * (a/2)^2 s^2 = 2 a^2 s^2.
    cov = np.repeat(np.eye(3)[None] * 1e-4, 4, axis=0)
    m4 = polygon_measures(xyz, cov)
    assert m4.sigma_area_2d == pytest.approx(np.sqrt(2) * 10 * 0.01, rel=1e-9)


def test_polygon_sigma_monte_carlo(rng):
    xyz = np.array([[E0, N0, 0.0], [E0 + 12, N0 - 1, 0.0], [E0 + 14, N0 + 9, 0.0],
                    [E0 + 5, N0 + 13, 0.0], [E0 - 2, N0 + 6, 0.0]])
    cov = _random_cov(rng, 5, scale=0.05)
    m = polygon_measures(xyz, cov)
    pts = _sample(rng, xyz, cov, 40_000)
    assert np.std(_shoelace(pts)) == pytest.approx(m.sigma_area_2d, rel=0.02)
    closed = np.concatenate([pts, pts[:, :1]], axis=1)
    assert np.std(_lengths(closed, 2)) == pytest.approx(m.sigma_perimeter_2d, rel=0.02)
    assert m.area_2d == pytest.approx(float(_shoelace(xyz)), rel=1e-12)


@pytest.mark.parametrize("pts, match", [
    ([[0, 0, 0], [1, 0, 0]], "at least 3 distinct"),
    ([[0, 0, 0], [1, 0, 0], [0, 0, 0]], "at least 3 distinct"),
    ([[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]], "more than once"),
    ([[0, 0, 0], [2, 2, 0], [2, 0, 0], [0, 2, 0]], "self-intersecting"),  # bow tie
    ([[0, 0, 0], [1, 0, 0], [2, 0, 0]], "self-intersecting|collinear"),
    ([[0, 0, 0], [4, 0, 0], [4, 4, 0], [2, 0, 0], [0, 4, 0]], "self-intersecting"),  # touches
])
def test_polygon_errors(pts, match):
    with pytest.raises(GeometryError, match=match):
        polygon_measures(np.array(pts, dtype=float))


def test_error_names_the_points():
    pts = np.array([[0, 0, 0], [2, 2, 0], [2, 0, 0], [0, 2, 0]], dtype=float)
    with pytest.raises(GeometryError, match="'A'-'B' meets edge 'C'-'D'"):
        polygon_measures(pts, ids=["A", "B", "C", "D"])


def test_line_errors():
    with pytest.raises(GeometryError, match="at least 2 distinct"):
        line_measures(np.array([[1.0, 2.0, 3.0]]))
    with pytest.raises(GeometryError, match="same position"):
        line_measures(np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 4.0]]))
    with pytest.raises(InputError, match="N x 3"):
        line_measures(np.zeros((3, 4)))
    with pytest.raises(InputError, match="finite"):
        line_measures(np.array([[np.nan, 0, 0], [1.0, 0, 0]]))
    with pytest.raises(InputError, match="covariances"):
        line_measures(np.zeros((2, 3)) + [[0, 0, 0], [1, 0, 0]], np.zeros((3, 3, 3)))


def test_self_intersection_simple_rings_pass(rng):
    # Rings sorted by angle about a centre, with every angular gap below 180 degrees, are
    # star-shaped about that centre and therefore simple.
    tested = 0
    for _ in range(200):
        n = int(rng.integers(3, 30))
        ang = np.sort(rng.uniform(0, 2 * np.pi, n))
        gaps = np.diff(np.append(ang, ang[0] + 2 * np.pi))
        if gaps.max() >= np.pi:
            continue
        r = rng.uniform(1, 2, n)
        xy = np.column_stack([E0 + r * np.cos(ang), N0 + r * np.sin(ang)])
        assert ring_self_intersection(xy) is None
        tested += 1
    assert tested > 50
    # Swapping two vertices of a convex ring makes it cross.
    sq = np.array([[0, 0], [1, 0], [1, 1], [0, 1], [-0.5, 0.5]], dtype=float)
    assert ring_self_intersection(sq) is None
    assert ring_self_intersection(sq[[0, 2, 1, 3, 4]]) is not None


def _nan_none(v):
    return np.nan if v is None else v


def test_many_equal_single_feature_results(rng):
    """line_measures_many / polygon_measures_many give line_measures / polygon_measures' values
    (feet, unknown heights and covariances included) and flag exactly the features they reject."""
    from gsgeo.measure.features import line_measures_many, polygon_measures_many

    lines, polys = [], []
    for k in range(60):
        n = int(rng.integers(2, 7))
        xyz = np.column_stack([E0 + rng.normal(0, 20, n), N0 + rng.normal(0, 20, n), rng.normal(50, 5, n)])
        cov = _random_cov(rng, n)
        if k % 7 == 0:
            xyz[0, 2] = np.nan  # unknown height: no 3-D length
        if k % 11 == 0:
            cov[-1, 2, 2] = np.nan  # unknown vertical variance: no 3-D sigma
        lines.append((xyz, cov))
        m = int(rng.integers(3, 9))  # star-shaped rings: simple
        ang = np.sort(rng.uniform(0, 2 * np.pi, m)) if k % 2 else np.linspace(0, 2 * np.pi, m, endpoint=False)
        r = rng.uniform(5, 10, m)
        ring = np.column_stack([E0 + r * np.cos(ang), N0 + r * np.sin(ang), rng.normal(50, 1, m)])
        polys.append((ring if k % 3 else ring[::-1], _random_cov(rng, m)))
    bad_lines = [np.array([[1.0, 2.0, 3.0]]), np.array([[1.0, 2.0, 3.0], [1.0, 2.0, 9.0]])]
    bad_polys = [np.array(p, dtype=float) for p in (
        [[0, 0, 0], [2, 2, 0], [2, 0, 0], [0, 2, 0]], [[0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]],
        [[0, 0, 0], [1, 0, 0], [2, 0, 0]], [[0, 0, 0], [4, 0, 0], [4, 4, 0], [2, 0, 0], [0, 4, 0]],
        [[0, 0, 0], [1, 0, 0]])]
    lines += [(b + [E0, N0, 0], _random_cov(rng, len(b))) for b in bad_lines]
    polys += [(b + [E0, N0, 0], _random_cov(rng, len(b))) for b in bad_polys]
    cov_nan = _random_cov(rng, 3)
    cov_nan[1, 0, 1] = np.nan  # horizontal covariance unknown: an input error
    lines.append((lines[1][0][:2], cov_nan[:2]))
    for unit in (1.0, 0.3048006096012192):
        out, ok = line_measures_many([x for x, _ in lines], [c for _, c in lines], unit_m=unit,
                                     vertical_unit_m=unit)
        assert ok.sum() == 60 and not ok[60:].any()
        for k, (x, c) in enumerate(lines):
            if not ok[k]:
                with pytest.raises((GeometryError, InputError)):
                    line_measures(x, c, unit_m=unit, vertical_unit_m=unit)
                continue
            m = line_measures(x, c, unit_m=unit, vertical_unit_m=unit)
            got = [out.n_points[k], out.length_2d[k], out.sigma_length_2d[k], out.length_3d[k],
                   out.sigma_length_3d[k]]
            want = [m.n_points, m.length_2d, m.sigma_length_2d, _nan_none(m.length_3d),
                    _nan_none(m.sigma_length_3d)]
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=0)
        out, ok = polygon_measures_many([x for x, _ in polys], [c for _, c in polys], unit_m=unit)
        assert ok.sum() == 60 and not ok[60:].any()
        for k, (x, c) in enumerate(polys):
            if not ok[k]:
                with pytest.raises(GeometryError):
                    polygon_measures(x, c, unit_m=unit)
                continue
            m = polygon_measures(x, c, unit_m=unit)
            assert out.counterclockwise[k] == m.counterclockwise == (k % 3 != 0)
            np.testing.assert_allclose(
                [out.n_points[k], out.area_2d[k], out.sigma_area_2d[k], out.perimeter_2d[k],
                 out.sigma_perimeter_2d[k]],
                [m.n_points, m.area_2d, m.sigma_area_2d, m.perimeter_2d, m.sigma_perimeter_2d],
                rtol=1e-12, atol=0)
