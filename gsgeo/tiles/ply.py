"""3DGS PLY reading (streamed in blocks) and writing.

Accepted layouts of the ``vertex`` element (binary little/big endian or ASCII, any numeric
property types):

- INRIA 3DGS (gsplat, nerfstudio, Postshot, the Inria code, ...): ``x y z [nx ny nz]
  f_dc_0..2 [f_rest_0..K-1] opacity scale_0..2 rot_0..3`` with K = 0, 9, 24 or 45 (SH degree
  0-3). f_rest is channel-major, opacity a logit, scales natural logs, rot w-first.
- The same with 8-bit ``red green blue`` instead of ``f_dc_*`` (some exporters write colours
  that way): f_dc = (c / 255 - 0.5) / C0.
- PlayCanvas/SuperSplat compressed PLY (``chunk`` + packed ``vertex`` [+ ``sh``] elements),
  as SuperSplat and splat-transform write it.

Extra properties are ignored. Anything else is rejected naming the missing properties.
"""

from __future__ import annotations

import os
from collections.abc import Iterable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, cast

import numpy as np
import numpy.typing as npt

from gsgeo.errors import InputError
from gsgeo.tiles.splats import SH_C0, SH_DEGREE_OF, Splats

_TYPES = {
    "char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
    "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
    "float": "f4", "float32": "f4", "double": "f8", "float64": "f8",
}
_REQUIRED = ["x", "y", "z", "opacity", "scale_0", "scale_1", "scale_2",
             "rot_0", "rot_1", "rot_2", "rot_3"]


@dataclass
class CompressedLayout:
    """PlayCanvas/SuperSplat compressed PLY: per 256 splats a ``chunk`` record of bounds, per
    splat four packed u32 (position 11-10-11, rotation 2+10+10+10, log-scale 11-10-11,
    colour RGBA 8-8-8-8), optionally an ``sh`` element of u8 f_rest_* (channel-major)."""
    path: Path
    count: int
    chunk_dtype: np.dtype
    chunk_offset: int
    n_chunks: int
    vertex_dtype: np.dtype
    vertex_offset: int
    sh_dtype: np.dtype | None
    sh_offset: int
    sh_degree: int
    n_rest: int
    fmt: str = "compressed"

    @property
    def size_bytes(self) -> int:
        return os.path.getsize(self.path)


_CHUNK_REQUIRED = ["min_x", "min_y", "min_z", "max_x", "max_y", "max_z", "min_scale_x",
                   "min_scale_y", "min_scale_z", "max_scale_x", "max_scale_y", "max_scale_z"]
_PACKED = ["packed_position", "packed_rotation", "packed_scale", "packed_color"]


def field_names(dtype: np.dtype) -> tuple[str, ...]:
    """The field names of a record dtype (every dtype here is one; () for a plain one)."""
    return dtype.names or ()


def _compressed_layout(path: Path, fmt: str, elements: list[tuple[str, int, list[tuple[str, str]]]],
                       header_end: int) -> CompressedLayout:
    if fmt != "binary_little_endian":
        raise InputError(f"{path}: a compressed PLY must be binary little endian")
    offs, els = {}, {}
    off = header_end
    for name, count, props in elements:
        if any(t == "list" for _, t in props):
            raise InputError(f"{path}: list properties in a compressed PLY")
        dt = np.dtype([(n, "<" + _TYPES[t]) for n, t in props])
        offs[name], els[name] = off, (count, dt)
        off += count * dt.itemsize
    if os.path.getsize(path) < off:
        raise InputError(f"{path}: file is truncated")
    if "chunk" not in els or "vertex" not in els:
        raise InputError(f"{path}: a compressed PLY needs 'chunk' and 'vertex' elements")
    n_chunks, cdt = els["chunk"]
    count, vdt = els["vertex"]
    missing = [n for n in _CHUNK_REQUIRED if n not in field_names(cdt)] + \
        [n for n in _PACKED if n not in field_names(vdt)]
    if missing:
        raise InputError(f"{path}: compressed PLY lacks {', '.join(missing)}")
    colour = [f"{m}_{c}" for c in "rgb" for m in ("min", "max")]
    if any(n in field_names(cdt) for n in colour) and \
            not all(n in field_names(cdt) for n in colour):
        raise InputError(f"{path}: compressed PLY chunks have some colour ranges but not all "
                         f"of {', '.join(colour)}")
    not_u32 = [n for n in _PACKED if vdt[n] != np.dtype("<u4")]
    if not_u32:
        raise InputError(f"{path}: compressed PLY properties {', '.join(not_u32)} must be "
                         "uint (32-bit)")
    if n_chunks * 256 < count:
        raise InputError(f"{path}: {n_chunks} chunks cannot hold {count} splats")
    sh_dt, n_rest = None, 0
    if "sh" in els:
        sh_count, sh_dt = els["sh"]
        n_rest = len(field_names(sh_dt))
        if sh_count != count or n_rest % 3 or n_rest // 3 not in SH_DEGREE_OF:
            raise InputError(f"{path}: the sh element has {n_rest} properties for {sh_count} "
                             f"splats; expected 9, 24 or 45 for {count}")
        absent = [f"f_rest_{i}" for i in range(n_rest) if f"f_rest_{i}" not in field_names(sh_dt)]
        if absent:
            raise InputError(f"{path}: the sh element lacks {', '.join(absent[:3])}")
    return CompressedLayout(path, count, cdt, offs["chunk"], n_chunks, vdt, offs["vertex"],
                            sh_dt, offs.get("sh", 0), SH_DEGREE_OF[n_rest // 3], n_rest)


def _unorm(v: np.ndarray, shift: int, bits: int) -> np.ndarray:
    return ((v >> np.uint32(shift)) & np.uint32((1 << bits) - 1)).astype(np.float32) / \
        np.float32((1 << bits) - 1)


def _lerp3(chunks: np.ndarray, ci: np.ndarray, names: list[str], packed: np.ndarray,
           layout: tuple[tuple[int, int], ...] = ((21, 11), (11, 10), (0, 11))) -> np.ndarray:
    out = np.empty((packed.shape[0], 3), np.float32)
    for i, (shift, bits) in enumerate(layout):
        t = _unorm(packed, shift, bits)
        lo = chunks["min_" + names[i]][ci]
        hi = chunks["max_" + names[i]][ci]
        out[:, i] = lo * (1 - t) + hi * t
    return out


CompressedMaps = tuple[np.ndarray, np.ndarray, "np.ndarray | None"]


def _compressed_maps(layout: CompressedLayout) -> CompressedMaps:
    chunks = np.fromfile(layout.path, layout.chunk_dtype, layout.n_chunks,
                         offset=layout.chunk_offset)
    vert = np.memmap(layout.path, layout.vertex_dtype, "r", layout.vertex_offset,
                     (layout.count,))
    sh_all = None if layout.sh_dtype is None else np.memmap(
        layout.path, layout.sh_dtype, "r", layout.sh_offset, (layout.count,))
    return chunks, vert, sh_all


def read_compressed(layout: CompressedLayout, start: int, stop: int,
                    maps: CompressedMaps | None = None) -> Splats:
    """Splats [start, stop) of a compressed PLY (``maps`` from a previous call may be reused)."""
    chunks, vert, sh_all = maps or _compressed_maps(layout)
    v = np.array(vert[start:stop])
    n = v.shape[0]
    ci = (np.arange(start, start + n) >> 8)
    pos = _lerp3(chunks, ci, ["x", "y", "z"], v["packed_position"]).astype(np.float64)
    scales = _lerp3(chunks, ci, ["scale_x", "scale_y", "scale_z"], v["packed_scale"])
    pr = v["packed_rotation"]
    largest = (pr >> np.uint32(30)).astype(np.int64)
    abc = np.stack([(_unorm(pr, s, 10) - np.float32(0.5)) * np.float32(np.sqrt(2))
                    for s in (20, 10, 0)], axis=1)
    wxyz = np.empty((n, 4), np.float32)
    # the three stored components fill the other slots in ascending order
    slots = np.array([[1, 2, 3], [0, 2, 3], [0, 1, 3], [0, 1, 2]])[largest]
    np.put_along_axis(wxyz, slots, abc, axis=1)
    np.put_along_axis(wxyz, largest[:, None],
                      np.sqrt(np.maximum(0, 1 - (abc * abc).sum(axis=1)))[:, None], axis=1)
    rotations = wxyz[:, [1, 2, 3, 0]]
    pc = v["packed_color"]
    rgb = np.stack([_unorm(pc, s, 8) for s in (24, 16, 8)], axis=1)
    if "min_r" in field_names(layout.chunk_dtype):
        for i, c in enumerate("rgb"):
            lo, hi = chunks[f"min_{c}"][ci], chunks[f"max_{c}"][ci]
            rgb[:, i] = lo * (1 - rgb[:, i]) + hi * rgb[:, i]
    colors = (rgb - np.float32(0.5)) / np.float32(SH_C0)
    alpha = np.clip(_unorm(pc, 0, 8), 0.25 / 255, 254.75 / 255)
    opacities = np.log(alpha) - np.log1p(-alpha)
    k = layout.n_rest // 3
    if k:
        # n_rest > 0 only with an sh element, whose map and dtype are then there
        sh_map = cast(np.ndarray, sh_all)
        b = np.array(sh_map[start:start + n]).view(np.uint8).reshape(n, layout.n_rest)
        sh_names = field_names(cast(np.dtype, layout.sh_dtype))
        b = b[:, np.array([sh_names.index(f"f_rest_{i}") for i in range(layout.n_rest)])]
        nrm = (b.astype(np.float32) + np.float32(0.5)) / np.float32(256)
        nrm[b == 0], nrm[b == 255] = 0.0, 1.0
        sh = ((nrm - np.float32(0.5)) * np.float32(8)).reshape(n, 3, k).transpose(0, 2, 1)
    else:
        sh = np.zeros((n, 0, 3), np.float32)
    return Splats(pos, scales, rotations, opacities.astype(np.float32), colors,
                  np.ascontiguousarray(sh))


def iter_compressed(layout: CompressedLayout, block: int = 65_536) -> Iterator[Splats]:
    """Splats of a compressed PLY in blocks."""
    maps = _compressed_maps(layout)
    for start in range(0, layout.count, block):
        yield read_compressed(layout, start, min(layout.count, start + block), maps)


def compressed_bounds(layout: CompressedLayout) -> tuple[np.ndarray, np.ndarray, int]:
    """Bounds of a compressed PLY's centres from its chunk records (no pass over the splats)."""
    lo, hi = np.full(3, np.inf), np.full(3, -np.inf)
    chunks = np.fromfile(layout.path, layout.chunk_dtype, layout.n_chunks,
                         offset=layout.chunk_offset)
    for i, c in enumerate("xyz"):
        # NaN-ignoring, and quiet when every chunk is NaN (then not finite: n = 0)
        lo[i] = np.fmin.reduce(chunks[f"min_{c}"], initial=np.inf)
        hi[i] = np.fmax.reduce(chunks[f"max_{c}"], initial=-np.inf)
    n = layout.count if np.isfinite(lo).all() and np.isfinite(hi).all() else 0
    return lo, hi, n


@dataclass
class PlyLayout:
    path: Path
    fmt: str                 # binary_little_endian | binary_big_endian | ascii
    count: int
    dtype: np.dtype          # one vertex record
    data_offset: int         # byte offset of the vertex element
    sh_degree: int
    color_mode: str          # "f_dc" or "rgb"
    n_rest: int

    @property
    def size_bytes(self) -> int:
        return os.path.getsize(self.path)


#: A PLY header longer than this is refused (3DGS headers are a few kilobytes).
MAX_HEADER_BYTES = 1 << 20
_FORMATS = ("binary_little_endian", "binary_big_endian", "ascii")


def _header_elements(path: Path, f: BinaryIO) -> tuple[str, list[tuple[str, int, list[tuple[str, str]]]]]:
    """Parse a PLY header from after its magic line: (format, [(element, count, [(property,
    type or "list")])]). Every malformed line is an InputError naming it."""
    fmt = None
    elements: list[tuple[str, int, list[tuple[str, str]]]] = []
    lineno = 1
    while True:
        line = f.readline(MAX_HEADER_BYTES)
        lineno += 1
        if not line:
            raise InputError(f"{path}: PLY header has no end_header")
        if f.tell() > MAX_HEADER_BYTES:
            raise InputError(f"{path}: PLY header is longer than {MAX_HEADER_BYTES} bytes")
        text = line.decode("ascii", "replace")
        words = text.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue     # comments may hold any bytes
        where = f"{path}: PLY header line {lineno}"
        if "\ufffd" in text:
            raise InputError(f"{where}: not ASCII")
        key = words[0]
        if key == "end_header":
            break
        if key == "format":
            if len(words) != 3 or words[1] not in _FORMATS:
                raise InputError(f"{where}: expected 'format ascii|binary_little_endian|"
                                 f"binary_big_endian 1.0', got {text.strip()[:80]!r}")
            fmt = words[1]
        elif key == "element":
            if len(words) != 3 or not (words[2].isascii() and words[2].isdigit()):
                raise InputError(f"{where}: expected 'element NAME COUNT' with a count of 0 "
                                 f"or more, got {text.strip()[:80]!r}")
            elements.append((words[1], int(words[2]), []))
        elif key == "property":
            if not elements:
                raise InputError(f"{where}: property before any element")
            props = elements[-1][2]
            if len(words) == 5 and words[1] == "list":
                if words[2] not in _TYPES or words[3] not in _TYPES:
                    raise InputError(f"{where}: unknown PLY list types {words[2]!r}, "
                                     f"{words[3]!r}")
                entry = (words[4], "list")
            elif len(words) == 3:
                if words[1] not in _TYPES:
                    raise InputError(f"{where}: unknown PLY property type {words[1]!r}")
                entry = (words[2], words[1])
            else:
                raise InputError(f"{where}: expected 'property TYPE NAME' or 'property list "
                                 f"COUNT_TYPE TYPE NAME', got {text.strip()[:80]!r}")
            if any(n == entry[0] for n, _ in props):
                raise InputError(f"{where}: property {entry[0]!r} appears twice in element "
                                 f"{elements[-1][0]!r}")
            props.append(entry)
        else:
            raise InputError(f"{where}: unknown keyword {key[:40]!r}")
    if fmt is None:
        raise InputError(f"{path}: PLY header has no format line")
    return fmt, elements


def read_layout(path: str | os.PathLike) -> PlyLayout | CompressedLayout:
    """Parse the header of a 3DGS PLY and check its vertex properties."""
    path = Path(path)
    try:
        f = open(path, "rb")
    except OSError as exc:
        raise InputError(f"{path}: cannot open ({exc.strerror})") from None
    with f:
        if f.readline(16).strip() != b"ply":
            raise InputError(f"{path}: not a PLY file (no 'ply' magic line)")
        fmt, elements = _header_elements(path, f)
        header_end = f.tell()
    offset = header_end
    vertex = None
    for name, count, props in elements:
        if name == "vertex":
            vertex = (count, props)
            break
        if any(t == "list" for _, t in props):
            raise InputError(f"{path}: list properties before the vertex element are not supported")
        if fmt != "ascii":
            offset += count * sum(np.dtype(_TYPES[t]).itemsize for _, t in props)
    if vertex is None:
        raise InputError(f"{path}: PLY has no 'vertex' element")
    count, props = vertex
    names = [n for n, _ in props]
    if any(t == "list" for _, t in props):
        raise InputError(f"{path}: the vertex element has list properties; not a 3DGS PLY")
    if "chunk" in [e[0] for e in elements] or "packed_position" in names:
        return _compressed_layout(path, fmt, elements, header_end)
    has_dc = all(f"f_dc_{i}" in names for i in range(3))
    has_rgb = all(c in names for c in ("red", "green", "blue"))
    missing = [n for n in _REQUIRED if n not in names]
    if not (has_dc or has_rgb):
        missing += ["f_dc_0", "f_dc_1", "f_dc_2"]
    if missing:
        raise InputError(f"{path}: not a 3DGS PLY; the vertex element lacks "
                         f"{', '.join(missing)}")
    n_rest = sum(1 for n in names if n.startswith("f_rest_"))
    if n_rest % 3 or n_rest // 3 not in SH_DEGREE_OF:
        raise InputError(f"{path}: {n_rest} f_rest_* properties; expected 0, 9, 24 or 45")
    missing_rest = [f"f_rest_{i}" for i in range(n_rest) if f"f_rest_{i}" not in names]
    if missing_rest:
        raise InputError(f"{path}: f_rest properties are not numbered 0..{n_rest - 1} "
                         f"(missing {', '.join(missing_rest[:3])})")
    order = "<" if fmt == "binary_little_endian" else ">"
    dtype = np.dtype([(n, order + _TYPES[t]) for n, t in props])
    size = os.path.getsize(path)
    if fmt != "ascii":
        need = offset + count * dtype.itemsize
    else:
        # every ASCII value takes a character and a separator at least
        need = header_end + sum(c * 2 * len(p) for _, c, p in
                                elements[:1 + [e[0] for e in elements].index("vertex")]) - 1
    if size < need:
        raise InputError(f"{path}: file is truncated ({size} bytes, the header announces "
                         f"{count} vertices needing {'at least ' if fmt == 'ascii' else ''}"
                         f"{need})")
    return PlyLayout(path, fmt, count, dtype, offset, SH_DEGREE_OF[n_rest // 3],
                     "f_dc" if has_dc else "rgb", n_rest)


def records_to_splats(rec: np.ndarray, layout: PlyLayout) -> Splats:
    n = rec.shape[0]
    names = list(field_names(rec.dtype))
    uniform = len(set(rec.dtype[i] for i in range(len(names)))) == 1 and \
        rec.dtype[0].kind == "f"
    if uniform:
        # the usual all-float32 layout: one 2-D view, columns gathered in one go each
        mat = rec.view(rec.dtype[0]).reshape(n, len(names))

        def cols(sel: list[str], dt: npt.DTypeLike = np.float32) -> np.ndarray:
            ix = [names.index(s) for s in sel]
            if ix == list(range(ix[0], ix[0] + len(ix))):
                # a view when the type matches (each block has its own buffer)
                return mat[:, ix[0]:ix[0] + len(ix)].astype(dt, copy=False)
            return mat[:, ix].astype(dt, copy=False)
    else:
        def cols(sel: list[str], dt: npt.DTypeLike = np.float32) -> np.ndarray:
            out = np.empty((n, len(sel)), dt)
            for i, name in enumerate(sel):
                out[:, i] = rec[name]
            return out

    positions = cols(["x", "y", "z"], np.float64)
    scales = cols(["scale_0", "scale_1", "scale_2"])
    rotations = cols(["rot_1", "rot_2", "rot_3", "rot_0"])  # PLY is w-first; ours x, y, z, w
    opacities = cols(["opacity"])[:, 0]
    if layout.color_mode == "f_dc":
        colors = cols(["f_dc_0", "f_dc_1", "f_dc_2"])
    else:
        colors = (cols(["red", "green", "blue"]) / 255.0 - 0.5) / SH_C0
    k = layout.n_rest // 3
    if k:
        # channel-major in the file (all R, all G, all B) -> (N, K, 3) as a transposed view
        sh = cols([f"f_rest_{i}" for i in range(layout.n_rest)]).reshape(n, 3, k)
        sh = sh.transpose(0, 2, 1)
    else:
        sh = np.zeros((n, 0, 3), np.float32)
    return Splats(positions, scales, rotations, opacities, colors, sh)


def iter_records(layout: PlyLayout, block: int = 262_144) -> Iterator[np.ndarray]:
    """Vertex records in blocks (structured arrays); memory is bounded by the block size."""
    if layout.fmt == "ascii":
        data = read_ascii_records(layout)
        for i in range(0, len(data), block):
            yield data[i:i + block]
        return
    reader = RecordReader(layout, block)
    for start in range(0, layout.count, block):
        yield reader.read(start, min(layout.count, start + block)).copy()


def read_ascii_records(layout: PlyLayout) -> np.ndarray:
    """All vertex records of an ASCII PLY (rare for 3DGS: read whole, with plyfile)."""
    from plyfile import PlyData, PlyParseError
    try:
        return PlyData.read(str(layout.path))["vertex"].data
    except (PlyParseError, ValueError, OverflowError) as exc:   # UnicodeDecodeError too
        raise InputError(f"{layout.path}: malformed ASCII PLY body ({exc})") from None


class RecordReader:
    """Reads ranges of vertex records of a binary PLY with pread into one reused buffer.

    Safe to share across fork (each process opens its own descriptor on first use). The
    array returned by :meth:`read` is overwritten by the next call."""

    def __init__(self, layout: PlyLayout, block: int) -> None:
        self.layout, self.block = layout, block
        self._fd = -1                                  # opened by the first read
        self._pid = -1
        self._buf: np.ndarray = np.empty(0, layout.dtype)

    def read(self, start: int, stop: int) -> np.ndarray:
        if self._pid != os.getpid():
            self._fd = os.open(self.layout.path, os.O_RDONLY)
            self._pid = os.getpid()
            self._buf = np.empty(self.block, self.layout.dtype)
        m = stop - start
        if m > self._buf.shape[0]:
            self._buf = np.empty(m, self.layout.dtype)
        rec = self._buf[:m]
        size = self.layout.dtype.itemsize
        view = rec.view(np.uint8).data      # a memoryview of the buffer, written in place
        got = 0
        while got < m * size:
            k = os.preadv(self._fd, [view[got:]], self.layout.data_offset + start * size + got)
            if k == 0:
                raise InputError(f"{self.layout.path}: file ended inside the vertex data")
            got += k
        return rec


def iter_ply(layout: PlyLayout, block: int = 262_144) -> Iterator[Splats]:
    """Splats of a PLY in blocks, as stored (frame of the file)."""
    for rec in iter_records(layout, block):
        yield records_to_splats(rec, layout)


def ply_bounds(layout: PlyLayout, sample: int | None = None,
               block: int = 1_048_576) -> tuple[np.ndarray, np.ndarray, int]:
    """Min and max of the finite x, y, z (float64) and the number of finite centres looked at.

    With ``sample``, only about that many records are read, in 64 runs spread evenly through
    the file (enough to find the scene centre without a pass over the whole file; runs of
    adjacent records cost far fewer page reads than records picked one by one).
    """
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    n = 0
    chunks: Iterable[np.ndarray]
    if layout.fmt != "ascii":
        # a read-only map: only the pages holding the records looked at are touched
        mm = np.memmap(layout.path, layout.dtype, "r", layout.data_offset, (layout.count,))
        if sample is not None and layout.count > sample:
            runs = 64
            length = max(1, sample // runs)
            starts = np.linspace(0, layout.count - length, runs).astype(np.int64)
            chunks = [mm[a:a + length] for a in starts]
        else:
            chunks = (mm[i:i + block] for i in range(0, layout.count, block))
    else:
        mm, chunks = None, iter_records(layout, block)
    for rec in chunks:
        p = np.empty((rec.shape[0], 3))
        for i, c in enumerate("xyz"):
            p[:, i] = rec[c]
        p = p[np.isfinite(p).all(axis=1)]
        if p.size:
            lo = np.minimum(lo, p.min(axis=0))
            hi = np.maximum(hi, p.max(axis=0))
            n += p.shape[0]
    del mm
    return lo, hi, n


def read_ply(path: str | os.PathLike) -> Splats:
    """Read a whole 3DGS PLY into memory (for tests and small files)."""
    layout = read_layout(path)
    if isinstance(layout, CompressedLayout):
        return Splats.concatenate(list(iter_compressed(layout)))
    parts = list(iter_ply(layout))
    if not parts:
        return records_to_splats(np.zeros(0, layout.dtype), layout)
    return Splats.concatenate(parts)


def write_ply(path: str | os.PathLike, s: Splats, *, normals: bool = True,
              dtype: str = "<f4", block: int = 1_048_576) -> None:
    """Write splats as an INRIA 3DGS PLY (binary little endian, float32 by default).

    Positions are written in the given dtype: float32 PLY coordinates carry about 7
    significant digits, so keep them local (small) or pass dtype='<f8'.
    """
    k = s.sh.shape[1]
    names = ["x", "y", "z"] + (["nx", "ny", "nz"] if normals else []) + \
        [f"f_dc_{i}" for i in range(3)] + [f"f_rest_{i}" for i in range(3 * k)] + \
        ["opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3"]
    tname = {"<f4": "float", "<f8": "double"}[dtype]
    rec_dt = np.dtype([(n, dtype) for n in names])
    header = ["ply", "format binary_little_endian 1.0", f"element vertex {s.count}"]
    header += [f"property {tname} {n}" for n in names] + ["end_header"]
    tmp = Path(str(path) + ".tmp")
    with open(tmp, "wb") as f:
        f.write(("\n".join(header) + "\n").encode("ascii"))
        for i in range(0, s.count, block):
            sl = slice(i, min(s.count, i + block))
            m = sl.stop - sl.start
            arr = np.empty((m, len(names)), dtype)
            col = 0
            arr[:, 0:3] = s.positions[sl]
            col = 3
            if normals:
                arr[:, 3:6] = 0
                col = 6
            arr[:, col:col + 3] = s.colors[sl]
            col += 3
            if k:
                arr[:, col:col + 3 * k] = s.sh[sl].transpose(0, 2, 1).reshape(m, 3 * k)
                col += 3 * k
            arr[:, col] = s.opacities[sl]
            arr[:, col + 1:col + 4] = s.scales[sl]
            q = s.rotations[sl]
            arr[:, col + 4] = q[:, 3]
            arr[:, col + 5:col + 8] = q[:, :3]
            f.write(np.ascontiguousarray(arr).view(rec_dt).tobytes())
    os.replace(tmp, path)
