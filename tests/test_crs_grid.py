"""to_grid: E, N against direct pyproj, the Jacobian three ways, covariance, operations, errors."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
from pyproj import Transformer

from gsgeo.crs import transformers as tr
from gsgeo.crs.confidence import ellipse_95, ellipsoid_axes_95
from gsgeo.crs.frames import geodetic_to_ecef
from gsgeo.crs.grid import analytic_jacobian, to_grid, to_grid_many
from gsgeo.errors import CRSError, InputError
from gsgeo.solve import SCALE_95_2D, SCALE_95_3D

# pytest resets warning filters per test; gsgeo.crs filters this pyproj message at import.
pytestmark = pytest.mark.filterwarnings("ignore:Best transformation is not available")

# (grid CRS, lon, lat, national geocentric realisation or None)
CASES = [
    ("EPSG:27700", -1.5, 52.5, None),  # OSGB36 / British National Grid
    ("EPSG:25832", 9.5, 50.0, "EPSG:4936"),  # ETRS89 / UTM 32N
    ("EPSG:28992", 5.3, 52.1, None),  # Amersfoort / RD New (oblique stereographic)
    ("EPSG:2056", 8.2, 46.8, None),  # CH1903+ / LV95 (oblique Mercator)
    ("EPSG:7856", 151.2, -33.8, "EPSG:7842"),  # GDA2020 / MGA 56
    ("EPSG:6339", -122.3, 45.0, "EPSG:6317"),  # NAD83(2011) / UTM 10N
    ("EPSG:6350", -100.0, 40.0, "EPSG:6317"),  # NAD83(2011) / Conus Albers
]


def _points(lon, lat, src="EPSG:4978", n=5, seed=3):
    rng = np.random.default_rng(seed)
    return geodetic_to_ecef(lon + rng.uniform(-0.05, 0.05, n), lat + rng.uniform(-0.05, 0.05, n),
                            rng.uniform(-20, 900, n), src)


def test_network_is_off():
    assert not pyproj.network.is_network_enabled()


@pytest.mark.parametrize(("crs", "lon", "lat", "national"), CASES)
def test_easting_northing_equal_direct_pyproj(crs, lon, lat, national):
    for src in ["EPSG:4978"] + ([national] if national else []):
        p = _points(lon, lat, src)
        g = to_grid_many(p, None, crs, source_crs=src)
        e, n, _ = Transformer.from_crs(src, crs, always_xy=True).transform(p[:, 0], p[:, 1], p[:, 2])
        assert np.abs(g.easting - e).max() < 1e-4, (src, g.easting - e)
        assert np.abs(g.northing - n).max() < 1e-4, (src, g.northing - n)


@pytest.mark.parametrize(("crs", "lon", "lat", "national"), CASES)
def test_numerical_and_analytic_jacobians_agree(crs, lon, lat, national):
    src = national or "EPSG:4978"
    p = _points(lon, lat, src)
    num = to_grid_many(p, None, crs, source_crs=src).jacobian
    ana = analytic_jacobian(p, crs, src)
    # A pure conversion agrees to rounding; a datum transformation adds its Helmert scale and
    # rotation (a few 1e-5) to the numerical Jacobian, which the projection factors lack.
    tol = 1e-7 if national else 1e-4
    np.testing.assert_allclose(num, ana, atol=tol)
    # the rows are not trivially equal: E, N rows carry scale factor and convergence
    assert np.abs(num[:, :2, :] - np.eye(3)[:2]).max() > 0.1


@pytest.mark.parametrize(("crs", "lon", "lat", "national"), CASES[:4])
def test_jacobian_matches_brute_force_differences_through_pyproj(crs, lon, lat, national):
    """Independent: central differences in ECEF through PROJ's own 4978 -> grid pipeline."""
    p = _points(lon, lat, n=2)
    jac = to_grid_many(p, None, crs).jacobian
    t = Transformer.from_crs("EPSG:4978", crs, always_xy=True)
    th = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)
    step = 0.5
    for i in range(3):
        dp = np.zeros(3)
        dp[i] = step
        ep, np_, _ = t.transform(*(p + dp).T)
        em, nm, _ = t.transform(*(p - dp).T)
        hp = th.transform(*(p + dp).T)[2]
        hm = th.transform(*(p - dp).T)[2]
        col = np.stack([(ep - em), (np_ - nm), (hp - hm)], axis=1) / (2 * step)
        np.testing.assert_allclose(jac[:, :, i], col, atol=2e-6)


def test_covariance_matches_monte_carlo_through_pyproj():
    """Sigma_grid = J Sigma J^T against the scatter of 40000 sampled points pushed through PROJ."""
    rng = np.random.default_rng(5)
    p = geodetic_to_ecef(-1.5, 52.5, 80.0)
    a = rng.normal(size=(3, 3))
    cov = a @ a.T + np.eye(3)  # metres^2, a full covariance
    g = to_grid(p, cov, "EPSG:27700")
    s = rng.multivariate_normal(p, cov, 40000)
    e, n, _ = Transformer.from_crs("EPSG:4978", "EPSG:27700", always_xy=True).transform(*s.T)
    h = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(*s.T)[2]
    emp = np.cov(np.stack([e, n, h]))
    scale = np.sqrt(np.outer(np.diag(emp), np.diag(emp)))
    np.testing.assert_allclose(g.covariance / scale, emp / scale, atol=0.03)
    assert g.sigma_e == pytest.approx(np.sqrt(g.covariance[0, 0]))


def test_source_crs_declared_gives_pure_conversion_wgs84_an_ensemble_operation():
    p = _points(9.5, 50.0, "EPSG:4936", n=1)[0]
    nat = to_grid(p, np.eye(3) * 1e-4, "EPSG:25832", source_crs="EPSG:4936")
    assert nat.operation_accuracy_m == 0.0
    assert not nat.warnings
    assert "ETRS89" in nat.vertical_datum and "GRS 1980" in nat.vertical_datum
    wgs = to_grid(p, np.eye(3) * 1e-4, "EPSG:25832", source_crs="EPSG:4978")
    assert wgs.operation_accuracy_m == 1.0 and "ETRS89 to WGS 84" in wgs.operation
    assert any("ensemble" in w and "--source-crs" in w for w in wgs.warnings)
    uk = to_grid(geodetic_to_ecef(-1.5, 52.5, 80.0), None, "EPSG:27700")
    assert 1.0 <= uk.operation_accuracy_m <= 3.0 and "OSGB36 to WGS 84" in uk.operation


def test_feet_crs_gives_feet_coordinates_and_metre_sigmas():
    p = geodetic_to_ecef(-122.0, 37.5, 50.0, "EPSG:6317")
    g = to_grid(p, np.eye(3) * 0.01**2, "EPSG:6420", source_crs="EPSG:6317")  # CA zone 3, ftUS
    e, n, _ = Transformer.from_crs("EPSG:6317", "EPSG:6420", always_xy=True).transform(*p)
    assert g.easting == pytest.approx(e, abs=1e-4) and g.northing == pytest.approx(n, abs=1e-4)
    assert g.sigma_e == pytest.approx(0.01, rel=1e-3) and g.sigma_n == pytest.approx(0.01, rel=1e-3)


def test_transformers_are_cached_not_built_per_point():
    p = _points(-1.5, 52.5, n=1)
    to_grid(p[0], np.eye(3), "EPSG:27700")
    before = (tr.BUILDS["transformers"], tr.BUILDS["groups"])
    for _ in range(50):
        to_grid(p[0], np.eye(3), "EPSG:27700")
    to_grid_many(np.repeat(p, 1000, axis=0), None, "EPSG:27700")
    after = (tr.BUILDS["transformers"], tr.BUILDS["groups"])
    assert after == before


def test_to_grid_from_many_threads_agrees():
    from concurrent.futures import ThreadPoolExecutor

    p = _points(-1.5, 52.5, n=200)
    ref = to_grid_many(p, None, "EPSG:27700").easting
    with ThreadPoolExecutor(4) as ex:
        outs = list(ex.map(lambda i: to_grid(p[i], None, "EPSG:27700").easting, range(200)))
    np.testing.assert_array_equal(np.array(outs), ref)


@pytest.mark.parametrize(
    ("kwargs", "error", "words"),
    [
        ({"crs": "EPSG:999999"}, CRSError, "unknown CRS 'EPSG:999999'"),
        ({"crs": "not a crs"}, CRSError, "unknown CRS"),
        ({"crs": "EPSG:4326"}, CRSError, "geographic CRS"),
        ({"crs": "EPSG:4978"}, CRSError, "not a projected one"),
        ({"crs": "EPSG:27700", "vertical": "EPSG:4326"}, CRSError, "not a vertical CRS"),
        ({"crs": "EPSG:27700", "source_crs": "EPSG:4326"}, CRSError, "not geocentric"),
        ({"crs": "EPSG:27700", "vertical": "EPSG:5701", "geoid": "x.tif"}, InputError, "not both"),
    ],
)
def test_clear_errors(kwargs, error, words):
    p = geodetic_to_ecef(-1.5, 52.5, 80.0)
    with pytest.raises(error, match=words.replace("(", r"\(").replace(")", r"\)")):
        to_grid(p, None, **kwargs)


def test_outside_area_of_use_is_a_warning():
    g = to_grid(geodetic_to_ecef(151.2, -33.8, 10.0), None, "EPSG:27700")
    assert any("outside the area of use of EPSG:27700" in w for w in g.warnings)
    assert np.isfinite(g.easting)
    inside = to_grid(geodetic_to_ecef(-1.5, 52.5, 10.0), None, "EPSG:27700")
    assert not any("area of use" in w for w in inside.warnings)


def test_error_ellipse_and_ellipsoid_of_known_covariances():
    a, b, t = ellipse_95(np.diag([4.0, 1.0]))
    assert (a, b, t) == pytest.approx((2 * SCALE_95_2D, SCALE_95_2D, 90.0))
    # major axis 30 degrees clockwise from grid north: direction (sin 30, cos 30) in (E, N)
    u = np.array([np.sin(np.radians(30)), np.cos(np.radians(30))])
    v = np.array([u[1], -u[0]])
    c = 9.0 * np.outer(u, u) + 0.25 * np.outer(v, v)
    a, b, t = ellipse_95(c)
    assert (a, b, t) == pytest.approx((3 * SCALE_95_2D, 0.5 * SCALE_95_2D, 30.0))
    a, b, t = ellipse_95(9.0 * np.outer(v, v) + 0.25 * np.outer(u, u))
    assert t == pytest.approx(120.0)
    axes = ellipsoid_axes_95(np.diag([1.0, 9.0, 4.0]))
    np.testing.assert_allclose(np.linalg.norm(axes, axis=1), SCALE_95_3D * np.array([3, 2, 1]))
    np.testing.assert_allclose(np.abs(axes[0]), [0, 3 * SCALE_95_3D, 0], atol=1e-12)
