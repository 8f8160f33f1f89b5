"""gsgeo.aim.snap: a click 1-2 px off a point feature is moved onto it (a checker target's
centre, a corner, a small dot), against the feature's known position in images drawn here by
supersampling (each pixel the mean of 8 x 8 samples, then a Gaussian blur as a renderer's
filtering); an edge, a flat patch and a feature too far from the click leave the click where
it was, with the reason."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from gsgeo.aim.snap import MAX_SHIFT_PX, snap_click

#: The feature, window coordinates of the image's own pixels (px); the image sits at ORIGIN.
FEATURE = np.array([31.37, 30.81])
ORIGIN = np.array([200.0, 120.0])
TURN = np.radians(20)


def drawn(fn, size: int = 64, ss: int = 8, blur: float = 0.7) -> np.ndarray:
    """Grey image (0-255) of intensity fn(x, y) (0-1) in image coordinates, pixel (i, j)
    covering [j, j + 1) x [i, i + 1)."""
    ys, xs = np.mgrid[0:size * ss, 0:size * ss]
    v = fn((xs + 0.5) / ss, (ys + 0.5) / ss).astype(np.float64)
    img = v.reshape(size, ss, size, ss).mean(axis=(1, 3))
    return (cv2.GaussianBlur(img, (0, 0), blur) * 255).astype(np.float32)


def axes(x, y):
    dx, dy = x - FEATURE[0], y - FEATURE[1]
    return dx * np.cos(TURN) + dy * np.sin(TURN), -dx * np.sin(TURN) + dy * np.cos(TURN)


def checker(x, y):
    u, v = axes(x, y)
    return ((u > 0) == (v > 0)) * 0.9 + 0.05


def foreshortened_checker(x, y):
    """A checker target on the ground seen obliquely: one axis squeezed to a third."""
    u, v = axes(x, y)
    return ((u > 0) == (3 * v > 0)) * 0.9 + 0.05


def corner(x, y):
    u, v = axes(x, y)
    return ((u > 0) & (v > 0)) * 0.8 + 0.1


def dot(x, y):
    return 0.2 + 0.6 * np.exp(-((x - FEATURE[0]) ** 2 + (y - FEATURE[1]) ** 2) / 2.0)


def edge(x, y):
    u, _ = axes(x, y)
    return (u > 0) * 0.8 + 0.1


def flat(x, y):
    return np.full_like(x, 0.5) + 0.01 * np.sin(x * 3) * np.cos(y * 2)


def clicks_about(centre: np.ndarray, r: float, n: int = 8) -> list[np.ndarray]:
    t = 2 * np.pi * np.arange(n) / n
    return [centre + r * np.array([np.cos(a), np.sin(a)]) for a in t]


@pytest.mark.parametrize("fn, tol", [(checker, 0.1), (foreshortened_checker, 0.15),
                                     (corner, 0.25), (dot, 0.15)])
@pytest.mark.parametrize("off_px", [1.0, 1.5, 2.0])
def test_a_click_beside_a_point_feature_lands_on_it(fn, tol, off_px):
    img = drawn(fn)
    truth = FEATURE + ORIGIN
    for click in clicks_about(truth, off_px):
        s = snap_click(img, ORIGIN, click)
        assert s.ok, s.reason
        assert np.linalg.norm(s.pixel - truth) < tol, (s.pixel, truth)
        assert s.moved_px == pytest.approx(np.linalg.norm(click - truth), abs=tol)


@pytest.mark.parametrize("fn, reason", [(edge, "point feature"), (flat, "")])
def test_an_edge_or_a_flat_patch_keeps_the_click(fn, reason):
    img = drawn(fn)
    for click in clicks_about(FEATURE + ORIGIN, 1.5):
        s = snap_click(img, ORIGIN, click)
        assert not s.ok and reason in s.reason, s
        assert np.array_equal(s.pixel, click)


def test_a_feature_further_than_the_limit_is_not_taken():
    img = drawn(checker)
    click = FEATURE + ORIGIN + np.array([MAX_SHIFT_PX + 0.6, 0.0])
    s = snap_click(img, ORIGIN, click)
    assert not s.ok and np.array_equal(s.pixel, click), s
    # nearer than the limit it is
    assert snap_click(img, ORIGIN, FEATURE + ORIGIN + np.array([MAX_SHIFT_PX - 0.6, 0.0])).ok


def test_a_click_at_the_edge_of_its_image_is_left_alone():
    img = drawn(checker)
    s = snap_click(img, ORIGIN, ORIGIN + np.array([2.0, 30.0]))
    assert not s.ok and "edge of its image" in s.reason


def test_a_corner_seen_only_in_colour_is_placed_by_its_colours():
    """A red roof's corner against a grey of the same brightness (an eaves corner against a
    wall): grey alone has nothing to snap to; the colour image, projected on its colours'
    principal axis, puts the click on the corner."""
    red, grey = np.array([0.1, 0.1, 0.8]), np.array([0.29, 0.29, 0.29])  # BGR, luma ~0.29 both
    inside = drawn(corner) / 255.0
    share = (inside - inside.min()) / (inside.max() - inside.min())
    bgr = (share[..., None] * red + (1 - share[..., None]) * grey) * 255
    luma = cv2.cvtColor(bgr.astype(np.float32), cv2.COLOR_BGR2GRAY)
    assert np.ptp(luma) < 0.05 * np.ptp(bgr)
    truth = FEATURE + ORIGIN
    for click in clicks_about(truth, 1.5):
        assert not snap_click(luma, ORIGIN, click).ok
        s = snap_click(bgr.astype(np.float32), ORIGIN, click)
        assert s.ok, s.reason
        assert np.linalg.norm(s.pixel - truth) < 0.25


def test_a_corner_in_brightness_under_strong_colour_noise_is_placed_by_its_brightness():
    """A dark corner on grass whose colours vary more than its brightness steps (the colours'
    principal axis runs along the noise): the brightness places it."""
    luma = np.array([0.114, 0.587, 0.299])
    chroma = np.cross(luma, [1.0, 0.0, 0.0])
    chroma /= np.linalg.norm(chroma)  # a colour change that keeps the brightness
    share = drawn(corner) / 255.0
    rng = np.random.default_rng(7)
    noise = cv2.GaussianBlur(rng.normal(0, 1, share.shape), (0, 0), 0.8)
    noise *= 0.45 / noise.std()
    bgr = 0.35 + (share[..., None] - 0.5) * 0.25 * luma / luma.sum() * 3 + noise[..., None] * chroma
    bgr = (np.clip(bgr, 0, 1) * 255).astype(np.float32)
    truth = FEATURE + ORIGIN
    for click in clicks_about(truth, 1.5):
        s = snap_click(bgr, ORIGIN, click)
        assert s.ok, s.reason
        assert np.linalg.norm(s.pixel - truth) < 0.3
