"""Monte-Carlo: a point measured by one human click and auto-aim states an honest 95 % ellipsoid.

Simulated as an operator works: the first click lands 0-2.5 px off the feature (uniform in
radius, any direction: a careful person), the clicked spot is where that ray meets the
feature's surface (seen 0-60 degrees off its normal), and 2-4 auto rays from other views find
*that spot* (each with a matching error of 0.05-0.3 px), as auto-aim's patch match does. The
rays go through gsgeo's whole measurement (rendered ECEF near Cambridge, measure_batch and
measure_point), and the truth is the feature, not the clicked spot. Expectations are computed
here from the simulation: the squared Mahalanobis distance of the truth under the stated ECEF
covariance against chi-square(3) at 95 %.

- With the rays marked auto, the truth is inside the stated 95 % ellipsoid in 95 % +- 2 % of
  2 000 trials.
- The same rays not marked auto (what gsgeo stated before): far below (the auto rays agree
  with each other, not with the truth), so the test can fail.
- A point of clicks only is measured exactly as before (auto None and all False alike).
"""

from __future__ import annotations

import numpy as np
import pyproj
import pytest

from gsgeo.measure import Rays, SolveSettings
from gsgeo.measure.batch import measure_batch
from gsgeo.measure.point import measure_point
from gsgeo.solve.sharedaim import MATCH_SIGMA_PX

TRIALS = 2000
CHI2_3_95 = 7.814728
IFOV = np.radians(60.0) / 1280  # a 60-degree view 1280 px wide
SETTINGS = SolveSettings.parse(crs=None, sigma_px=1.0)


def _enu_frame(lat: float, lon: float, h: float) -> tuple[np.ndarray, np.ndarray]:
    """ENU -> ECEF rotation (columns e, n, u) and origin, written out here (pyproj the origin)."""
    x, y, z = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(
        lon, lat, h)
    p, lam = np.radians(lat), np.radians(lon)
    r = np.array([[-np.sin(lam), -np.sin(p) * np.cos(lam), np.cos(p) * np.cos(lam)],
                  [np.cos(lam), -np.sin(p) * np.sin(lam), np.cos(p) * np.sin(lam)],
                  [0.0, np.cos(p), np.sin(p)]])
    return r, np.array([x, y, z])


ROT, ORIGIN = _enu_frame(52.2053, 0.1218, 15.0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _camera(rng: np.random.Generator, x: np.ndarray, az: float) -> np.ndarray:
    el = np.radians(rng.uniform(20.0, 70.0))
    rng_m = rng.uniform(8.0, 20.0)
    a = np.radians(az)
    return x + rng_m * np.array([np.cos(el) * np.sin(a), np.cos(el) * np.cos(a), np.sin(el)])


def _image_axes(d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    b1 = _unit(np.cross(d, [0.0, 0.0, 1.0]))
    return b1, np.cross(d, b1)


def _aim(rng: np.random.Generator, o: np.ndarray, at: np.ndarray, px: float) -> np.ndarray:
    """Unit direction from o to `at`, off by an isotropic error of `px` pixels (1 sigma)."""
    d = _unit(at - o)
    b1, b2 = _image_axes(d)
    return _unit(d + IFOV * px * (rng.normal() * b1 + rng.normal() * b2))


def simulate(rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """One operator's point: truth (ENU), origins and directions (K, 3) ENU, auto flags (K,)."""
    x = rng.uniform(-5.0, 5.0, 3)
    az0 = rng.uniform(0.0, 360.0)
    o0 = _camera(rng, x, az0)
    d_true = _unit(x - o0)
    b1, b2 = _image_axes(d_true)
    # the click: 0-2.5 px off, any direction
    r_px, th = rng.uniform(0.0, 2.5), rng.uniform(0.0, 2 * np.pi)
    d0 = _unit(d_true + IFOV * r_px * (np.cos(th) * b1 + np.sin(th) * b2))
    # the surface there, seen 0-60 degrees off its normal; the clicked spot is on it
    inc, ph = np.radians(rng.uniform(0.0, 60.0)), rng.uniform(0.0, 2 * np.pi)
    normal = -np.cos(inc) * d_true + np.sin(inc) * (np.cos(ph) * b1 + np.sin(ph) * b2)
    spot = o0 + d0 * (normal @ (x - o0)) / (normal @ d0)
    origins, dirs = [o0], [d0]
    az = az0
    for _ in range(rng.integers(2, 5)):
        az += rng.uniform(40.0, 110.0)
        o = _camera(rng, x, az)
        origins.append(o)
        dirs.append(_aim(rng, o, spot, rng.uniform(0.05, MATCH_SIGMA_PX)))
    auto = np.arange(len(origins)) > 0
    return x, np.array(origins), np.array(dirs), auto


def to_rays(o_enu: np.ndarray, d_enu: np.ndarray, auto: np.ndarray | None) -> Rays:
    return Rays(o_enu @ ROT.T + ORIGIN, d_enu @ ROT.T, np.full(len(o_enu), IFOV), auto=auto)


def mahalanobis2(result, truth_enu: np.ndarray) -> float:
    e = result.point_ecef - (ROT @ truth_enu + ORIGIN)
    return float(e @ np.linalg.solve(result.cov_ecef, e))


@pytest.fixture(scope="module")
def trials():
    rng = np.random.default_rng(20261128)
    sims = [simulate(rng) for _ in range(TRIALS)]
    out = {}
    for name, marked in (("auto", True), ("unmarked", False)):
        pts = [(f"P{i}", "", "", to_rays(o, d, auto if marked else None), ())
               for i, (_, o, d, auto) in enumerate(sims)]
        res = measure_batch(pts, SETTINGS)
        out[name] = np.array([mahalanobis2(r, s[0]) for r, s in zip(res, sims, strict=True)])
    out["sims"] = sims
    return out


def test_stated_95_percent_holds_the_truth_under_human_aim(trials):
    coverage = float(np.mean(trials["auto"] <= CHI2_3_95))
    assert abs(coverage - 0.95) <= 0.02, coverage


def test_without_the_shared_error_the_ellipsoid_is_dishonest(trials):
    coverage = float(np.mean(trials["unmarked"] <= CHI2_3_95))
    assert coverage < 0.75, coverage


def test_one_point_and_the_batch_state_the_same_covariance(trials):
    for _, o, d, auto in trials["sims"][:25]:
        one = measure_point(to_rays(o, d, auto), SETTINGS)
        many = measure_batch([("P", "", "", to_rays(o, d, auto), ())], SETTINGS)[0]
        assert np.allclose(one.cov_ecef, many.cov_ecef, rtol=1e-6, atol=1e-12)
        assert np.allclose(one.point_ecef, many.point_ecef, rtol=0, atol=1e-9)


def test_clicks_only_are_measured_as_before(trials):
    _, o, d, _ = trials["sims"][0]
    plain = measure_point(to_rays(o, d, None), SETTINGS)
    clicked = measure_point(to_rays(o, d, np.zeros(len(o), dtype=bool)), SETTINGS)
    assert np.array_equal(plain.cov_ecef, clicked.cov_ecef)
    assert np.array_equal(plain.point_ecef, clicked.point_ecef)


def test_the_reference_alone_in_its_group_changes_nothing_but_the_weights():
    """An auto ray matched to a click, with a third clicked ray: the hand-computed covariance
    N^-1 (A + G S G^T) N^-1 of the module's model, term by term."""
    rng = np.random.default_rng(5)
    x, o, d, _ = simulate(rng)
    o, d = o[:3], d[:3]
    auto = np.array([False, True, False])
    res = measure_point(to_rays(o, d, auto), SETTINGS)
    # the same in ENU, by hand
    u = d / np.linalg.norm(d, axis=1, keepdims=True)
    p_enu = ROT.T @ (res.point_ecef - ORIGIN)
    r = np.einsum("ki,ki->k", p_enu - o, u)
    s = np.array([1.0, MATCH_SIGMA_PX, 1.0]) * IFOV * r
    w = 1 / s**2
    proj = np.eye(3) - u[:, :, None] * u[:, None, :]
    n = np.einsum("k,kij->ij", w, proj)
    g = w[0] * proj[0] + w[1] * proj[1]
    a = w[1] * proj[1] + w[2] * proj[2]
    ninv = np.linalg.inv(n)
    c = ninv @ (a + g @ (s[0] ** 2 * np.eye(3)) @ g.T) @ ninv
    assert np.allclose(ROT.T @ res.cov_ecef @ ROT, c, rtol=1e-6, atol=1e-14)
    assert res.solution.sigma0 < 3  # no global-test scaling in this case
