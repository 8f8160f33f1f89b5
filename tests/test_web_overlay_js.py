"""When the measuring overlay may be repainted without a frame of the scene (web/js/overlay.js's
sameView), in Node.js: a camera set back where it was (float round-off) is the same view; a
move of 1 mm, a turn of 1e-6 rad, another canvas size or field of view is not."""

from __future__ import annotations

import shutil

import numpy as np
import pytest

from tests.nodejs import run_web_module

pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")


def view_matrix(position, yaw: float) -> list[float]:
    """A camera's view matrix (column-major, world -> camera) at ECEF `position` (m), turned by
    `yaw` (rad) about the world z axis."""
    c, s = np.cos(yaw), np.sin(yaw)
    r = np.array([[c, s, 0.0], [-s, c, 0.0], [0.0, 0.0, 1.0]])
    m = np.eye(4)
    m[:3, :3] = r
    m[:3, 3] = -r @ np.asarray(position, float)
    return m.T.reshape(-1).tolist()


def same(a: dict, b: dict) -> bool:
    return run_web_module("overlay.js", "console.log(JSON.stringify(M.sameView(...data)));", [a, b])


def test_a_camera_set_back_is_the_same_view_and_any_real_change_is_not():
    pos = np.array([3978000.5, -8300.25, 4968000.75])  # ECEF near London (m)
    base = {"matrix": view_matrix(pos, 0.3), "fovy": 0.6, "width": 1280, "height": 720}
    # set back by way of the camera's position and direction (round-off of ~1e-9 m)
    back = {**base, "matrix": (np.asarray(base["matrix"]) * (1 + 1e-15)).tolist()}
    assert same(base, back)
    assert not same(base, {**base, "matrix": view_matrix(pos + [0.001, 0, 0], 0.3)})
    assert not same(base, {**base, "matrix": view_matrix(pos, 0.3 + 1e-6)})
    assert not same(base, {**base, "width": 1279})
    assert not same(base, {**base, "fovy": 0.61})
    assert not same(base, None)
