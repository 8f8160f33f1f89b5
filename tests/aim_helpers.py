"""Synthetic scenes for the aiming tests: flat splat planes in an ECEF-sized frame, a tiny
tileset of such a plane, and pinhole cameras as the viewer sends them."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from gsgeo.aim.splatindex import SplatIndex

#: A local frame somewhere on the Earth (ECEF metres): origin and east, north, up axes.
ORIGIN = np.array([3_980_000.0, 10_000.0, 4_966_000.0])
UP = ORIGIN / np.linalg.norm(ORIGIN)
EAST = np.cross([0.0, 0.0, 1.0], UP)
EAST /= np.linalg.norm(EAST)
NORTH = np.cross(UP, EAST)
AXES = np.stack([EAST, NORTH, UP], axis=1)     # local (e, n, u) -> ECEF directions


def to_ecef(local: np.ndarray) -> np.ndarray:
    """Local east/north/up (metres) -> ECEF."""
    return ORIGIN + np.asarray(local, dtype=np.float64) @ AXES.T


def axes_quat() -> np.ndarray:
    """The quaternion (x, y, z, w) of the local axes in ECEF."""
    from gsgeo.tiles.splats import matrix_to_quat

    return matrix_to_quat(AXES)


def plane_splats(half: float = 5.0, step: float = 0.05, height: float = 0.0,
                 alpha: float = 0.95) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Flat splats tiling the local plane u = height over |e|, |n| <= half: positions (ECEF),
    sigmas, quats, alpha."""
    g = np.arange(-half, half + step / 2, step)
    e, n = np.meshgrid(g, g)
    local = np.stack([e.ravel(), n.ravel(), np.full(e.size, height)], axis=1)
    k = local.shape[0]
    sig = np.tile([step * 0.7, step * 0.7, 0.002], (k, 1))
    return to_ecef(local), sig, np.tile(axes_quat(), (k, 1)), np.full(k, alpha)


def wall_splats(e_pos: float, half: float = 5.0, top: float = 6.0, step: float = 0.1
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """An opaque wall at east = e_pos (spanning n in [-half, half], u in [0, top])."""
    n, u = np.meshgrid(np.arange(-half, half, step), np.arange(0.0, top, step))
    local = np.stack([np.full(n.size, e_pos), n.ravel(), u.ravel()], axis=1)
    k = local.shape[0]
    sig = np.tile([0.01, step * 0.8, step * 0.8], (k, 1))
    return to_ecef(local), sig, np.tile(axes_quat(), (k, 1)), np.full(k, 0.98)


def index_of(*parts: tuple[np.ndarray, ...]) -> SplatIndex:
    """One index of several (positions, sigmas, quats, alpha) parts."""
    return SplatIndex.from_arrays(*(np.concatenate([p[i] for p in parts]) for i in range(4)))


def plane_tileset(folder: Path, rng: np.random.Generator) -> np.ndarray:
    """A small SPZ tileset of a flat plane (20 m square at local height 0) in ``folder``, as
    ``gsgeo tiles`` writes it; returns its root transform (4, 4; local ENU -> ECEF)."""
    import json

    from gsgeo.tiles.build import build_tileset
    from gsgeo.tiles.georef import Georeference
    from gsgeo.tiles.ply import write_ply
    from gsgeo.tiles.splats import Splats

    g = np.arange(-10.0, 10.0, 0.1)
    e, n = np.meshgrid(g, g)
    k = e.size
    pos = np.stack([e.ravel(), n.ravel(), np.zeros(k)], axis=1)
    s = Splats(pos, np.log(np.tile([0.07, 0.07, 0.003], (k, 1))).astype(np.float32),
               np.tile([0.0, 0.0, 0.0, 1.0], (k, 1)).astype(np.float32),
               np.full(k, 4.0, dtype=np.float32), rng.normal(0, 0.5, (k, 3)).astype(np.float32),
               np.zeros((k, 0, 3), dtype=np.float32))
    folder.parent.mkdir(parents=True, exist_ok=True)
    ply = folder.parent / f"{folder.name}.ply"
    write_ply(ply, s)
    build_tileset(ply, folder, Georeference("origin", origin=(52.2, 0.13, 10.0)), progress=None)
    doc = json.loads((folder / "tileset.json").read_text())
    return np.array(doc["root"]["transform"], dtype=np.float64).reshape(4, 4).T
