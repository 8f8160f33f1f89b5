"""Inputs of `gsgeo tiles`: a 3DGS file opened for reading splats by index range.

:func:`open_source` returns a :class:`Source` for an INRIA PLY (binary or ASCII), a
PlayCanvas/SuperSplat compressed PLY or an SPZ file. ``read(start, stop)`` gives the splats
[start, stop) in the file's frame; it may be called from worker processes forked after
opening (binary PLY ranges are read with pread on a descriptor each process opens itself).
"""

from __future__ import annotations

import stat
from pathlib import Path

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles import ply, spz
from gsgeo.tiles.splats import Splats

#: The scene centre (origin of the root ENU frame) is the centre of the bounding box of this
#: many splat centres spread through the file; the true extent is checked after reading.
CENTRE_SAMPLE = 16_384


class Source:
    """A splat file: ``count``, ``sh_degree``, ``size_bytes``, ``bounds()`` and ``read()``."""

    count: int
    sh_degree: int
    size_bytes: int

    def bounds(self) -> tuple[np.ndarray, np.ndarray, int]:
        """(lo, hi, n): box of finite centres (file frame) and how many were looked at."""
        raise NotImplementedError

    def read(self, start: int, stop: int) -> Splats:
        """Splats [start, stop) in the file's frame. Arrays may be views of a buffer that
        the next call overwrites."""
        raise NotImplementedError

    def read_finite(self, start: int, stop: int) -> tuple[Splats, np.ndarray]:
        """:meth:`read` and the splats' :meth:`~gsgeo.tiles.splats.Splats.finite_mask`."""
        s = self.read(start, stop)
        return s, s.finite_mask()


class _BinaryPly(Source):
    def __init__(self, layout: ply.PlyLayout, block: int) -> None:
        self.layout = layout
        self.count, self.sh_degree, self.size_bytes = layout.count, layout.sh_degree, \
            layout.size_bytes
        self.reader = ply.RecordReader(layout, block)
        dt = layout.dtype
        uniform = all(dt[i] == np.dtype("<f4") for i in range(len(ply.field_names(dt))))
        self._ones = np.ones(len(ply.field_names(dt)), np.float32) if uniform else None

    def bounds(self) -> tuple[np.ndarray, np.ndarray, int]:
        lo, hi, n = ply.ply_bounds(self.layout, sample=CENTRE_SAMPLE)
        if n == 0:   # the sample may have missed the few finite ones: look at all
            lo, hi, n = ply.ply_bounds(self.layout)
        return lo, hi, n

    def read(self, start: int, stop: int) -> Splats:
        return ply.records_to_splats(self.reader.read(start, stop), self.layout)

    def read_finite(self, start: int, stop: int) -> tuple[Splats, np.ndarray]:
        rec = self.reader.read(start, stop)
        s = ply.records_to_splats(rec, self.layout)
        if self._ones is None:
            return s, s.finite_mask()
        # All-float32 records: one matrix-vector product screens every value of a record (a
        # sum is finite only if each term is); the few records it flags (a non-finite value,
        # perhaps in a property gsgeo ignores, or a sum beyond float32) get the exact check.
        with np.errstate(over="ignore", invalid="ignore"):
            ok = np.isfinite(rec.view(np.float32).reshape(rec.shape[0], -1) @ self._ones)
        ok &= np.einsum("ij,ij->i", s.rotations, s.rotations) > 0
        if not ok.all():
            bad = np.flatnonzero(~ok)
            ok[bad] = s.take(bad).finite_mask()
        return s, ok


class _InMemory(Source):
    """ASCII PLY (read whole with plyfile) and SPZ (decoded whole): sliced per range."""

    def __init__(self, splats: Splats, sh_degree: int, size_bytes: int) -> None:
        self.splats = splats
        self.count, self.sh_degree, self.size_bytes = splats.count, sh_degree, size_bytes

    def bounds(self) -> tuple[np.ndarray, np.ndarray, int]:
        p = self.splats.positions
        p = p[np.isfinite(p).all(axis=1)]
        if not p.size:
            return np.zeros(3), np.zeros(3), 0
        return p.min(axis=0), p.max(axis=0), int(p.shape[0])

    def read(self, start: int, stop: int) -> Splats:
        return self.splats.take(slice(start, stop))


class _CompressedPly(Source):
    def __init__(self, layout: ply.CompressedLayout) -> None:
        self.layout = layout
        self.count, self.sh_degree, self.size_bytes = layout.count, layout.sh_degree, \
            layout.size_bytes

    def bounds(self) -> tuple[np.ndarray, np.ndarray, int]:
        return ply.compressed_bounds(self.layout)

    def read(self, start: int, stop: int) -> Splats:
        return ply.read_compressed(self.layout, start, stop)


def open_source(path: str | Path, block: int = 16_384) -> Source:
    """Open a .ply or .spz input; ``block`` is the largest range a binary PLY read serves
    from its buffer without reallocating."""
    path = Path(path)
    if "\0" in str(path):
        raise InputError("the input path holds a NUL character")
    try:
        st = path.stat()
    except OSError as exc:
        raise InputError(f"{path}: cannot open ({exc.strerror})") from None
    if not stat.S_ISREG(st.st_mode):
        raise InputError(f"{path}: not a regular file")
    suffix = path.suffix.lower()
    if suffix == ".spz":
        try:
            data = path.read_bytes()
        except OSError as exc:
            raise InputError(f"{path}: cannot read ({exc.strerror})") from None
        s = spz.decode(data)[0]
        return _InMemory(s, s.sh_degree, len(data))
    if suffix != ".ply":
        raise InputError(f"{path}: unsupported input; expected a .ply or .spz file")
    layout = ply.read_layout(path)
    if isinstance(layout, ply.CompressedLayout):
        return _CompressedPly(layout)
    if layout.fmt == "ascii":
        rec = ply.read_ascii_records(layout)
        s = ply.records_to_splats(rec, layout)
        return _InMemory(s, layout.sh_degree, layout.size_bytes)
    return _BinaryPly(layout, block)
