"""Monte-Carlo: the georeference's reported sigmas are honest.

4 000 simulated georeferences of one local scene (8 control points with anisotropic
measurement covariances in the scene frame, control with stated horizontal / vertical sigmas,
both perturbed by exactly those covariances). Over the trials, the true parameters must lie
inside the reported 95 % region as often as promised (95 % +- 1.5 %): the scale on its own,
all seven parameters jointly (chi-square, 7 dof), and the propagated position of points
inside and far outside the control (chi-square, 3 dof), the frame's share alone and the
total with the point's own measurement noise. The same statistics with covariances
understated by 20 % in sigma must fall clearly outside the band (the test can fail).
"""

from __future__ import annotations

import numpy as np
import pytest
from georef_helpers import truth

from gsgeo.crs.ellipsoid import enu_rotation, geodetic_to_ecef_closed_form
from gsgeo.georef.control import enu_covariances
from gsgeo.georef.helmert import Similarity, fit_similarity
from gsgeo.measure.framecov import FrameCovariance

TRIALS = 4000
CHI2_95 = {1: 3.841459, 3: 7.814728, 7: 14.067140}


def _rotvec(r: np.ndarray) -> np.ndarray:
    """Rotation vector of a rotation matrix (small angles)."""
    return 0.5 * np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])


def _random_covs(rng: np.random.Generator, n: int, sigmas: tuple[float, float, float]
                 ) -> np.ndarray:
    q, _ = np.linalg.qr(rng.normal(size=(n, 3, 3)))
    d = np.zeros((n, 3, 3))
    d[:, [0, 1, 2], [0, 1, 2]] = np.asarray(sigmas) ** 2 * rng.uniform(0.5, 1.5, (n, 3))
    return q @ d @ np.transpose(q, (0, 2, 1))


def _noisy(rng: np.random.Generator, covs: np.ndarray) -> np.ndarray:
    return np.einsum("nij,nj->ni", np.linalg.cholesky(covs), rng.normal(size=covs.shape[:2]))


@pytest.fixture(scope="module")
def trials():
    rng = np.random.default_rng(424242)
    t = truth()
    frame0 = np.eye(4)
    frame0[:3, :3] = enu_rotation(0.0, 0.0).T
    frame0[:3, 3] = geodetic_to_ecef_closed_form(0.0, 0.0, 0.0)
    local = rng.uniform(-12, 12, (8, 3))
    local[:, 2] = rng.uniform(-1, 4, 8)
    x_true = local @ frame0[:3, :3].T + frame0[:3, 3]   # the scene's current frame
    true_sim = Similarity.from_matrix(t.matrix() @ np.linalg.inv(frame0))
    y_true = true_sim.apply(x_true)
    cx = _random_covs(rng, 8, (0.004, 0.004, 0.012))     # scene units (the scene is 2.7x small)
    cy = enu_covariances(y_true, np.full(8, 0.01), np.full(8, 0.02))
    probes_local = np.array([[0.0, 0, 1], [40.0, 0, 0], [0, -120.0, 5], [300.0, 200.0, 0]])
    probes_x = probes_local @ frame0[:3, :3].T + frame0[:3, 3]
    probes_y = true_sim.apply(probes_x)
    cp = _random_covs(rng, 4, (0.003, 0.003, 0.009))
    out = {k: [] for k in ("z_scale", "q7", "q_frame", "q_total", "q7_low", "q_total_low")}
    for _ in range(TRIALS):
        xn = x_true + _noisy(rng, cx)
        yn = y_true + _noisy(rng, cy)
        f = fit_similarity(xn, yn, cx, cy)
        s = f.similarity
        out["z_scale"].append((s.scale - true_sim.scale) / f.scale_sigma())
        # the true frame as a perturbation of the fitted one about its centre c
        delta = Similarity.from_matrix(true_sim.matrix() @ np.linalg.inv(s.matrix()))
        c = f.centre
        d = np.concatenate([delta.apply(c) - c, _rotvec(delta.rotation), [delta.scale - 1]])
        cinv = np.linalg.inv(f.covariance)
        out["q7"].append(d @ cinv @ d)
        out["q7_low"].append(d @ cinv @ d / 0.64)
        frame = FrameCovariance(c, f.covariance)
        mapped = s.apply(probes_x)
        cf = frame.point_covariances(mapped)
        e = mapped - probes_y
        out["q_frame"].append(np.einsum("ni,nij,nj->n", e, np.linalg.inv(cf), e))
        pn = probes_x + _noisy(rng, cp)
        a = s.scale * s.rotation
        ct = cf + np.einsum("ik,nkl,jl->nij", a, cp, a)
        e = s.apply(pn) - probes_y
        q = np.einsum("ni,nij,nj->n", e, np.linalg.inv(ct), e)
        out["q_total"].append(q)
        out["q_total_low"].append(q / 0.64)
    return {k: np.asarray(v) for k, v in out.items()}


def _coverage(q: np.ndarray, dof: int) -> np.ndarray:
    return np.mean(q <= CHI2_95[dof], axis=0)


def test_scale_sigma_is_calibrated(trials):
    cov = np.mean(np.abs(trials["z_scale"]) <= 1.959964)
    assert abs(cov - 0.95) <= 0.015, cov
    assert abs(np.mean(trials["z_scale"])) < 0.05  # no bias beyond 5 % of a sigma


def test_seven_parameter_covariance_is_calibrated(trials):
    cov = _coverage(trials["q7"], 7)
    assert abs(cov - 0.95) <= 0.015, cov


def test_propagated_point_covariance_is_calibrated_inside_and_far_outside(trials):
    for name in ("q_frame", "q_total"):
        cov = _coverage(trials[name], 3)  # one figure per probe point
        assert np.all(np.abs(cov - 0.95) <= 0.015), (name, cov)


def test_understated_covariances_fail_the_same_check(trials):
    assert _coverage(trials["q7_low"], 7) < 0.90
    assert np.all(_coverage(trials["q_total_low"], 3) < 0.90)
