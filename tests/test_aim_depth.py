"""The depth hint along a ray (gsgeo.aim.depth) on synthetic splats with a known surface."""

from __future__ import annotations

import numpy as np
from aim_helpers import EAST, NORTH, UP, index_of, plane_splats, to_ecef, wall_splats

from gsgeo.aim.depth import SKY, depth_hint


def _floaters(rng: np.random.Generator, n: int = 400):
    local = rng.uniform([-5, -5, 0.3], [5, 5, 4], (n, 3))
    q = np.tile([0.0, 0.0, 0.0, 1.0], (n, 1))
    return to_ecef(local), np.full((n, 3), 0.02), q, np.full(n, 0.05)


def test_depth_of_a_plane_with_scattered_splats_within_a_few_cm(rng):
    index = index_of(plane_splats(), _floaters(rng))
    target = to_ecef([0.7, -1.3, 0.0])
    for k, (az, el) in enumerate([(30, 40), (200, 60), (300, 25)]):
        a, b = np.radians(az), np.radians(el)
        back = np.cos(b) * (np.sin(a) * EAST + np.cos(a) * NORTH) + np.sin(b) * UP
        origin = target + (12.0 + k) * back
        hint = depth_hint(index, origin, target - origin, ifov=1e-3)
        assert hint.hit, hint.reason
        assert abs(hint.depth_m - (12.0 + k)) < 0.03
        assert np.linalg.norm(hint.point - target) < 0.03
        assert hint.near_m < hint.depth_m < hint.far_m
        assert hint.far_m - hint.near_m < 1.0
        assert hint.n_splats > 0 and hint.reason is None


def test_a_ray_into_empty_sky_is_no_hit_with_the_reason(rng):
    index = index_of(plane_splats(), _floaters(rng))
    origin = to_ecef([0.0, 0.0, 2.0])
    hint = depth_hint(index, origin, UP + 0.2 * EAST, ifov=1e-3)
    assert not hint.hit
    assert hint.depth_m is None and hint.point is None and hint.near_m is None
    assert hint.reason == SKY
    assert hint.to_json()["reason"] == SKY


def test_a_faint_haze_is_no_hit_and_says_how_faint(rng):
    n = 20   # faint splats straight along the ray: 1 - 0.98^20 = 0.33 in all
    local = np.column_stack([rng.normal(0, 0.01, n), rng.normal(0, 0.01, n),
                             np.linspace(1, 5, n)])
    index = index_of((to_ecef(local), np.full((n, 3), 0.1), np.tile([0.0, 0, 0, 1], (n, 1)),
                      np.full(n, 0.02)))
    origin = to_ecef([0.0, 0.0, 10.0])
    hint = depth_hint(index, origin, -UP, ifov=1e-3)
    assert not hint.hit
    assert hint.reason.startswith(SKY) and "opacity" in hint.reason


def test_the_model_matrix_is_undone_and_the_answer_given_in_the_rendered_frame():
    index = index_of(plane_splats())
    m = np.eye(4)
    m[:3, 3] = [30.0, -20.0, 5.0]                 # the viewer moved the tileset
    target = to_ecef([1.0, 1.0, 0.0])
    origin_t = target + 8.0 * UP + 6.0 * EAST      # 10 m from the target, tileset frame
    origin_r = origin_t + m[:3, 3]
    hint = depth_hint(index, origin_r, target - origin_t, ifov=1e-3, model_matrix=m)
    assert hint.hit
    assert abs(hint.depth_m - 10.0) < 0.03
    assert np.linalg.norm(hint.point - (target + m[:3, 3])) < 0.03


def test_the_surface_normal_of_flat_splats(rng):
    index = index_of(plane_splats(), wall_splats(3.0))
    origin = to_ecef([-4.0, 1.0, 6.0])
    hint = depth_hint(index, origin, to_ecef([0.5, 0.2, 0.0]) - origin, ifov=1e-3)
    assert hint.normal is not None and hint.normal @ UP > 0.999      # the ground
    hint = depth_hint(index, origin, to_ecef([3.0, 0.5, 2.0]) - origin, ifov=1e-3)
    assert hint.normal is not None and hint.normal @ -EAST > 0.999   # the wall, facing us
    assert hint.to_json()["normal_ecef"] == hint.normal.tolist()
    # round splats have no normal
    n = 2000
    local = np.column_stack([rng.uniform(-2, 2, n), rng.uniform(-2, 2, n), np.zeros(n)])
    blobs = index_of((to_ecef(local), np.full((n, 3), 0.05), np.tile([0.0, 0, 0, 1], (n, 1)),
                      np.full(n, 0.9)))
    assert depth_hint(blobs, origin, to_ecef([0.0, 0.0, 0.0]) - origin, 1e-3).normal is None
