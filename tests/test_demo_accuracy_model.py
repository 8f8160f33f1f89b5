"""The building blocks of benchmarks/accuracy.py against hand-computed geometry: the DSM
raster and its ray marching, the 3-D smoothed surface, the view selection and the multi-ray
run (without noise it must return the truth)."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from gsgeo.demo import scene

_spec = importlib.util.spec_from_file_location(
    "accuracy_bench", Path(__file__).resolve().parents[1] / "benchmarks" / "accuracy.py")
acc = importlib.util.module_from_spec(_spec)
sys.modules["accuracy_bench"] = acc   # dataclasses look their module up there
_spec.loader.exec_module(acc)


@pytest.fixture(scope="module")
def dsm_sharp():
    ds, mem = acc.build_dsm(0.0)
    with mem, ds:
        assert ds.crs.to_epsg() == 27700
        return acc.DsmSampler(ds)


def test_dsm_heights(dsm_sharp):
    # cell centres well inside: ground, ridge line, south eaves strip
    z = dsm_sharp(np.array([0.025, -8.975, -8.975]), np.array([-1.975, 5.525, 2.025]))
    np.testing.assert_allclose(z[0], 0.0, atol=1e-6)
    assert z[1] == pytest.approx(7.5 - 2.5 / 3.5 * 0.025, abs=0.01)
    assert z[2] == pytest.approx(5.0 + 2.5 / 3.5 * 0.025, abs=0.01)
    assert math.isnan(dsm_sharp(np.array([25.0]), np.array([0.0]))[0])   # outside the raster


def test_march_hits_ground_and_roof(dsm_sharp):
    o = np.array([[0.0, -2.0, 30.0], [-9.0, 3.75, 30.0], [5.0, 5.0, 10.0], [0.0, 0.0, 10.0]])
    d = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [1.0, 0.0, -1.0], [0.0, 0.0, 1.0]])
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    p = acc.march(dsm_sharp, o, d)
    np.testing.assert_allclose(p[0], [0.0, -2.0, 0.0], atol=2e-3)
    np.testing.assert_allclose(p[1], [-9.0, 3.75, 6.25], atol=0.01)
    np.testing.assert_allclose(p[2], [15.0, 5.0, 0.0], atol=2e-3)       # 45 degrees down
    assert np.all(np.isnan(p[3]))                                       # looking up: no hit


def test_smoothed_mesh_keeps_flat_ground_and_loses_a_pole():
    target = np.array([0.0, -2.0, 0.0])
    mesh = acc.LocalMesh(target, 0.05)
    o = np.array([[0.3, -2.0, 20.0]])
    d = (target - o) / np.linalg.norm(target - o)
    np.testing.assert_allclose(acc.mesh_march(mesh, target, o, d)[0], target, atol=2e-3)
    # an 8 cm pole smoothed with sigma 5 cm: occupancy on its axis below 0.5, no surface
    top = np.array([*scene.POLES_XY[0], scene.POLE_HEIGHT])
    pole = acc.LocalMesh(top, 0.05)
    assert pole(top[None] - [0, 0, 0.3])[0] < 0.5
    o = top + np.array([[0.0, -10.0, 10.0]])
    d = (top - o) / np.linalg.norm(top - o)
    assert np.all(np.isnan(acc.mesh_march(pole, top, o, d)))


def test_usable_views_are_visible_and_in_range():
    origins, axes, kinds = acc.survey_views()
    assert len(origins) == 5 * 121 + 36
    truth = scene.truth_array()
    cand = acc.usable_views(origins, axes, truth)
    for p, c in zip(truth, cand, strict=True):
        assert len(c) >= 10
        assert np.all(np.linalg.norm(origins[c] - p, axis=1) <= acc.MAX_RANGE)
        assert np.all(scene.visible(origins[c], np.broadcast_to(p, origins[c].shape)))


def test_multi_ray_without_noise_returns_the_truth():
    origins, axes, _ = acc.survey_views()
    truth = scene.truth_array()
    cand = acc.usable_views(origins, axes, truth)
    errs, pred = acc.multi_ray(origins, truth, cand, 1e-9, 3, 5)
    assert np.abs(errs).max() < 1e-6
    # and with 1 px noise the errors scale with the predicted sigma (same order)
    errs, pred = acc.multi_ray(origins, truth, cand, 1.0, 5, 200)
    ratio = np.sqrt(np.mean(np.sum(errs**2, -1))) / np.sqrt(np.mean(pred**2))
    assert 0.85 < ratio < 1.15
