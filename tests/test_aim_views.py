"""Suggested views (gsgeo.aim.views) on synthetic splats: checked by an independent projection,
gsgeo.solve's covariance of the rays alone, and walls that hide the point."""

from __future__ import annotations

import math
import time

import numpy as np
from aim_helpers import EAST, NORTH, UP, index_of, plane_splats, to_ecef, wall_splats
from hypothesis_profiles import examples

from gsgeo.aim.views import (
    MIN_SEPARATION_DEG,
    NONPLANAR_MAX_DEG,
    Occlusion,
    planar_about,
    suggest_views,
)
from gsgeo.solve import intersect

FOVY, W, H = math.radians(60.0), 1280.0, 720.0
POINT = to_ecef([0.0, 0.0, 0.0])


def _project(cam: dict, p: np.ndarray) -> np.ndarray:
    """The contract's projection, written out again (not gsgeo.aim.camera)."""
    pos, fwd, up = (np.asarray(cam[k], float) for k in ("position", "direction", "up"))
    d = p - pos
    right = np.cross(fwd, up)
    f = cam["height"] / (2 * math.tan(cam["fovy"] / 2))
    return np.array([cam["width"] / 2 + f * (d @ right) / (d @ fwd),
                     cam["height"] / 2 - f * (d @ up) / (d @ fwd)])


def _rays(*backs: np.ndarray, dist: float = 15.0) -> tuple[np.ndarray, np.ndarray]:
    o = np.array([POINT + dist * b / np.linalg.norm(b) for b in backs])
    return o, POINT - o


def test_views_see_the_point_at_wide_angles_and_shrink_its_sigma():
    index = index_of(plane_splats())
    o, d = _rays(0.3 * EAST + UP, -0.6 * NORTH + 0.4 * UP)
    ifov = np.full(2, 1e-3)
    views = suggest_views(index, o, d, ifov, POINT, 4, FOVY, W, H)
    assert len(views) == 4
    cov = intersect(o, d, ifov=ifov, sigma_px=1.0).covariance
    sigma_without = math.sqrt(np.trace(cov))
    unit = d / np.linalg.norm(d, axis=1, keepdims=True)
    backs = []
    for v in views:
        js = v.to_json()
        cam = js["camera"]
        xy = _project(cam, POINT)
        assert 0 <= xy[0] <= W and 0 <= xy[1] <= H
        assert np.linalg.norm(xy - [W / 2, H / 2]) < 1.0          # looking at the point
        look = POINT - np.asarray(cam["position"])
        look /= np.linalg.norm(look)
        angles = np.degrees(np.arccos(np.clip(unit @ look, -1, 1)))
        assert abs(angles.min() - v.min_angle_deg) < 1e-6
        assert v.min_angle_deg > 30.0
        assert v.predicted_sigma_m < sigma_without
        assert abs(v.range_m - 15.0) < 1e-6
        assert np.asarray(cam["up"]) @ UP > 0.3                      # up as local up
        assert not v.occluded
        backs.append(-look)
    backs = np.array(backs)
    cos = backs @ backs.T - 2 * np.eye(len(backs))
    assert np.degrees(np.arccos(cos.max())) >= MIN_SEPARATION_DEG - 1e-6   # spread
    assert np.ptp([v.azimuth_deg for v in views]) > 90.0


def test_a_wall_hides_the_views_behind_it():
    index = index_of(plane_splats(), wall_splats(2.0, top=8.0))
    occ = Occlusion(index, POINT, None, 1e-3)
    assert occ.hidden(POINT + 15.0 * (0.9 * EAST + 0.3 * UP) / np.linalg.norm([0.9, 0.3]))
    assert not occ.hidden(POINT + 15.0 * (-0.9 * EAST + 0.3 * UP) / np.linalg.norm([0.9, 0.3]))
    o, d = _rays(-EAST + 0.5 * UP)
    views = suggest_views(index, o, d, np.array([1e-3]), POINT, 6, FOVY, W, H)
    for v in views:
        assert not v.occluded
        # independently: the line of sight does not cross the wall (east = 2 m, north
        # -5..5 m, up to 8 m)
        c = v.camera.position - POINT
        e, n, u = c @ EAST, c @ NORTH, c @ UP
        if e > 2.0:
            s = 2.0 / e
            assert not (abs(s * n) < 5.0 and s * u < 8.0), v
    assert any(v.camera.position @ EAST - POINT @ EAST > 2.0 for v in views) or len(views) == 6


def test_a_point_walled_in_gets_views_flagged_occluded():
    box = [wall_splats(1.5, top=6.0), wall_splats(-1.5, top=6.0)]
    # the same walls turned by 90 degrees: swap east and north
    for part in list(box):
        pos, sig, q, a = part
        local = (pos - POINT) @ np.stack([EAST, NORTH, UP], axis=1)
        turned = local[:, [1, 0, 2]]
        box.append((to_ecef(turned), sig[:, [1, 0, 2]], q, a))
    lid = plane_splats(half=2.0, height=6.0)
    index = index_of(plane_splats(), *box, lid)
    o, d = _rays(UP + 0.1 * EAST)
    views = suggest_views(index, o, d, np.array([1e-3]), POINT, 3, FOVY, W, H)
    assert len(views) == 3
    assert all(v.occluded for v in views)


def test_views_are_quick_after_the_first_call():
    index = index_of(plane_splats(half=10.0, step=0.04), wall_splats(2.0))   # ~250 000 splats
    o, d = _rays(-EAST + UP)
    suggest_views(index, o, d, np.array([1e-3]), POINT, 4, FOVY, W, H)
    t0 = time.perf_counter()
    suggest_views(index, o, d, np.array([1e-3]), POINT, 4, FOVY, W, H)
    assert time.perf_counter() - t0 < 0.5


def test_views_and_depth_answer_whatever_the_rays():
    """Random rays and points (near or far, inside the splats or above): always an answer with
    finite numbers, never an exception."""
    from hypothesis import given, settings
    from hypothesis import strategies as st

    from gsgeo.aim.depth import depth_hint

    index = index_of(plane_splats(half=3.0, step=0.1), wall_splats(1.0, half=3.0, top=3.0))
    local = st.tuples(st.floats(-50, 50), st.floats(-50, 50), st.floats(-5, 50))

    @settings(max_examples=examples(40), deadline=None)
    @given(origins=st.lists(local, min_size=1, max_size=4), point=local,
           k=st.integers(1, 12), ifov=st.one_of(st.none(), st.floats(1e-5, 1e-2)))
    def check(origins, point, k, ifov):
        o = to_ecef(np.array(origins))
        p = to_ecef(point)
        if np.min(np.linalg.norm(o - p, axis=1)) < 1e-2:
            return
        f = None if ifov is None else np.full(len(o), ifov)
        views = suggest_views(index, o, p - o, f, p, k, FOVY, W, H)
        assert 1 <= len(views) <= k
        for v in views:
            assert math.isfinite(v.predicted_sigma_m) and math.isfinite(v.min_angle_deg)
        hint = depth_hint(index, o[0], p - o[0], ifov)
        assert hint.hit == (hint.depth_m is not None)
        if hint.hit:
            assert 0 <= hint.near_m <= hint.depth_m <= hint.far_m

    check()


def test_views_do_not_see_the_ground_at_grazing_incidence():
    """A point on flat ground clicked from 45 degrees elevation: the views suggested see the
    ground at 20 degrees or more (a 10-degree view showed a ground marker as a sliver no
    matcher finds; they were chosen first for their wide angle to the ray)."""
    index = index_of(plane_splats())
    for az in (200.0, 30.0):
        a, e = math.radians(az), math.radians(45.0)
        o = np.array([POINT + 12.0 * (math.cos(e) * math.sin(a) * EAST
                                      + math.cos(e) * math.cos(a) * NORTH + math.sin(e) * UP)])
        views = suggest_views(index, o, POINT - o, np.array([1e-3]), POINT, 4, FOVY, W, H)
        assert len(views) == 4
        assert min(v.elevation_deg for v in views) >= 20.0, [v.elevation_deg for v in views]
        for v in views:
            back = np.asarray(v.camera.position) - POINT
            assert back @ UP / np.linalg.norm(back) > math.sin(math.radians(20.0))
        # without the splats (no surface known) the choice is the covariance's alone
        free = suggest_views(None, o, POINT - o, np.array([1e-3]), POINT, 4, FOVY, W, H)
        assert len(free) == 4


def test_views_of_a_corner_stay_near_the_first_ray():
    """The foot of a wall (ground and wall splats about the point: not one plane) clicked
    from the west at 45 degrees, views asked for the splat-shaped matcher: every view lies
    within NONPLANAR_MAX_DEG of the click's ray,
    at least MIN_SEPARATION_DEG from it, and they are spread round it; the same click on the
    ground alone gets wider views (the plane's warp holds there)."""
    a = math.radians(45.0)
    o = np.array([POINT + 12.0 * (-math.cos(a) * EAST + math.sin(a) * UP)])
    d = POINT - o
    corner = index_of(plane_splats(), wall_splats(0.0, top=4.0))
    assert not planar_about(corner, POINT, 0.4)
    assert planar_about(index_of(plane_splats()), POINT, 0.4)
    views = suggest_views(corner, o, d, np.array([1e-3]), POINT, 4, FOVY, W, H,
                          shape_views=True)
    assert len(views) == 4
    unit = d[0] / np.linalg.norm(d[0])
    backs = []
    for v in views:
        look = POINT - v.camera.position
        look /= np.linalg.norm(look)
        angle = math.degrees(math.acos(float(np.clip(look @ unit, -1, 1))))
        assert MIN_SEPARATION_DEG - 1e-6 <= angle <= NONPLANAR_MAX_DEG + 1e-6, angle
        assert (v.camera.position - POINT) @ EAST < 0            # the wall's west side
        backs.append(-look)
    backs = np.array(backs)
    cos = backs @ backs.T - 2 * np.eye(len(backs))
    assert np.degrees(np.arccos(cos.max())) >= MIN_SEPARATION_DEG - 1e-6
    wide = suggest_views(index_of(plane_splats()), o, d, np.array([1e-3]), POINT, 4, FOVY, W, H,
                         shape_views=True)
    assert max(v.min_angle_deg for v in wide) > 60.0
    # not asked for (the plain matcher's views): the corner's are wide too
    plain = suggest_views(corner, o, d, np.array([1e-3]), POINT, 4, FOVY, W, H)
    assert max(v.min_angle_deg for v in plain) > 60.0
