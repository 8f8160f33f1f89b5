"""A small synthetic 3DGS scene with known marker points, written as an INRIA PLY.

The scene is in a local ENU frame (x east, y north, z up, metres) that `gsgeo tiles
--origin LAT,LON,H` puts on the Earth: a 10 x 10 m checkerboard ground at z = 0, a box
of 2 x 2 x 1.5 m at the centre with differently coloured faces, and small bright marker
splats at the points in MARKERS (their ENU coordinates are the ground truth).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from plyfile import PlyData, PlyElement

SH_C0 = 0.28209479177387814

#: Ground truth of the markers in the scene's local ENU frame, metres.
MARKERS = {
    "roof_ne": (1.0, 1.0, 1.5),     # top north-east corner of the box
    "ground_sw": (-3.0, -2.5, 0.0),  # a ground mark south-west of the box
    "roof_c": (0.0, 0.0, 1.5),     # centre of the box top
}


def _grid(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    u, v = np.meshgrid(a, b, indexing="ij")
    return u.ravel(), v.ravel()


def scene_splats() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(positions (N, 3), colours RGB in 0..1 (N, 3), radii (N,)) of the scene."""
    pos, col, rad = [], [], []
    # ground: 10 x 10 m checkerboard, 1 m squares, splats every 0.1 m
    x, y = _grid(np.arange(-5.0, 5.0001, 0.1), np.arange(-5.0, 5.0001, 0.1))
    pos.append(np.c_[x, y, np.zeros_like(x)])
    dark = (np.floor(x + 1e-6) + np.floor(y + 1e-6)) % 2 == 0
    col.append(np.where(dark[:, None], [0.25, 0.3, 0.25], [0.75, 0.78, 0.7]))
    rad.append(np.full(x.shape, 0.06))
    # box faces, spacing 0.08 m
    s = np.arange(-1.0, 1.0001, 0.08)
    h = np.arange(0.0, 1.5001, 0.08)
    faces = [
        (np.c_[_grid(s, s)[0], _grid(s, s)[1], np.full(s.size ** 2, 1.5)], [0.85, 0.55, 0.2]),
        (np.c_[np.full(s.size * h.size, 1.0), *_grid(s, h)], [0.3, 0.45, 0.85]),
        (np.c_[np.full(s.size * h.size, -1.0), *_grid(s, h)], [0.3, 0.75, 0.4]),
        (np.c_[_grid(s, h)[0], np.full(s.size * h.size, 1.0), _grid(s, h)[1]], [0.8, 0.3, 0.6]),
        (np.c_[_grid(s, h)[0], np.full(s.size * h.size, -1.0), _grid(s, h)[1]], [0.9, 0.85, 0.3]),
    ]
    for p, c in faces:
        pos.append(p)
        col.append(np.tile(c, (p.shape[0], 1)))
        rad.append(np.full(p.shape[0], 0.05))
    # markers: a small white disc with a red centre
    for m in MARKERS.values():
        ring = np.array(m) + 0.04 * np.c_[np.cos(np.arange(8) * np.pi / 4),
                                          np.sin(np.arange(8) * np.pi / 4), np.zeros(8)]
        pos.append(np.vstack([ring, [m]]))
        col.append(np.vstack([np.tile([1.0, 1.0, 1.0], (8, 1)), [[1.0, 0.0, 0.0]]]))
        rad.append(np.r_[np.full(8, 0.02), 0.015])
    return np.vstack(pos), np.vstack(col), np.concatenate(rad)


def write_scene_ply(path: Path) -> Path:
    """Write the scene as a binary INRIA 3DGS PLY (SH degree 0) and return the path."""
    pos, col, rad = scene_splats()
    n = pos.shape[0]
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    v = np.zeros(n, dtype=[(k, "f4") for k in names])
    v["x"], v["y"], v["z"] = pos.T
    f_dc = (col - 0.5) / SH_C0
    v["f_dc_0"], v["f_dc_1"], v["f_dc_2"] = f_dc.T
    v["opacity"] = 5.0  # logit: alpha 0.993
    for k in ("scale_0", "scale_1", "scale_2"):
        v[k] = np.log(rad)
    v["rot_0"] = 1.0
    PlyData([PlyElement.describe(v, "vertex")]).write(str(path))
    return path
