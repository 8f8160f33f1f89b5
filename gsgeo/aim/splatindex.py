"""A scene's splats as the aiming aids need them, read once per tileset version and cached.

Only what ray queries use is kept: centres (float32 offsets from a float64 centre, so ECEF
sized coordinates keep millimetres), standard deviations along the splat axes (metres),
orientations (unit quaternions x, y, z, w turning splat axes into ECEF) and alpha (0..1).
Everything is in the tileset's own ECEF (EPSG:4978 as the tileset places it, metres), i.e.
before the viewer's modelMatrix.

A tileset refined by ADD (as ``gsgeo tiles`` writes it) holds every splat in exactly one
tile, so the union of all tiles is the scene at full detail.
"""

from __future__ import annotations

import math
import os
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles.reader import iter_tileset
from gsgeo.tiles.splats import matrix_to_quat, quat_multiply

#: A splat reaches this many standard deviations from its centre (3DGS renderers cut there).
EXTENT_SIGMAS = 3.0
#: Tilesets kept in memory at once (least recently used dropped first).
CACHE_SIZE = 2


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

    def subset(self, keep: np.ndarray) -> SplatIndex:
        """The splats selected by a boolean mask or index array (same centre)."""
        return SplatIndex(self.centre, np.ascontiguousarray(self.offsets[:, keep]),
                          self.sigmas[keep], self.quats[keep], self.alpha[keep],
                          self.reach[keep])

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
