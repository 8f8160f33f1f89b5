"""Monte-Carlo: the reported 1-sigma of volume, ridge, eaves and measured height and footprint
area are calibrated.

1000 noisy measurements of one gable house (each roof point with its own correlated,
anisotropic covariance; the ground a measured point too): the spread of each quantity across
the trials must match the sigma the model reports (within 10 %), and the 95 % intervals must
cover the truth about 95 % of the time.
"""

from __future__ import annotations

import numpy as np
from buildings_helpers import GABLE, GABLE_ROOFS, GABLE_VOLUME, GROUND, OFFSET

from gsgeo.buildings.model import build_building
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import GeometryError

TRIALS = 1000


def covariances(rng: np.random.Generator, ids: list[str]) -> dict[str, np.ndarray]:
    """A fixed random covariance per point: sigmas 1.5-4 cm, H worse, correlated."""
    out = {}
    for pid in ids:
        q = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        s = rng.uniform(0.015, 0.04, 3) * np.array([1.0, 1.0, 1.5])
        out[pid] = q @ np.diag(s ** 2) @ q.T
    return out


def test_volume_and_height_sigmas_are_calibrated():
    rng = np.random.default_rng(20261124)
    truth = {k: np.asarray(v, float) + OFFSET + np.array([0, 0, GROUND]) for k, v in GABLE.items()}
    truth["G"] = OFFSET + np.array([6.0, -3.0, GROUND])
    cov = covariances(rng, list(truth))
    chol = {k: np.linalg.cholesky(c) for k, c in cov.items()}
    spec = parse_building({"id": "B1", "roofs": GABLE_ROOFS, "ground": "G"})
    names = ("volume", "ridge_height", "eaves_height", "measured_height", "footprint_area")
    true_values = {"volume": GABLE_VOLUME, "ridge_height": GROUND + 9,
                   "eaves_height": GROUND + 6, "measured_height": 9.0, "footprint_area": 96.0}
    values = {k: [] for k in names}
    sigmas = {k: [] for k in names}
    refused = 0
    noise = rng.normal(size=(TRIALS, len(truth), 3))
    for t in range(TRIALS):
        pts = {k: (truth[k] + chol[k] @ noise[t, i], cov[k]) for i, k in enumerate(truth)}
        try:
            m = build_building(spec, pts).measures
        except GeometryError:
            refused += 1  # the chi-square tests refuse ~0.1 % of honest data each
            continue
        for k in names:
            values[k].append(m[k])
            sigmas[k].append(m["sigma_" + k])
    assert refused <= 0.01 * TRIALS
    report = {}
    for k in names:
        v = np.array(values[k])
        s = np.array(sigmas[k])
        empirical = float(v.std(ddof=1))
        reported = float(np.sqrt(np.mean(s ** 2)))
        coverage = float(np.mean(np.abs(v - true_values[k]) <= 1.96 * s))
        report[k] = (empirical, reported, coverage)
        assert abs(empirical / reported - 1) < 0.10, (k, empirical, reported)
        assert 0.93 <= coverage <= 0.97, (k, coverage)
    print(report)
