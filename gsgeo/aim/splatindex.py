"""A scene's splats as the aiming aids need them, read once per tileset version and cached.

Only what ray queries use is kept: centres (float32 offsets from a float64 centre, so ECEF
sized coordinates keep millimetres), standard deviations along the splat axes (metres),
orientations (unit quaternions x, y, z, w turning splat axes into ECEF) and alpha (0..1).
Everything is in the tileset's own ECEF (EPSG:4978 as the tileset places it, metres), i.e.
before the viewer's modelMatrix.

A tileset refined by ADD (as ``gsgeo tiles`` writes it) holds every splat in exactly one
tile, so the union of all tiles is the scene at full detail (a REPLACE tileset's coarse
levels would be counted on top of its fine ones).

The splats are stored in Z-order (the widest 5 % apart), in blocks of BLOCK with a box each:
a ray query first keeps the blocks whose box it passes, then tests only their splats.
"""

from __future__ import annotations

import math
import os
import threading
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles.reader import iter_tileset
from gsgeo.tiles.splats import matrix_to_quat, quat_multiply, quat_to_matrix

#: A splat reaches this many standard deviations from its centre (3DGS renderers cut there).
EXTENT_SIGMAS = 3.0
#: Splats per block of the coarse search structure.
BLOCK = 128
#: The share of splats, the largest, kept in blocks of their own.
BIG_QUANTILE = 0.95
#: Tilesets kept in memory at once (least recently used dropped first).
CACHE_SIZE = 2


def morton_order(points: np.ndarray) -> np.ndarray:
    """The permutation (N,) sorting points (N, 3) along a Z-order curve over their bounding
    box (10 bits per axis): neighbours in space end up near each other in the arrays."""
    if points.shape[0] == 0:
        return np.zeros(0, dtype=np.int64)
    lo = points.min(axis=0)
    span = np.maximum(points.max(axis=0) - lo, 1e-9)
    q = np.clip((points - lo) / span * 1023.0, 0, 1023).astype(np.uint64)
    code = np.zeros(points.shape[0], dtype=np.uint64)
    for axis in range(3):
        v = q[:, axis]
        v = (v | (v << np.uint64(16))) & np.uint64(0x030000FF)
        v = (v | (v << np.uint64(8))) & np.uint64(0x0300F00F)
        v = (v | (v << np.uint64(4))) & np.uint64(0x030C30C3)
        v = (v | (v << np.uint64(2))) & np.uint64(0x09249249)
        code |= v << np.uint64(axis)
    return np.argsort(code, kind="stable")


@dataclass(frozen=True, eq=False)
class SplatIndex:
    """N splats in the tileset's ECEF (metres).

    centre : (3,) float64; offsets : (3, N) float32 rows x, y, z (contiguous each), the
    centres minus ``centre``; sigmas : (N, 3) float32 standard deviations along the splat
    axes; quats : (N, 4) float32 unit quaternions x, y, z, w (splat axes -> ECEF);
    alpha : (N,) float32 opacity 0..1; reach : (N,) float32, EXTENT_SIGMAS times the
    largest sigma (metres): no part of the splat lies farther from its centre.
    """

    centre: np.ndarray
    offsets: np.ndarray
    sigmas: np.ndarray
    quats: np.ndarray
    alpha: np.ndarray
    reach: np.ndarray

    @property
    def count(self) -> int:
        return int(self.alpha.shape[0])

    @cached_property
    def rotations(self) -> np.ndarray:
        """(N, 3, 3) float32 rotation matrices of ``quats`` (splat axes -> ECEF), made once:
        every ray query needs those of the splats it touches."""
        return quat_to_matrix(self.quats).astype(np.float32)

    @cached_property
    def blocks(self) -> tuple[np.ndarray, np.ndarray]:
        """Boxes (lo, hi), each (B, 3) offsets, of consecutive runs of BLOCK splats (reach
        included): the splats are stored in Z-order, so each run is compact in space and a
        query first skips the boxes it cannot touch."""
        n = self.count
        starts = np.arange(0, n, BLOCK)
        if n == 0:
            return np.zeros((0, 3), np.float32), np.zeros((0, 3), np.float32)
        lo = np.stack([np.minimum.reduceat(self.offsets[k] - self.reach, starts)
                       for k in range(3)], axis=1)
        hi = np.stack([np.maximum.reduceat(self.offsets[k] + self.reach, starts)
                       for k in range(3)], axis=1)
        return lo, hi

    def gather(self, blocks: np.ndarray) -> np.ndarray:
        """The splat indices (sorted) of the given block numbers."""
        b = np.asarray(blocks, dtype=np.int64)
        if b.size == 0:
            return np.zeros(0, dtype=np.int64)
        idx = (b[:, None] * BLOCK + np.arange(BLOCK)[None, :]).ravel()
        return idx[idx < self.count]

    @cached_property
    def block_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """Centres (B, 3) and radii (B,) of the spheres around the blocks' boxes."""
        lo, hi = self.blocks
        mid = (lo.astype(np.float64) + hi) / 2.0
        half = hi.astype(np.float64) - mid
        return mid, np.sqrt(np.einsum("ij,ij->i", half, half))

    @cached_property
    def block_axes(self) -> tuple[np.ndarray, np.ndarray]:
        """The blocks' boxes as (3, B) float64 rows lo and hi, one contiguous row per axis
        (per-axis arithmetic is several times faster than reductions over a short axis)."""
        lo, hi = self.blocks
        return (np.ascontiguousarray(lo.T, dtype=np.float64),
                np.ascontiguousarray(hi.T, dtype=np.float64))

    def blocks_near_ray(self, origin: np.ndarray, direction: np.ndarray, spread: float,
                        t_max: float | None = None) -> np.ndarray:
        """Block numbers whose box, widened by ``spread`` metres per metre of distance from
        the origin, the ray (offset origin, unit direction) passes through in front of the
        origin (and before ``t_max``): the slab test, one axis at a time."""
        lo, hi = self.block_axes
        o = np.asarray(origin, dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64)
        grow: np.ndarray | float = 0.0
        if spread > 0:
            mid, radius = self.block_spheres
            rel = mid - o
            grow = spread * (np.sqrt(np.einsum("ij,ij->i", rel, rel)) + radius)
        t_in = np.zeros(lo.shape[1])
        t_out = np.full(lo.shape[1], np.inf if t_max is None else float(t_max))
        for k in range(3):
            inv = 1.0 / (d[k] if abs(d[k]) >= 1e-12 else 1e-12)
            t1 = (lo[k] - grow - o[k]) * inv
            t2 = (hi[k] + grow - o[k]) * inv
            if inv < 0:
                t1, t2 = t2, t1
            np.maximum(t_in, t1, out=t_in)
            np.minimum(t_out, t2, out=t_out)
        return np.flatnonzero(t_out >= t_in)

    @classmethod
    def from_arrays(cls, positions: np.ndarray, sigmas: np.ndarray, quats: np.ndarray,
                    alpha: np.ndarray) -> SplatIndex:
        """An index of splats given as arrays: positions (N, 3) ECEF metres, sigmas (N, 3)
        metres, quats (N, 4) x, y, z, w, alpha (N,) 0..1. Non-finite splats are dropped."""
        p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
        s = np.asarray(sigmas, dtype=np.float32).reshape(-1, 3)
        q = np.asarray(quats, dtype=np.float32).reshape(-1, 4)
        a = np.asarray(alpha, dtype=np.float32).reshape(-1)
        qn = np.linalg.norm(q, axis=1)
        ok = np.isfinite(p).all(axis=1) & np.isfinite(s).all(axis=1) & (s > 0).all(axis=1) \
            & np.isfinite(qn) & (qn > 0) & np.isfinite(a) & (a > 0)
        p, s, q, a, qn = p[ok], s[ok], q[ok], a[ok], qn[ok]
        # Z-order, the largest splats apart at the end: they would swell every block's box
        widest = s.max(axis=1, initial=0.0)
        big = widest > np.quantile(widest, BIG_QUANTILE) if len(s) else widest > 0
        order = np.concatenate([np.flatnonzero(~big)[morton_order(p[~big])],
                                np.flatnonzero(big)[morton_order(p[big])]])
        p, s, q, a, qn = p[order], s[order], q[order], a[order], qn[order]
        centre = p.mean(axis=0) if p.shape[0] else np.zeros(3)
        offsets = np.ascontiguousarray((p - centre).T.astype(np.float32))
        return cls(centre, offsets, s, (q / qn[:, None]).astype(np.float32),
                   np.clip(a, 0.0, 1.0).astype(np.float32),
                   (EXTENT_SIGMAS * s.max(axis=1, initial=0.0)).astype(np.float32))

    @classmethod
    def read(cls, tileset: str | os.PathLike[str]) -> SplatIndex:
        """Every splat of an SPZ tileset (gsgeo.tiles.reader), in the tileset's ECEF.

        Only centres, sizes, orientations and opacities are carried into ECEF (the colours'
        spherical harmonics, which the reader would rotate too, are not needed here)."""
        pos, sig, rot, alp = [], [], [], []
        for tile in iter_tileset(tileset, frame="content"):
            m = tile.to_ecef
            lin = m[:3, :3]
            scale = float(np.cbrt(np.linalg.det(lin)))
            if not math.isfinite(scale) or scale <= 0:
                raise InputError(f"{tileset}: tile {tile.uri} has a singular or mirrored "
                                 "transform")
            u, _, vt = np.linalg.svd(lin / scale)
            q = matrix_to_quat(u @ vt).astype(np.float32)
            s = tile.splats
            pos.append(s.positions @ lin.T + m[:3, 3])
            sig.append(np.exp(s.scales.astype(np.float32)) * np.float32(scale))
            rot.append(quat_multiply(np.broadcast_to(q, s.rotations.shape), s.rotations))
            alp.append(1.0 / (1.0 + np.exp(-s.opacities.astype(np.float32))))
        if not pos:
            raise InputError(f"{tileset}: the tileset has no SPZ splat content")
        return cls.from_arrays(np.concatenate(pos), np.concatenate(sig), np.concatenate(rot),
                               np.concatenate(alp))


_cache: dict[tuple[str, int, int], SplatIndex] = {}
_cache_lock = threading.Lock()
_loading: dict[str, threading.Lock] = {}


def scene_index(tileset: str | os.PathLike[str]) -> SplatIndex:
    """The index of a tileset, read at the first call and kept while tileset.json is the
    same file version (modification time and size); a regenerated or re-georeferenced
    scene is read again. Concurrent first calls read it once."""
    path = Path(tileset)
    real = os.path.realpath(path)
    with _cache_lock:
        lock = _loading.setdefault(real, threading.Lock())
    with lock:
        try:
            st = os.stat(real)
        except OSError as exc:
            raise InputError(f"{path}: cannot read the tileset ({exc.strerror})") from None
        key = (real, st.st_mtime_ns, st.st_size)
        with _cache_lock:
            hit = _cache.get(key)
            if hit is not None:
                _cache[key] = _cache.pop(key)  # most recently used last
                return hit
        index = SplatIndex.read(path)
        with _cache_lock:
            for old in [k for k in _cache if k[0] == real]:
                del _cache[old]
            _cache[key] = index
            while len(_cache) > CACHE_SIZE:
                del _cache[next(iter(_cache))]
        return index
