"""End to end: a known EPSG:27700 point, noisy viewer rays with a modelMatrix, the pipeline.

Done-when test of issue 3: the point is recovered inside its 95 % ellipsoid, and over many
trials the coverage and the scatter match the reported covariance.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from crs_helpers import camera_origins, model_matrix, noisy_directions, render
from pyproj import Proj, Transformer

from gsgeo.crs.frames import EnuFrame
from gsgeo.crs.grid import to_grid_many
from gsgeo.crs.modelmatrix import column_major, rendered_to_georeferenced
from gsgeo.errors import CRSError, InputError
from gsgeo.measure import RECORD_KEYS, Measurement, MeasurementFailure
from gsgeo.session import Ray, Session, SessionPoint, measure_session
from gsgeo.session import measure_session_point as measure_point
from gsgeo.solve import intersect_batch

CHI2_3_95 = 7.814727903251178
IFOV = 0.0008  # rad per pixel
SIGMA_PX = 1.0
E0, N0, H0 = 529070.0, 179680.0, 61.5  # London, British National Grid; h on WGS 84


@pytest.fixture(scope="module")
def truth():
    """Truth in ECEF from the grid point, and its grid coordinates by direct pyproj."""
    lon, lat = Transformer.from_crs("EPSG:27700", "EPSG:4326", always_xy=True).transform(E0, N0)
    x, y, z = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon, lat, H0)
    p = np.array([x, y, z])
    e, n, h = Transformer.from_crs("EPSG:4978", "EPSG:27700", always_xy=True).transform(x, y, z)
    assert abs(e - E0) < 0.01 and abs(n - N0) < 0.01  # 2-D vs 3-D Helmert differ by mm
    return p, np.array([e, n, H0])


def _session_point(pid, o_r, d_r, m, ifov=IFOV) -> SessionPoint:
    mm = np.array(column_major(m))
    return SessionPoint(pid, [Ray(o, d, ifov=ifov, model_matrix=mm) for o, d in zip(o_r, d_r, strict=True)],
                        code="test", description="synthetic")


def _mahalanobis(x, truth, cov) -> float:
    r = x - truth
    return float(r @ np.linalg.solve(cov, r))


def test_single_point_recovered_inside_95_ellipsoid(truth, rng):
    p, g_true = truth
    m = model_matrix(p)
    o = camera_origins(p, 5, rng)
    d = noisy_directions(o, p, SIGMA_PX * IFOV, rng)
    o_r, d_r = render(m, o, d)
    # the rendered rays really are somewhere else: the test needs the inverse modelMatrix
    assert np.linalg.norm(o_r - o, axis=1).min() > 1.0
    meas = measure_point(_session_point("P1", o_r, d_r, m), crs="EPSG:27700", sigma_px=SIGMA_PX)
    g = meas.grid
    x = np.array([g.easting, g.northing, g.height])
    assert _mahalanobis(x, g_true, g.covariance) < CHI2_3_95
    assert np.linalg.norm(x - g_true) < 0.1
    # camera centres in the grid match direct pyproj of the georeferenced origins
    t = Transformer.from_crs("EPSG:4978", "EPSG:27700", always_xy=True)
    e, n, _ = t.transform(o[:, 0], o[:, 1], o[:, 2])
    np.testing.assert_allclose(meas.ray_origins_grid[:, 0], e, atol=1e-4)
    np.testing.assert_allclose(meas.ray_origins_grid[:, 1], n, atol=1e-4)
    np.testing.assert_allclose(meas.ray_origins_ecef, o, atol=1e-6)


def test_monte_carlo_coverage_full_pipeline(truth):
    """300 trials through measure_point (modelMatrix, ENU, intersect, to_grid)."""
    p, g_true = truth
    rng = np.random.default_rng(7)
    m = model_matrix(p)
    trials = 300
    d2 = np.empty(trials)
    for k in range(trials):
        o = camera_origins(p, 3 + k % 4, rng)
        d = noisy_directions(o, p, SIGMA_PX * IFOV, rng)
        o_r, d_r = render(m, o, d)
        g = measure_point(_session_point(f"T{k}", o_r, d_r, m), crs="EPSG:27700").grid
        d2[k] = _mahalanobis(np.array([g.easting, g.northing, g.height]), g_true, g.covariance)
    coverage = np.mean(d2 <= CHI2_3_95)
    # binomial sd at n = 300 is 1.26 %; 4 sd
    assert abs(coverage - 0.95) < 0.05, coverage
    # the mean squared Mahalanobis distance of a calibrated 3-D covariance is 3
    assert 2.5 < d2.mean() < 3.5, d2.mean()


def test_monte_carlo_statistics_batch(truth):
    """2000 trials of 5 rays: the same frames and transforms, vectorised (intersect_batch)."""
    p, g_true = truth
    rng = np.random.default_rng(11)
    m = model_matrix(p)
    trials, n = 2000, 5
    o = np.stack([camera_origins(p, n, rng) for _ in range(trials)])
    d = noisy_directions(o, p, SIGMA_PX * IFOV, rng)
    o_r, d_r = render(m, o, d)
    go, gd, similar = rendered_to_georeferenced(o_r.reshape(-1, 3), d_r.reshape(-1, 3),
                                                [m] * (trials * n))
    assert similar
    frame = EnuFrame(p + np.array([0.3, -0.2, 0.1]))  # a provisional origin near the point
    oe = frame.to_enu(go).reshape(trials, n, 3)
    de = frame.directions_to_enu(gd).reshape(trials, n, 3)
    res = intersect_batch(oe, de, ifov=IFOV, sigma_px=SIGMA_PX)
    assert res.valid.all()
    pts = frame.to_ecef(res.points)
    cov = frame.covariance_to_ecef(res.covariances)
    g = to_grid_many(pts, cov, "EPSG:27700")
    x = np.stack([g.easting, g.northing, g.height], axis=1)
    err = x - g_true
    d2 = np.einsum("mi,mi->m", err, np.linalg.solve(g.covariance, err[..., None])[..., 0])
    coverage = np.mean(d2 <= CHI2_3_95)
    assert abs(coverage - 0.95) < 0.02, coverage  # sd 0.49 %
    # per-component: scatter of the errors against the mean reported variance
    mean_var = g.covariance.mean(axis=0).diagonal()
    ratio = err.var(axis=0) / mean_var
    np.testing.assert_allclose(ratio, 1.0, atol=0.15)
    # and no bias beyond 4 standard errors
    assert np.all(np.abs(err.mean(axis=0)) < 4 * np.sqrt(mean_var / trials))
    # the grid covariance is the ENU one rotated by the meridian convergence and scaled by
    # the point scale factor k: trace(C_EN) = k^2 trace(C_en); k from PROJ's own factors
    k2 = (np.trace(g.covariance[:, :2, :2], axis1=1, axis2=2)
          / np.trace(res.covariances[:, :2, :2], axis1=1, axis2=2))
    lon, lat = Transformer.from_crs("EPSG:27700", "EPSG:4326", always_xy=True).transform(E0, N0)
    k = Proj("EPSG:27700").get_factors(lon, lat).meridional_scale
    np.testing.assert_allclose(np.sqrt(k2), k, atol=5e-5)  # Helmert scale is 20 ppm
    np.testing.assert_allclose(g.covariance[:, 2, 2], res.covariances[:, 2, 2], rtol=1e-6)


def test_record_has_exactly_the_point_schema_and_to_dict_is_json(truth, rng):
    p, _ = truth
    m = model_matrix(p)
    o = camera_origins(p, 4, rng)
    o_r, d_r = render(m, o, noisy_directions(o, p, IFOV, rng))
    meas = measure_point(_session_point("P9", o_r, d_r, m), crs="EPSG:27700", exclude=[3])
    rec = meas.record()
    assert tuple(rec) == RECORD_KEYS
    assert len(RECORD_KEYS) == 35
    # no georeference uncertainty: the total sigmas are the aiming's
    assert [rec[f"sigma_{a}_meas"] for a in "enh"] == [rec[f"sigma_{a}"] for a in "enh"]
    assert rec["crs"] == "EPSG:27700" and rec["n_rays"] == 3
    assert rec["height_type"] == "ellipsoidal" and "WGS 84" in rec["vertical_datum"]
    assert rec["operation_accuracy_m"] == 2.0 and "OSGB36 to WGS 84" in rec["operation"]
    assert rec["cov_en"] == pytest.approx(meas.grid.covariance[0, 1])
    d = json.loads(json.dumps(meas.to_dict()))
    assert [r["excluded"] for r in d["rays"]] == [False, False, False, True]
    assert d["rays"][3]["residual_px"] > 0 and d["rays"][3]["outlier"] is False
    assert any("excluded" in w for w in d["warnings"])
    assert any("accurate to 2 m" in w for w in d["warnings"])
    assert len(d["ellipsoid_axes_95"]) == 3


def test_no_crs_gives_wgs84_only(truth, rng):
    p, _ = truth
    o = camera_origins(p, 3, rng)
    d = noisy_directions(o, p, 0.0, rng)
    meas = measure_point(SessionPoint("A", [Ray(a, b) for a, b in zip(o, d, strict=True)]), crs=None)
    rec = meas.record()
    assert rec["easting"] is None and rec["crs"] is None and rec["operation"] is None
    lon, lat, h = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(*p)
    assert rec["lon"] == pytest.approx(lon, abs=1e-9) and rec["h_wgs84"] == pytest.approx(h, abs=1e-4)
    np.testing.assert_allclose(meas.point_ecef, p, atol=1e-5)


def test_bad_exclusions_and_session_level_errors(truth, rng):
    p, _ = truth
    o = camera_origins(p, 3, rng)
    pt = SessionPoint("A", [Ray(a, b) for a, b in zip(o, noisy_directions(o, p, 0, rng), strict=True)])
    with pytest.raises(InputError, match="0-based"):
        measure_point(pt, crs=None, exclude=[3])
    with pytest.raises(InputError, match="fewer than 2"):
        measure_point(pt, crs=None, exclude=[0, 1])
    bad = SessionPoint("B", [Ray(o[0], p - o[0]), Ray(o[0] + 1, p - o[0])])  # parallel
    sess = Session(points=[pt, bad], crs="EPSG:27700")
    out = measure_session(sess)
    assert isinstance(out[0], Measurement) and isinstance(out[1], MeasurementFailure)
    assert "parallel" in out[1].error
    with pytest.raises(CRSError, match="unknown CRS"):
        measure_session(sess, crs="EPSG:999999")
    with pytest.raises(CRSError, match="geographic CRS"):
        measure_session(sess, crs="EPSG:4326")
    with pytest.raises(CRSError, match="not geocentric"):
        measure_session(sess, source_crs="EPSG:4326")


def test_model_matrix_scale_keeps_ifov_valid(truth, rng):
    """A uniformly scaled, rotated modelMatrix gives the same point and covariance as identity:
    directions go through the linear part and are re-normalised, ifov is an angle."""
    p, _ = truth
    o = camera_origins(p, 4, rng)
    d = noisy_directions(o, p, IFOV, rng)
    plain = measure_point(_session_point("I", o, d, np.eye(4)), crs="EPSG:27700")
    m = model_matrix(p, angle_deg=3.0, scale=1.25, shift=(40.0, 0.0, -10.0))
    o_r, d_r = render(m, o, d)
    moved = measure_point(_session_point("M", o_r, d_r, m), crs="EPSG:27700")
    np.testing.assert_allclose(moved.point_ecef, plain.point_ecef, atol=1e-6)
    cmax = np.abs(plain.grid.covariance).max()
    np.testing.assert_allclose(moved.grid.covariance, plain.grid.covariance, rtol=1e-6, atol=1e-6 * cmax)
    np.testing.assert_allclose(moved.residuals_px, plain.residuals_px, rtol=1e-6)
    assert not any("model_matrix" in w for w in moved.warnings)
    shear = m.copy()
    shear[0, 1] += 0.05
    o_s, d_s = render(shear, o, d)
    sheared = measure_point(_session_point("S", o_s, d_s, shear), crs="EPSG:27700")
    np.testing.assert_allclose(sheared.point_ecef, plain.point_ecef, atol=1e-6)
    assert any("not a rotation with uniform scale" in w for w in sheared.warnings)


def test_point_outside_geoid_fails_alone_missing_grid_fails_the_session(truth, rng, tmp_path):
    import rasterio
    from affine import Affine

    p, _ = truth
    lon, lat, _ = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(*p)
    g = tmp_path / "small.tif"  # a 300 m geoid grid around the truth point
    tf = Affine(0.001, 0, lon - 0.0015, 0, -0.001, lat + 0.0015)
    with rasterio.open(g, "w", driver="GTiff", width=3, height=3, count=1, dtype="float32",
                       crs="EPSG:4326", transform=tf) as ds:
        ds.write(np.full((3, 3), 47.0, dtype=np.float32), 1)
    o = camera_origins(p, 3, rng)
    near = SessionPoint("NEAR", [Ray(a, b) for a, b in zip(o, noisy_directions(o, p, 0, rng), strict=True)])
    q = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon + 0.01, lat, 60.0)
    q = np.array(q)
    o2 = camera_origins(q, 3, rng)
    far = SessionPoint("FAR", [Ray(a, b) for a, b in zip(o2, noisy_directions(o2, q, 0, rng), strict=True)])
    out = measure_session(Session(points=[near, far], crs="EPSG:27700"), geoid=g)
    assert isinstance(out[0], Measurement) and out[0].grid.height_type == "orthometric"
    assert isinstance(out[1], MeasurementFailure) and "outside the geoid grid" in out[1].error
    with pytest.raises(CRSError, match="uk_os_OSGM15_GB.tif"):
        measure_session(Session(points=[near, far], crs="EPSG:27700", vertical="EPSG:5701"))
