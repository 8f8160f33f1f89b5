"""measure_batch: point by point the same Measurement as measure_point, without its per-point cost.

Every test compares the batch with measure_point itself (records, to_dict, solution fields),
and checks that the vectorised path really ran (a counter on the fallback to measure_point),
so an equivalence that only holds because everything fell back would fail.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import orjson
import pyproj
import pytest
import rasterio
from affine import Affine
from crs_helpers import camera_origins, model_matrix, noisy_directions

import gsgeo.measure.batch as batch
from gsgeo.crs.frames import EnuFrame, geodetic_to_ecef
from gsgeo.errors import DatumError, InputError
from gsgeo.measure.batch import measure_batch, measure_batch_json, snoop_many
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.measure.point import measure_point, measure_points
from gsgeo.measure.rays import Rays, SolveSettings
from gsgeo.measure.schema import Measurement, MeasurementFailure
from gsgeo.solve.outliers import snoop

EGM96 = Path("/usr/share/proj/egm96_15.gtx")
IFOV = 0.0008
#: Keys of metre-valued coordinates: equal to 1e-8 m (ECEF rounding is ~1e-9 m at 6e6 m).
METRES = {"easting", "northing", "height", "h_wgs84", "point_ecef", "origin_ecef", "origin_grid",
          "direction_ecef", "residual_m", "rms_m", "point", "max_angle_deg"}
#: Keys derived from the grid covariance. Its Jacobian is a PROJ forward difference whose
#: rounding already moves measure_point's own result by ~1e-7 relative when the point moves
#: by one ulp, so these are compared to 1e-6 of the covariance's scale (m²) or of its root
#: (sigmas and axes, m).
GRID_COV = {"cov_ee", "cov_en", "cov_eh", "cov_nn", "cov_nh", "cov_hh"}
GRID_SIGMA = {"sigma_e", "sigma_n", "sigma_h", "sigma_e_meas", "sigma_n_meas", "sigma_h_meas",
              "ellipse_major_95", "ellipse_minor_95"}


def _near(key: str, a: float, b: float, scale: dict[str, float]) -> bool:
    if key in METRES:
        return abs(a - b) <= 1e-8
    if key in ("lon", "lat"):
        return abs(a - b) <= 1e-12
    if key in GRID_COV:
        return abs(a - b) <= 1e-6 * scale["grid"]
    if key in GRID_SIGMA:
        return abs(a - b) <= 1e-6 * math.sqrt(scale["grid"])
    if key in ("cov_ecef", "cov_ecef_total", "covariance"):
        return abs(a - b) <= 1e-9 * scale["ecef"]
    if key == "residual_px" or key == "max_residual_px":
        return abs(a - b) <= 1e-9
    return abs(a - b) <= 1e-9 * max(abs(a), abs(b))  # sigma0 and anything else: relative


def _compare(a: object, b: object, key: str, scale: dict[str, float], path: str) -> None:
    if isinstance(a, dict) and isinstance(b, dict):
        assert a.keys() == b.keys(), path
        for k in a:
            if k != "measured_at":
                _compare(a[k], b[k], k if k not in ("enu", "rays") else key, scale,
                         f"{path}.{k}")
    elif isinstance(a, list) and isinstance(b, list):
        assert len(a) == len(b), path
        for x, y in zip(a, b, strict=True):
            _compare(x, y, key, scale, path)
    elif isinstance(a, float) and isinstance(b, float):
        assert _near(key, a, b, scale) or (math.isnan(a) and math.isnan(b)), (path, a, b)
    else:
        assert a == b, (path, a, b)


def assert_same(got: Measurement | MeasurementFailure, ref: Measurement | MeasurementFailure
                ) -> None:
    """The batch's result equals measure_point's (see the tolerances above)."""
    assert type(got) is type(ref)
    if isinstance(got, MeasurementFailure):
        assert got == ref
        return
    assert isinstance(ref, Measurement)
    ecef = float(np.abs(ref.cov_ecef).max())
    grid = 0.0 if ref.grid is None or ref.grid.covariance is None else \
        float(np.abs(ref.grid.covariance).max())
    scale = {"ecef": max(ecef, float(np.abs(ref.solution.covariance).max())), "grid": grid}
    a, b = got.to_dict(), ref.to_dict()
    # Eigenvectors and the bearing of a near-circular ellipse are ill-conditioned: compare
    # the 95 % ellipsoid the axes span (sum of a aᵀ) and the bearing of elongated ellipses.
    axes_a, axes_b = a.pop("ellipsoid_axes_95"), b.pop("ellipsoid_axes_95")
    assert (axes_a is None) == (axes_b is None)
    if axes_a is not None:
        np.testing.assert_allclose(np.transpose(axes_a) @ np.asarray(axes_a),
                                   np.transpose(axes_b) @ np.asarray(axes_b),
                                   rtol=0, atol=1e-6 * 7.82 * scale["grid"])
    bear_a, bear_b = a.pop("ellipse_bearing_deg"), b.pop("ellipse_bearing_deg")
    assert (bear_a is None) == (bear_b is None)
    if bear_a is not None and b["ellipse_minor_95"] < 0.99 * b["ellipse_major_95"]:
        turn = abs(bear_a - bear_b) % 180.0
        assert min(turn, 180.0 - turn) <= 1e-3, (ref.point_id, bear_a, bear_b)
    _compare(a, b, "", scale, ref.point_id)
    assert got.record().keys() == ref.record().keys()
    s, r = got.solution, ref.solution
    assert s.warnings == r.warnings and s.model == r.model and s.dof == r.dof
    np.testing.assert_array_equal(s.outliers, r.outliers)
    np.testing.assert_array_equal(got.excluded, ref.excluded)
    np.testing.assert_allclose(s.ranges_m, r.ranges_m, rtol=0, atol=1e-8)
    np.testing.assert_allclose(s.outlier_ratio, r.outlier_ratio, rtol=1e-6, equal_nan=True)
    assert s.condition == pytest.approx(r.condition, rel=1e-6)


def reference(points, settings):
    """What measure_points does, with exclusions: measure_point per point, errors caught."""
    out = []
    for pid, code, description, rays, exclude in points:
        try:
            out.append(measure_point(rays, settings, point_id=pid, code=code,
                                     description=description, exclude=exclude))
        except Exception as exc:  # noqa: BLE001 - GsgeoError subclasses, compared as text
            out.append(MeasurementFailure(pid, str(exc)))
    return out


@pytest.fixture
def fallbacks(monkeypatch):
    """Counts the points the batch hands to measure_point."""
    calls = []
    real = batch.measure_point

    def counting(rays, settings, **kw):
        calls.append(kw["point_id"])
        return real(rays, settings, **kw)

    monkeypatch.setattr(batch, "measure_point", counting)
    return calls


def make_points(rng, count, *, lon=-1.5, lat=52.5, spread=0.01, rays=(2, 7), sigma_rad=IFOV,
                angular=None, prefix="P"):
    """Well-posed points around (lon, lat): 2..6 cameras 20-45 m away, 1 px aiming noise.
    ``angular`` None alternates the angular and the unweighted model."""
    out = []
    for k in range(count):
        p = geodetic_to_ecef(lon + rng.uniform(-spread, spread), lat + rng.uniform(-spread, spread),
                             rng.uniform(0, 120))
        n = int(rng.integers(*rays))
        o = camera_origins(p, n, rng)
        d = noisy_directions(o, p, sigma_rad, rng)
        ang = (k % 2 == 0) if angular is None else angular
        out.append((f"{prefix}{k}", "code", f"point {k}", Rays(o, d, np.full(n, IFOV) if ang else None),
                    ()))
    return out


FRAME = FrameCovariance(geodetic_to_ecef(-1.5, 52.5, 50.0),
                        np.diag([0.01, 0.01, 0.02, 2e-6, 2e-6, 3e-6, 1e-5]) ** 2)


@pytest.mark.parametrize("settings", [
    SolveSettings(crs="EPSG:27700"),
    SolveSettings(crs=None, sigma_px=0.7),
    SolveSettings(crs="EPSG:27700", frame=FRAME),
    SolveSettings(crs="EPSG:25830", source_crs="EPSG:4936"),  # ETRS89: a pure conversion
], ids=["bng", "no-grid", "bng-frame-covariance", "etrs89-utm"])
def test_random_points_equal_measure_point(settings, fallbacks):
    rng = np.random.default_rng(16)
    points = make_points(rng, 150)
    got = measure_batch(points, settings)
    assert fallbacks == []  # all on the vectorised path
    ref = reference(points, settings)
    for g, r in zip(got, ref, strict=True):
        assert_same(g, r)
    if settings.frame is not None:  # the total covariance really is larger than the aiming's
        rec = got[0].record()
        assert isinstance(rec["sigma_e"], float) and isinstance(rec["sigma_e_meas"], float)
        assert rec["sigma_e"] > rec["sigma_e_meas"]


def test_geoid_file_and_vertical_crs_equal_measure_point(fallbacks):
    if not EGM96.is_file():
        pytest.skip("Debian proj-data's egm96_15.gtx is not installed")
    rng = np.random.default_rng(3)
    points = make_points(rng, 40)
    by_file = SolveSettings(crs="EPSG:32630", geoid=str(EGM96))
    got = measure_batch(points, by_file)
    for g, r in zip(got, reference(points, by_file), strict=True):
        assert_same(g, r)
        assert isinstance(g, Measurement) and g.grid is not None
        assert g.grid.height_type == "orthometric"
    original = pyproj.datadir.get_data_dir()
    try:
        pyproj.datadir.append_data_dir(str(EGM96.parent))
        by_proj = SolveSettings(crs="EPSG:32630", vertical="EPSG:5773")
        got = measure_batch(points, by_proj)
        ref = reference(points, by_proj)
    finally:
        pyproj.datadir.set_data_dir(original)
    for g, r in zip(got, ref, strict=True):
        assert_same(g, r)
        assert isinstance(g, Measurement) and g.grid is not None and "EGM96" in g.grid.operation
    assert fallbacks == []


def test_excluded_rays_equal_measure_point(fallbacks):
    rng = np.random.default_rng(6)
    points = make_points(rng, 60, rays=(3, 7))
    for k, (pid, code, desc, rays, _) in enumerate(points):
        n = len(rays)
        drop = [int(rng.integers(n))]
        if n > 4 and k % 3 == 0:
            drop += [int(rng.integers(n)), drop[0]]  # a second ray, and one index twice
        if k % 4 == 0:  # an excluded blunder: its residual is large, the point unaffected
            d = rays.directions.copy()
            d[drop[0]] += 0.02 * np.cross(d[drop[0]], [0.0, 0.0, 1.0])
            rays = Rays(rays.origins, d, rays.ifov)
        points[k] = (pid, code, desc, rays, tuple(drop) if k % 5 else np.array(drop))
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
        assert isinstance(g, Measurement)
        assert any("excluded by request" in w for w in g.warnings)
        assert g.n_rays == len(g.excluded) - int(g.excluded.sum()) < len(g.excluded)
        assert not (g.outliers is not None and (g.outliers & g.excluded).any())


def rendered(point, matrices):
    """The point as the viewer reports it under per-ray model matrices (None: identity)."""
    pid, code, desc, rays, exclude = point
    o, d = rays.origins.copy(), rays.directions.copy()
    for i, mm in enumerate(matrices):
        if mm is not None:
            o[i] = mm[:3, :3] @ o[i] + mm[:3, 3]
            d[i] = mm[:3, :3] @ d[i]
    stack = np.array([np.full((4, 4), np.nan) if mm is None else mm for mm in matrices])
    return (pid, code, desc, Rays(o, d, rays.ifov, model_matrices=stack), exclude)


def test_model_matrices_equal_measure_point(fallbacks):
    rng = np.random.default_rng(12)
    points = make_points(rng, 24, rays=(3, 6))
    centre = geodetic_to_ecef(-1.5, 52.5, 50.0)
    similarity = model_matrix(centre)  # rotation, uniform scale and shift
    shear = similarity.copy()
    shear[0, 1] += 1e-3  # not a similarity: measure_point warns
    shift = np.eye(4)
    shift[:3, 3] = (2.0, -1.0, 0.5)
    for k, point in enumerate(points):
        n = len(point[3])
        choice = [similarity, shift, np.eye(4), None][k % 4]
        matrices = [choice] * n
        if k % 3 == 0:
            matrices[0] = shift if choice is not shift else None  # rays under two matrices
        if k % 8 == 5:
            matrices[-1] = shear
        points[k] = rendered(point, matrices)
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    assert sum(isinstance(g, Measurement) and any("not a rotation with uniform scale" in w
                                                  for w in g.warnings) for g in got) == 3
    same = [points[k] for k in (4, 8, 16, 20)]  # one matrix on every ray of the batch
    for g, r in zip(measure_batch(same, settings), reference(same, settings), strict=True):
        assert_same(g, r)
    assert fallbacks == []
    g = got[0]
    assert isinstance(g, Measurement)  # mapped back to where the rays were aimed from
    assert np.linalg.norm(g.ray_origins_ecef - rays_of(points[0]).origins, axis=1).max() > 1.0


def test_partial_ifov_singular_matrices_and_refused_exclusions_go_through_measure_point(
        fallbacks):
    rng = np.random.default_rng(5)
    points = make_points(rng, 12, rays=(4, 6))
    flat = np.eye(4)
    flat[2, 2] = 0.0  # affine but singular: measure_point's error
    points[1] = rendered(points[1], [flat] + [None] * (len(points[1][3]) - 1))
    pid, code, desc, rays, _ = points[2]
    f = np.full(len(rays), IFOV)
    f[1] = np.nan
    points[2] = (pid, code, desc, Rays(rays.origins, rays.directions, f), ())  # ifov on some
    pid, code, desc, rays, _ = points[3]
    points[3] = (pid, code, desc, rays, tuple(range(len(rays) - 1)))  # leaves one ray
    points[4] = points[4][:4] + ((len(points[4][3]),),)  # index out of range
    points[5] = points[5][:4] + ((True,),)  # not an index
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert sorted(fallbacks) == ["P1", "P2", "P3", "P4", "P5"]
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    assert isinstance(got[1], MeasurementFailure) and "singular" in got[1].error
    assert isinstance(got[2], MeasurementFailure) and "no ifov on ray(s) 1" in got[2].error
    assert isinstance(got[3], MeasurementFailure) and "leaves fewer than 2" in got[3].error
    assert isinstance(got[4], MeasurementFailure) and "cannot exclude ray index" in got[4].error
    assert isinstance(got[5], MeasurementFailure) and "cannot exclude ray index" in got[5].error


def rays_of(point):
    return point[3]


def test_parallel_rays_and_a_point_behind_a_camera_fail_with_measure_points_message(fallbacks):
    rng = np.random.default_rng(9)
    points = make_points(rng, 6)
    p = geodetic_to_ecef(-1.5, 52.5, 40.0)
    frame = EnuFrame(p)
    o = frame.to_ecef(np.array([[0.0, -30.0, 5.0], [0.02, -30.0, 5.0], [-0.02, -30.0, 5.0]]))
    d = frame.directions_to_ecef(np.array([[0.0, 1.0, 0.0]] * 3))
    points.append(("PAR", "", "", Rays(o, d, np.full(3, IFOV)), ()))
    o2 = frame.to_ecef(np.array([[-20.0, -20.0, 5.0], [20.0, -20.0, 5.0]]))
    d2 = frame.directions_to_ecef(np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0]]))
    points.append(("BACK", "", "", Rays(o2, d2), ()))  # both aim away from their crossing
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert fallbacks == ["PAR", "BACK"]
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    assert isinstance(got[-2], MeasurementFailure) and "parallel" in got[-2].error
    assert isinstance(got[-1], MeasurementFailure) and "behind the camera" in got[-1].error


@pytest.mark.parametrize("angular", [True, False], ids=["angular", "unweighted"])
def test_outlier_rays_weak_geometry_and_global_test_warn_as_measure_point(angular, fallbacks):
    rng = np.random.default_rng(21)
    points = make_points(rng, 60, rays=(3, 7), angular=angular)
    for k in range(0, 60, 3):  # every third point: one ray aimed 40 px off
        pid, code, desc, rays, _ = points[k]
        d = rays.directions.copy()
        d[k % len(d)] += 40 * IFOV * np.cross(d[k % len(d)], [0.0, 0.0, 1.0]) / np.linalg.norm(
            np.cross(d[k % len(d)], [0.0, 0.0, 1.0]))
        points[k] = (pid, code, desc, Rays(rays.origins, d, rays.ifov), ())
    # weak geometry: cameras 0.5 m apart, 40 m away (under 2 degrees)
    p = geodetic_to_ecef(-1.5, 52.5, 30.0)
    fr = EnuFrame(p)
    o = fr.to_ecef(np.array([[0.0, -40.0, 2.0], [0.5, -40.0, 2.0], [0.25, -40.0, 2.4]]))
    d = noisy_directions(o, p, 0.2 * IFOV, rng)
    points.append(("WEAK", "", "", Rays(o, d, np.full(3, IFOV) if angular else None), ()))
    settings = SolveSettings(crs="EPSG:27700", sigma_px=0.3)  # aiming noise is 1 px: scaled
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    warnings = [w for g in got if isinstance(g, Measurement) for w in g.warnings]
    assert sum("look like outliers" in w for w in warnings) >= 15
    assert any("weak geometry" in w for w in warnings)
    assert any("global test" in w for w in warnings) == angular
    flagged = [g for g in got[:60:3] if isinstance(g, Measurement) and g.outliers is not None]
    assert sum(bool(g.outliers.any()) for g in flagged) >= 15


def test_snoop_many_equals_snoop_point_by_point():
    rng = np.random.default_rng(2)
    for n in (3, 4, 6):
        o = rng.normal(0, 20, (80, n, 3))
        target = rng.normal(0, 2, (80, 1, 3))
        d = target - o + rng.normal(0, 0.01, (80, n, 3))
        d[::2, 0] += rng.normal(0, 1.0, (40, 3))  # blunders in half the points
        d /= np.linalg.norm(d, axis=2, keepdims=True)
        sigma = 0.0006 * np.linalg.norm(target - o, axis=2)  # ~ the noise above
        for w, s in ((None, None), (1 / sigma**2, sigma)):
            flags, ratios = snoop_many(o, d, w, s)
            for k in range(80):
                f1, r1 = snoop(o[k], d[k], None if w is None else w[k], None if s is None else s[k])
                np.testing.assert_array_equal(flags[k], f1)
                np.testing.assert_allclose(ratios[k], r1, rtol=1e-9, equal_nan=True)
            if n > 3:  # with three rays a blunder is rarely separable; with more, mostly
                assert flags[::2].any(axis=1).mean() > 0.5 > flags[1::2].any(axis=1).mean()


def test_points_outside_the_grid_area_and_far_apart_warn_per_point(fallbacks):
    """London points and a few across the Channel (outside EPSG:27700's area of use): each
    carries the single-point warning, not one counting the whole batch."""
    rng = np.random.default_rng(4)
    points = make_points(rng, 20, lon=-0.12, lat=51.5) + make_points(
        rng, 4, lon=2.35, lat=48.86, prefix="FR")
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    assert all(isinstance(g, Measurement) for g in got)
    outside = [g for g in got if isinstance(g, Measurement)
               and any("the point lies outside the area of use" in w for w in g.warnings)]
    assert [g.point_id for g in outside] == ["FR0", "FR1", "FR2", "FR3"]


def test_points_whose_centroid_lies_where_none_of_them_does_are_not_one_call(fallbacks):
    """West of Ireland and in the North Sea: each outside every real OSGB36 operation's area
    of use (measure_point falls back to PROJ's ballpark and says so), while their centroid
    lies inside them."""
    rng = np.random.default_rng(11)
    points = make_points(rng, 3, lon=-10.0, lat=55.0, prefix="W") + make_points(
        rng, 3, lon=3.5, lat=55.0, prefix="E")
    settings = SolveSettings(crs="EPSG:27700")
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
        assert isinstance(g, Measurement)
        assert g.grid is not None and "Ballpark" in g.grid.operation
        assert any("unknown accuracy" in w for w in g.warnings)


def write_geoid(path: Path) -> Path:
    """A flat 45 m geoid over lon -2..-1, lat 52..53 (EPSG:4326)."""
    res = 0.01
    with rasterio.open(path, "w", driver="GTiff", width=100, height=100, count=1,
                       dtype="float32", crs="EPSG:4326",
                       transform=Affine(res, 0.0, -2.0, 0.0, -res, 53.0), nodata=-9999) as ds:
        ds.write(np.full((100, 100), 45.0, dtype=np.float32), 1)
    return path


def test_a_point_outside_the_geoid_fails_alone(tmp_path, fallbacks):
    geoid = write_geoid(tmp_path / "geoid.tif")
    rng = np.random.default_rng(8)
    points = make_points(rng, 30, spread=0.2)
    points[7] = make_points(rng, 1, lon=-0.5, lat=52.5, spread=0.001, prefix="OUT")[0]
    settings = SolveSettings(crs="EPSG:27700", geoid=str(geoid))
    got = measure_batch(points, settings)
    assert fallbacks == []
    for g, r in zip(got, reference(points, settings), strict=True):
        assert_same(g, r)
    assert isinstance(got[7], MeasurementFailure) and "outside the geoid grid" in got[7].error
    assert sum(isinstance(g, Measurement) for g in got) == 29


def test_a_crs_problem_of_the_whole_set_is_raised_once_as_measure_points_does():
    rng = np.random.default_rng(1)
    points = make_points(rng, 5)
    settings = SolveSettings(crs="EPSG:27700", vertical="EPSG:5701")  # OSGM15 not installed
    with pytest.raises(DatumError) as ours:
        measure_batch(points, settings)
    with pytest.raises(DatumError) as theirs:
        measure_points([p[:4] for p in points], settings)
    assert str(ours.value) == str(theirs.value)
    assert measure_batch([], settings) == []
    with pytest.raises(InputError, match="needs a grid CRS"):  # checked before any point
        measure_batch(points, SolveSettings(vertical="EPSG:5701"))


def as_stored(value):
    """A result as the store keeps it: orjson's JSON (NaN -> null), read back."""
    return orjson.loads(orjson.dumps(value, option=orjson.OPT_SERIALIZE_NUMPY))


@pytest.mark.parametrize("settings", [
    SolveSettings(crs="EPSG:27700"),
    SolveSettings(crs=None, sigma_px=0.7),
    SolveSettings(crs="EPSG:27700", frame=FRAME),
    SolveSettings(crs="EPSG:27700", sigma_px=0.0),  # the unweighted model: no pixel residuals
], ids=["bng", "no-grid", "bng-frame-covariance", "unweighted"])
def test_json_results_are_the_measurements_to_dict(settings):
    """measure_batch_json (what a re-measure stores) makes, without Measurement objects, what
    measure_batch's Measurements' to_dict() give: same keys in the same order, same values
    (measured_at aside), failures and points off the vectorised path included."""
    rng = np.random.default_rng(21)
    points = make_points(rng, 80, rays=(2, 6))
    for k in range(0, 80, 7):  # exclusions
        pid, code, desc, rays, _ = points[k]
        if len(rays) > 2:
            points[k] = (pid, code, desc, rays, (k % len(rays),))
    pid, code, desc, rays, _ = points[3]
    points[3] = (pid, code, desc, rays, tuple(range(len(rays) - 1)))  # refused: one ray left
    pid, code, desc, rays, _ = points[5]
    f = np.full(len(rays), IFOV)
    f[0] = np.nan
    points[5] = (pid, code, desc, Rays(rays.origins, rays.directions, f), ())  # measure_point
    got = measure_batch_json(points, settings)
    ref = measure_batch(points, settings)
    assert len(got) == len(ref) == 80
    for g, r in zip(got, ref, strict=True):
        if isinstance(r, MeasurementFailure):
            assert g == r
            continue
        assert isinstance(g, dict)
        a, b = as_stored(g), as_stored(r.to_dict())
        a.pop("measured_at")
        b.pop("measured_at")
        assert list(a) == list(b)
        assert a == b, r.point_id
    assert sum(isinstance(r, MeasurementFailure) for r in ref) >= 1
