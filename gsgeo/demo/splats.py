"""Gaussian splats sampled on the demo scene's analytic geometry (`gsgeo.demo.scene`).

Surfaces become flat splats lying in the surface (two in-plane sizes from the sampling step,
a thin size along the normal); poles and rails thin splats around their axis; the ground's
texture and the building's materials are colour variations; every validation point gets a
marker: a black/white checker disc for targets and a small red dot exactly at every
validation point (the centre of a disc, a corner, the centre of a pole top).

All positions are in the scene frame (x east, y north, z up, metres). Deterministic: one
generator seeded with :data:`SEED`, used in a fixed order.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.demo import scene

SEED = 20261122
SH_C0 = 0.28209479177387814
#: Colour of the dot on every validation point (RGB 0..1).
MARKER_RGB = (0.9, 0.05, 0.05)
#: Standard deviation (m) of a marker dot.
MARKER_SIZE = 0.01
#: Sampling steps (m).
GROUND_STEP = 0.09
BUILDING_STEP = 0.05
DETAIL_STEP = 0.02
TARGET_STEP = 0.0125   # 40 cells across a disc: none at the centre, which holds the truth dot
#: Offset of a target's disc above its surface (m), so that it covers the surface splats.
TARGET_LIFT = 0.002


@dataclass
class Part:
    """Splats in plain arrays: positions (N, 3) m, sigmas (N, 3) m along the splat's axes,
    axes (N, 3, 3) with the splat axes as columns, rgb (N, 3) 0..1, alpha (N,) 0..1."""

    positions: np.ndarray
    sigmas: np.ndarray
    axes: np.ndarray
    rgb: np.ndarray
    alpha: np.ndarray

    @staticmethod
    def concatenate(parts: list[Part]) -> Part:
        return Part(*(np.concatenate([getattr(p, f) for p in parts])
                      for f in ("positions", "sigmas", "axes", "rgb", "alpha")))


def _flat(points: np.ndarray, t1: ArrayLike, t2: ArrayLike, step: float, rgb: np.ndarray, thin: float = 0.002,
          alpha: float = 0.97) -> Part:
    """Flat splats at points (N, 3) lying in the plane spanned by unit t1, t2."""
    n = len(points)
    t1 = np.broadcast_to(np.asarray(t1, float), (n, 3))
    t2 = np.broadcast_to(np.asarray(t2, float), (n, 3))
    normal = np.cross(t1, t2)
    axes = np.stack([t1, t2, normal], axis=-1)
    sig = np.tile([0.6 * step, 0.6 * step, thin], (n, 1))
    return Part(points, sig, axes, np.clip(rgb, 0, 1), np.full(n, alpha))


def _grid(u0: float, u1: float, v0: float, v1: float, step: float) -> tuple[np.ndarray, np.ndarray]:
    """Cell-centred grid over [u0, u1] x [v0, v1] (flattened u, v)."""
    nu = max(1, int(round((u1 - u0) / step)))
    nv = max(1, int(round((v1 - v0) / step)))
    u = u0 + (np.arange(nu) + 0.5) * (u1 - u0) / nu
    v = v0 + (np.arange(nv) + 0.5) * (v1 - v0) / nv
    uu, vv = np.meshgrid(u, v, indexing="ij")
    return uu.ravel(), vv.ravel()


def _noise2d(rng: np.random.Generator, x: np.ndarray, y: np.ndarray, waves: int = 12,
             scale: tuple[float, float] = (0.3, 6.0)) -> np.ndarray:
    """Smooth procedural noise in about [-1, 1]: a sum of plane waves of random direction,
    wavelength between scale[0] and scale[1] metres, and phase."""
    ang = rng.uniform(0, 2 * np.pi, waves)
    lam = np.exp(rng.uniform(np.log(scale[0]), np.log(scale[1]), waves))
    ph = rng.uniform(0, 2 * np.pi, waves)
    k = 2 * np.pi / lam
    out = np.zeros_like(x)
    for a, kk, p in zip(ang, k, ph, strict=True):   # a dozen waves, vectorised over points
        out += np.sin(kk * (x * np.cos(a) + y * np.sin(a)) + p)
    return out / np.sqrt(waves / 2)


# --- objects ----------------------------------------------------------------------------------

def _ground(rng: np.random.Generator) -> Part:
    h = scene.GROUND_HALF
    x, y = _grid(-h, h, -h, h, GROUND_STEP)
    x = x + rng.uniform(-0.3, 0.3, x.size) * GROUND_STEP
    y = y + rng.uniform(-0.3, 0.3, y.size) * GROUND_STEP
    x0, x1 = scene.BUILDING_X
    y0, y1 = scene.BUILDING_Y
    keep = ~((x > x0) & (x < x1) & (y > y0) & (y < y1))
    for vp in scene.VALIDATION_POINTS:   # the targets' discs replace the ground under them
        if vp.kind == "target" and vp.xyz[2] == 0.0:
            keep &= (x - vp.xyz[0]) ** 2 + (y - vp.xyz[1]) ** 2 > (scene.TARGET_RADIUS + 0.02) ** 2
    x, y = x[keep], y[keep]
    n1 = _noise2d(rng, x, y, scale=(0.4, 8.0))
    n2 = _noise2d(rng, x, y, scale=(0.1, 0.6))
    grass = np.stack([0.30 + 0.06 * n1, 0.45 + 0.08 * n1, 0.18 + 0.04 * n1], -1)
    soil = np.array([0.45, 0.38, 0.28])
    mix = np.clip(0.5 + 0.5 * n2 - 0.3, 0, 1)[:, None] * 0.6
    rgb = grass * (1 - mix) + soil * mix
    # a paved apron around the building and a path to the south, with slab joints
    apron = (x > x0 - 1.5) & (x < x1 + 1.5) & (y > y0 - 1.5) & (y < y1 + 1.5)
    path = (np.abs(x + 9.0) < 1.0) & (y < y0)
    paved = apron | path
    joint = (np.abs(((x + 0.3) % 0.6) - 0.3) < 0.03) | (np.abs(((y + 0.3) % 0.6) - 0.3) < 0.03)
    slab = np.array([0.62, 0.61, 0.58]) + 0.03 * n2[:, None]
    rgb = np.where(paved[:, None], np.where(joint[:, None], slab * 0.6, slab), rgb)
    rgb = rgb + rng.normal(0, 0.025, rgb.shape)
    pts = np.stack([x, y, np.zeros_like(x)], -1)
    return _flat(pts, [1, 0, 0], [0, 1, 0], GROUND_STEP, rgb)


def _wall_colour(u: np.ndarray, z: np.ndarray, windows: list[tuple[float, float, float, float]],
                 rng: np.random.Generator) -> np.ndarray:
    """Brick courses (7.5 cm) with window rectangles (u0, u1, z0, z1) in dark glass."""
    course = np.floor(z / 0.075)
    tint = (np.sin(course * 12.9898 + np.floor((u + 0.1125 * (course % 2)) / 0.225) * 78.233)
            * 43758.5453) % 1.0
    rgb = np.stack([0.58 + 0.10 * tint, 0.27 + 0.05 * tint, 0.20 + 0.04 * tint], -1)
    for u0, u1, z0, z1 in windows:
        inside = (u > u0) & (u < u1) & (z > z0) & (z < z1)
        frame = inside & ~((u > u0 + 0.06) & (u < u1 - 0.06) & (z > z0 + 0.06) & (z < z1 - 0.06))
        rgb = np.where(inside[:, None], [0.16, 0.20, 0.26], rgb)
        rgb = np.where(frame[:, None], [0.92, 0.92, 0.90], rgb)
    return rgb + rng.normal(0, 0.02, rgb.shape)


def _building(rng: np.random.Generator) -> Part:
    x0, x1 = scene.BUILDING_X
    y0, y1 = scene.BUILDING_Y
    ez, rz, ry = scene.EAVES_Z, scene.RIDGE_Z, scene.RIDGE_Y
    st = BUILDING_STEP
    parts = []
    win_long = [(u, u + 1.2, 1.0, 2.4) for u in (1.0, 3.2, 5.6, 7.8)] + \
               [(u, u + 1.2, 3.0, 4.3) for u in (1.0, 3.2, 5.6, 7.8)]
    win_short = [(1.0, 2.2, 3.0, 4.3), (4.8, 6.0, 3.0, 4.3), (2.9, 4.1, 0.0, 2.2)]
    # long walls (south y = y0 facing -y, north y = y1 facing +y), u along x from x0
    for y, sgn in ((y0, -1.0), (y1, 1.0)):
        u, z = _grid(0, x1 - x0, 0, ez, st)
        pts = np.stack([x0 + u, np.full_like(u, y), z], -1)
        t1 = [1.0, 0, 0] if sgn > 0 else [-1.0, 0, 0]
        parts.append(_flat(pts, t1, [0, 0, 1.0], st, _wall_colour(u, z, win_long, rng)))
    # gable walls (west x = x0 facing -x, east x = x1 facing +x), u along y from y0, up to roof
    s = (rz - ez) / (ry - y0)
    for x, sgn in ((x0, -1.0), (x1, 1.0)):
        u, z = _grid(0, y1 - y0, 0, rz, st)
        top = ez + s * np.minimum(u, (y1 - y0) - u)
        keep = z < top
        u, z = u[keep], z[keep]
        pts = np.stack([np.full_like(u, x), y0 + u, z], -1)
        t1 = [0, -1.0, 0] if sgn > 0 else [0, 1.0, 0]
        parts.append(_flat(pts, t1, [0, 0, 1.0], st, _wall_colour(u, z, win_short, rng)))
    # roof slopes: u along x, v up the slope from the eaves
    slope_len = float(np.hypot(ry - y0, rz - ez))
    for sgn in (1.0, -1.0):   # south slope rises towards +y, north towards -y
        u, v = _grid(0, x1 - x0, 0, slope_len, st)
        f = v / slope_len
        ys = (y0 + f * (ry - y0)) if sgn > 0 else (y1 - f * (y1 - ry))
        z = ez + f * (rz - ez)
        pts = np.stack([x0 + u, ys, z], -1)
        up_slope = np.array([0.0, sgn * (ry - y0), rz - ez]) / slope_len
        t1 = [1.0, 0, 0] if sgn > 0 else [-1.0, 0, 0]
        row = np.floor(v / 0.25)
        shade = 0.28 + 0.04 * ((row % 2) * 2 - 1) + 0.03 * np.sin(u * 7.1 + row * 3.3)
        rgb = np.stack([shade, shade * 1.02, shade * 1.12], -1) + rng.normal(0, 0.015, (u.size, 3))
        parts.append(_flat(pts, t1, up_slope, st, rgb))
    return Part.concatenate(parts)


def _cylinder(a: ArrayLike, b: ArrayLike, radius: float, around: int, step: float,
              rgb: ArrayLike, rng: np.random.Generator,
              cap: bool = True) -> Part:
    """Splats on the side of a cylinder (axis a -> b) and on its top cap at b."""
    a, b = np.asarray(a, float), np.asarray(b, float)
    axis = b - a
    length = float(np.linalg.norm(axis))
    w = axis / length
    ref = np.array([0.0, 0.0, 1.0]) if abs(w[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    e1 = np.cross(w, ref)
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(w, e1)
    n_ax = max(2, int(round(length / step)))
    s = (np.arange(n_ax) + 0.5) / n_ax * length
    phi = np.arange(around) * 2 * np.pi / around
    ss_grid, pp_grid = np.meshgrid(s, phi + np.pi / around, indexing="ij")
    ss, pp = ss_grid.ravel(), pp_grid.ravel()
    radial = np.cos(pp)[:, None] * e1 + np.sin(pp)[:, None] * e2
    pts = a + ss[:, None] * w + radius * radial
    tang = np.cross(w, radial)
    n = len(pts)
    axes = np.stack([tang, np.broadcast_to(w, (n, 3)), radial], axis=-1)
    sig = np.tile([0.6 * 2 * np.pi * radius / around, 0.6 * length / n_ax, 0.0015], (n, 1))
    col = np.clip(np.asarray(rgb) + rng.normal(0, 0.02, (n, 3)), 0, 1)
    parts = [Part(pts, sig, axes, col, np.full(n, 0.98))]
    if cap:   # a ring on the top face (the centre holds the marker dot)
        ring = np.arange(6) * np.pi / 3
        rr = radius * 0.6
        cpts = b + rr * (np.cos(ring)[:, None] * e1 + np.sin(ring)[:, None] * e2)
        m = len(cpts)
        caxes = np.broadcast_to(np.stack([e1, e2, w], axis=-1), (m, 3, 3))
        csig = np.tile([0.45 * radius, 0.45 * radius, 0.0015], (m, 1))
        parts.append(Part(cpts, csig, caxes.copy(), np.tile(np.asarray(rgb) * 0.9, (m, 1)),
                          np.full(m, 0.98)))
    return Part.concatenate(parts)


def _poles(rng: np.random.Generator) -> Part:
    parts = []
    for x, y in scene.POLES_XY:
        parts.append(_cylinder([x, y, 0], [x, y, scene.POLE_HEIGHT], scene.POLE_RADIUS, 12,
                               DETAIL_STEP, [0.22, 0.25, 0.24], rng))
    for x in scene.RAIL_POSTS_X:
        parts.append(_cylinder([x, scene.RAIL_Y, 0], [x, scene.RAIL_Y, scene.RAIL_POST_HEIGHT],
                               scene.RAIL_POST_RADIUS, 8, DETAIL_STEP, [0.75, 0.72, 0.20], rng))
    for z in scene.RAIL_HEIGHTS:
        parts.append(_cylinder([scene.RAIL_POSTS_X[0], scene.RAIL_Y, z],
                               [scene.RAIL_POSTS_X[-1], scene.RAIL_Y, z], scene.RAIL_RADIUS, 8,
                               DETAIL_STEP, [0.75, 0.72, 0.20], rng, cap=False))
    return Part.concatenate(parts)


def _sculpture(rng: np.random.Generator) -> Part:
    c = scene.sculpture_corners()            # top corners (-u,-v), (+u,-v), (+u,+v), (-u,+v)
    base = c.copy()
    base[:, 2] = 0.0
    st = DETAIL_STEP
    parts = []
    stone = np.array([0.86, 0.84, 0.80])

    def quad(p00: np.ndarray, p10: np.ndarray, p01: np.ndarray,
             top_fn: object = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Samples of the parallelogram p00 + s (p10 - p00) + t (p01 - p00)."""
        e1, e2 = p10 - p00, p01 - p00
        l1, l2 = np.linalg.norm(e1), np.linalg.norm(e2)
        s, t = _grid(0, 1, 0, 1, st / float(max(l1, l2)))
        pts = p00 + s[:, None] * e1 + t[:, None] * e2
        return pts, e1 / l1, e2 / l2

    # top (sloped plane through the 4 top corners)
    pts, t1, t2 = quad(c[0], c[1], c[3])
    rgb = stone + rng.normal(0, 0.02, (len(pts), 3))
    parts.append(_flat(pts, t1, t2, st, rgb))
    # sides: from the base edge up to the top edge (the top is sloped: sample a rectangle up to
    # the highest corner and keep what lies below the top plane)
    for i in range(4):
        j = (i + 1) % 4
        h = max(c[i, 2], c[j, 2])
        p00, p10 = base[i], base[j]
        p01 = base[i] + np.array([0, 0, h])
        pts, t1, t2 = quad(p00, p10, p01)
        s = np.linalg.norm(pts[:, :2] - base[i, :2], axis=1) / np.linalg.norm(base[j, :2] - base[i, :2])
        top = c[i, 2] + s * (c[j, 2] - c[i, 2])
        keep = pts[:, 2] < top
        pts = pts[keep]
        # t1 along the edge from i to j turns the normal outwards (corners are counter-clockwise)
        rgb = stone * 0.92 + rng.normal(0, 0.02, (len(pts), 3))
        parts.append(_flat(pts, t1, t2, st, rgb))
    return Part.concatenate(parts)


def _targets(rng: np.random.Generator) -> Part:
    parts = []
    r = scene.TARGET_RADIUS
    for vp in scene.VALIDATION_POINTS:
        if vp.kind != "target":
            continue
        n = np.asarray(vp.normal)
        ref = np.array([1.0, 0, 0]) if abs(n[0]) < 0.9 else np.array([0, 1.0, 0])
        t2 = np.cross(n, ref)
        t2 /= np.linalg.norm(t2)
        t1 = np.cross(t2, n)
        u, v = _grid(-r, r, -r, r, TARGET_STEP)
        rad = np.hypot(u, v)
        keep = rad <= r
        u, v, rad = u[keep], v[keep], rad[keep]
        white = (u > 0) == (v > 0)
        rgb = np.where(white[:, None], [0.95, 0.95, 0.95], [0.04, 0.04, 0.04])
        rgb = np.where((rad > r - 0.03)[:, None], [0.95, 0.95, 0.95], rgb)   # white rim
        pts = np.asarray(vp.xyz) + TARGET_LIFT * n + u[:, None] * t1 + v[:, None] * t2
        parts.append(_flat(pts, t1, t2, TARGET_STEP, rgb, thin=0.001, alpha=0.99))
    return Part.concatenate(parts)


def _marker_dots() -> Part:
    """One dot exactly on every validation point (the truth)."""
    pts = scene.truth_array()
    n = len(pts)
    return Part(pts, np.full((n, 3), MARKER_SIZE), np.broadcast_to(np.eye(3), (n, 3, 3)).copy(),
                np.tile(MARKER_RGB, (n, 1)), np.full(n, 0.99))


#: Direction towards the sun (east, north, up) for the baked shading.
SUN = np.array([0.4, -0.5, 0.77]) / np.linalg.norm([0.4, -0.5, 0.77])


def _shade(part: Part) -> Part:
    """Baked lighting, as trained splats have it: faces turned differently differ in
    brightness, so edges and corners show. Relative to a horizontal surface (factor 1)."""
    cos = np.abs(part.axes[:, :, 2] @ SUN)   # the sign of a flat splat's normal is arbitrary
    f = (0.45 + 0.55 * cos) / (0.45 + 0.55 * SUN[2])
    return Part(part.positions, part.sigmas, part.axes, np.clip(part.rgb * f[:, None], 0, 1),
                part.alpha)


def build_part() -> Part:
    """Every splat of the demo scene (about 340 000), deterministic."""
    rng = np.random.default_rng(SEED)
    lit = _shade(Part.concatenate([_ground(rng), _building(rng), _poles(rng), _sculpture(rng),
                                   _targets(rng)]))
    return Part.concatenate([lit, _marker_dots()])


# --- INRIA PLY ----------------------------------------------------------------------------------

def _quat_wxyz(axes: np.ndarray) -> np.ndarray:
    """Quaternions (N, 4) w, x, y, z of proper rotation matrices (N, 3, 3)."""
    from gsgeo.tiles.splats import matrix_to_quat

    q = matrix_to_quat(axes)            # x, y, z, w
    return np.concatenate([q[:, 3:], q[:, :3]], axis=1)


def write_ply(path: str | os.PathLike, part: Part) -> int:
    """Write splats as an INRIA 3DGS PLY (binary little endian, float32, SH degree 0) with
    plyfile, atomically (temporary file beside ``path``, then rename). Returns the count."""
    from plyfile import PlyData, PlyElement

    n = len(part.positions)
    names = ["x", "y", "z", "nx", "ny", "nz", "f_dc_0", "f_dc_1", "f_dc_2", "opacity",
             "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    rec = np.zeros(n, dtype=[(k, "<f4") for k in names])
    for i, k in enumerate("xyz"):
        rec[k] = part.positions[:, i]
        rec["n" + k] = part.axes[:, i, 2]
    f_dc = (part.rgb - 0.5) / SH_C0
    for i in range(3):
        rec[f"f_dc_{i}"] = f_dc[:, i]
        rec[f"scale_{i}"] = np.log(part.sigmas[:, i])
    a = np.clip(part.alpha, 1e-4, 1 - 1e-4)
    rec["opacity"] = np.log(a / (1 - a))
    q = _quat_wxyz(part.axes)
    for i in range(4):
        rec[f"rot_{i}"] = q[:, i]
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    PlyData([PlyElement.describe(rec, "vertex")], byte_order="<").write(str(tmp))
    os.replace(tmp, path)
    return n
