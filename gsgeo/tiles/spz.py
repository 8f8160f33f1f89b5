"""SPZ (Niantic's compressed splat format, gzip file versions 2 and 3) with numpy.

Layout (all little-endian, the whole payload gzip-compressed): a 16-byte header
(u32 magic 0x5053474e "NGSP", u32 version, u32 number of points, u8 SH degree, u8 fractional
bits, u8 flags, u8 reserved), then per attribute one array over all points: positions
(3 x signed 24-bit fixed point), alphas (u8), colours (3 x u8), scales (3 x u8), rotations
(v2: 3 x u8; v3: one u32 "smallest three"), SH (u8 per coefficient, channel innermost).

Encoding is split in two: :func:`quantize` turns float attributes into the byte arrays of an
:class:`SpzBytes` (positions stay float64 until :func:`pack`, which knows the fractional bits),
so large inputs are held compactly between reading and tile writing.
"""

from __future__ import annotations

import functools
import gzip
import struct
import zlib
from dataclasses import dataclass
from types import ModuleType
from typing import Protocol

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles.splats import SH_COEFFS, SH_DEGREE_OF, Splats

_isal: ModuleType | None
try:  # ISA-L's deflate is 5-6x faster than zlib at levels 0-3 with the same gzip output format
    from isal import isal_zlib as _isal
except ImportError:  # pragma: no cover - isal is a declared dependency
    _isal = None

MAGIC = 0x5053474E
COLOR_SCALE = 0.15
SQRT1_2 = np.float32(np.sqrt(0.5))
#: Fractional bits used unless positions need more range: ±2048 m at 0.24 mm.
DEFAULT_FRACTIONAL_BITS = 12
#: Precision of SH bytes kept for degree 1 and for degrees 2-3 (as the reference encoder).
SH_BITS = (5, 4)


@dataclass
class SpzBytes:
    """Quantised splat attributes; positions (N, 3) float64 are quantised at packing time."""
    positions: np.ndarray
    alphas: np.ndarray      # (N,) u8
    colors: np.ndarray      # (N, 3) u8
    scales: np.ndarray      # (N, 3) u8
    rotations: np.ndarray   # (N,) u32 (v3) or (N, 3) u8 (v2)
    sh: np.ndarray          # (N, K*3) u8

    @property
    def count(self) -> int:
        return int(self.positions.shape[0])

    def take(self, idx: np.ndarray | slice) -> SpzBytes:
        if isinstance(idx, slice):
            return SpzBytes(self.positions[idx], self.alphas[idx], self.colors[idx],
                            self.scales[idx], self.rotations[idx], self.sh[idx])
        # np.take along axis 0 copies whole rows; arr[idx] on 2-D arrays is several x slower
        return SpzBytes(*(np.take(a, idx, axis=0) for a in (
            self.positions, self.alphas, self.colors, self.scales, self.rotations, self.sh)))

    @staticmethod
    def concatenate(parts: list[SpzBytes]) -> SpzBytes:
        return SpzBytes(*(np.concatenate([getattr(p, f) for p in parts])
                          for f in ("positions", "alphas", "colors", "scales", "rotations",
                                    "sh")))


def _u8(x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Round and clamp to bytes (into ``out`` if given); works in place on float temporaries."""
    x = np.asarray(x, np.float32)
    np.rint(x, out=x)
    np.clip(x, 0, 255, out=x)
    if out is None:
        return x.astype(np.uint8)
    np.copyto(out, x, casting="unsafe")
    return out


def _sh_buckets(k: int) -> np.ndarray:
    """Bucket size per SH coefficient: 8 (5 bits) for degree 1, 16 (4 bits) for 2-3."""
    bits = np.array([SH_BITS[0]] * 3 + [SH_BITS[1]] * 12)[:k]
    return (1 << (8 - bits)).astype(np.float32)


#: Rows of SH quantised per pass (bounds the float temporaries to about 3 MB).
SH_CHUNK = 16_384


@functools.lru_cache(maxsize=16)
def _sh_constants(k: int, channel_major: bool) -> tuple[np.ndarray, np.ndarray]:
    """Per-value offset 128 + bucket/2 (float32) and low-bit mask ~(bucket - 1) (u8) for rows
    of 3k SH values, repeated over SH_CHUNK rows: whole-array operands keep numpy in one long
    loop, where a broadcast row of 3k values costs a short inner loop per splat."""
    b = _sh_buckets(k)
    row = np.tile(b, 3) if channel_major else np.repeat(b, 3)
    add = np.tile(np.float32(128.0) + row / np.float32(2.0), (SH_CHUNK, 1))
    mask = np.tile(~(row.astype(np.uint8) - np.uint8(1)), (SH_CHUNK, 1))
    add.flags.writeable = mask.flags.writeable = False
    return add, mask


def quantize_sh(sh: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """SH floats (N, K, 3) to bytes (N, K*3): x·128 + 128 to the nearest multiple of the
    coefficient's bucket (the reference encoder's precision), at most 256 - bucket. (The
    reference encoder rounds twice and clamps to 255; both decode within half a bucket.)

    With bucket a power of two, floor((x·128 + 128 + bucket/2) clamped to [0, 255]) with its
    low bits cleared is exactly that multiple."""
    n, k, _ = sh.shape
    if out is None:
        out = np.empty((n, 3 * k), np.uint8)
    if not out.flags.c_contiguous:
        raise ValueError("out must be C-contiguous")  # rows are reshaped in place below
    if k == 0 or n == 0:
        return out
    channel_major = sh.transpose(0, 2, 1)
    # PLY blocks arrive as a transposed view of (N, 3, K): read them in memory order and put
    # the bytes in coefficient order at the end
    cm = channel_major.strides[2] == channel_major.itemsize
    if cm:
        work = channel_major.reshape(n, 3 * k)   # a view when each row's values are adjacent
    else:
        work = np.ascontiguousarray(sh, np.float32).reshape(n, 3 * k)
    add, mask = _sh_constants(k, cm)
    for a in range(0, n, SH_CHUNK):
        b = min(n, a + SH_CHUNK)
        v = np.multiply(work[a:b], np.float32(128.0), dtype=np.float32)
        v += add[:b - a]
        np.clip(v, 0, 255, out=v)
        if cm:
            u = v.astype(np.uint8)
            u &= mask[:b - a]
            o3, u3 = out[a:b].reshape(b - a, k, 3), u.reshape(b - a, 3, k)
            for c in range(3):
                o3[:, :, c] = u3[:, c, :]
        else:
            o = out[a:b]
            np.copyto(o, v, casting="unsafe")
            o &= mask[:b - a]
    return out


def pack_rotations_v3(q: np.ndarray) -> np.ndarray:
    """Quaternions (N, 4) x, y, z, w to SPZ v3 u32: 2 bits index of the largest |component|,
    then for each other component in order a sign bit and 9 bits of 511·|c|/√½, the signs
    taken with the largest component made positive. A zero quaternion is the identity.

    Worked on the (4, N) transpose with whole-array arithmetic: numpy's argmax, where and
    masked assignment over a 4-wide axis cost several times more than these passes."""
    q = np.asarray(q, np.float32)
    qt = np.ascontiguousarray(q.T)
    a = np.abs(qt)
    top = np.maximum(np.maximum(a[0], a[1]), np.maximum(a[2], a[3]))
    # index of the largest |component|, the first of equals (as argmax): n0 (1 + n1 (1 + n2))
    # with n_i "component i is not the largest"
    largest = (a[2] != top).astype(np.uint32)
    largest += 1
    largest *= a[1] != top
    largest += 1
    largest *= a[0] != top
    signed = np.choose(largest, qt)
    sq = qt * qt
    norm2 = sq[0] + sq[1]
    norm2 += sq[2]
    norm2 += sq[3]
    zero = norm2 < np.float32(1e-30)
    np.maximum(norm2, np.float32(1e-30), out=norm2)
    # in the reference encoder's order of operations, so the bytes match it
    a /= np.sqrt(norm2)
    a /= SQRT1_2
    a *= np.float32(511.0)
    a += np.float32(0.5)
    np.minimum(a, np.float32(511.0), out=a)
    fields = a.astype(np.uint64)                       # 511·|c|/√½ rounded, per component
    qt *= signed                                       # < 0: sign opposite to the largest
    fields |= (qt < 0).astype(np.uint64) << np.uint64(9)
    # the four 10-bit fields side by side (40 bits), then the largest one's field cut out
    row = fields[0] << np.uint64(30)
    row |= fields[1] << np.uint64(20)
    row |= fields[2] << np.uint64(10)
    row |= fields[3]
    shift = (np.uint64(3) - largest) * np.uint64(10)   # bits below the dropped field
    low = row & ((np.uint64(1) << shift) - np.uint64(1))
    row >>= shift + np.uint64(10)
    row <<= shift
    row |= low
    comp = row.astype(np.uint32)
    comp |= largest << np.uint32(30)
    if zero.any():
        comp[zero] = np.uint32(3 << 30)                # w = 1, the rest 0
    return comp


def unpack_rotations_v3(comp: np.ndarray) -> np.ndarray:
    comp = comp.astype(np.uint32)
    largest = (comp >> 30).astype(np.int64)
    q = np.zeros((comp.shape[0], 4), np.float32)
    ss = np.zeros(comp.shape[0], np.float32)
    c = comp.copy()
    for i in range(3, -1, -1):
        keep = largest != i
        mag = (c & 511).astype(np.float32)
        sign = np.where((c >> 9) & 1, -1.0, 1.0).astype(np.float32)
        v = sign * SQRT1_2 * mag / 511.0
        q[:, i] = np.where(keep, v, 0)
        ss += np.where(keep, v * v, 0)
        c = np.where(keep, c >> 10, c)
    np.put_along_axis(q, largest[:, None], np.sqrt(np.maximum(0, 1 - ss))[:, None], 1)
    return q


def pack_rotations_v2(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, np.float32)
    q = q / np.linalg.norm(q, axis=1, keepdims=True)
    q = np.where(q[:, 3:4] < 0, -q, q)
    return _u8(q[:, :3] * 127.5 + 127.5)


def unpack_rotations_v2(b: np.ndarray) -> np.ndarray:
    xyz = b.astype(np.float32) / 127.5 - 1.0
    w = np.sqrt(np.maximum(0.0, 1.0 - (xyz * xyz).sum(axis=1)))
    return np.concatenate([xyz, w[:, None]], axis=1)


def quantize(s: Splats, version: int = 3, out: SpzBytes | None = None) -> SpzBytes:
    """Quantise splats to SPZ bytes (positions kept float64), into ``out`` (arrays of
    s.count rows, e.g. slices of a larger store) if given."""
    alpha = 1.0 / (1.0 + np.exp(-s.opacities.astype(np.float32)))
    rot = pack_rotations_v3(s.rotations) if version == 3 else pack_rotations_v2(s.rotations)
    if out is None:
        return SpzBytes(
            positions=np.asarray(s.positions, np.float64),
            alphas=_u8(alpha * 255.0),
            colors=_u8(s.colors * (COLOR_SCALE * 255.0) + 127.5),
            scales=_u8((s.scales + 10.0) * 16.0),
            rotations=rot,
            sh=quantize_sh(s.sh),
        )
    out.positions[:] = s.positions
    _u8(alpha * 255.0, out.alphas)
    _u8(s.colors * (COLOR_SCALE * 255.0) + 127.5, out.colors)
    _u8((s.scales + 10.0) * 16.0, out.scales)
    out.rotations[:] = rot
    quantize_sh(s.sh, out.sh)
    return out


class Compressor(Protocol):
    """A gzip compressobj (zlib's or ISA-L's)."""
    def compress(self, data: memoryview, /) -> bytes: ...
    def flush(self) -> bytes: ...


def compressor(level: int) -> Compressor:
    """A gzip compressobj: ISA-L for levels 0-3 when available, else zlib (levels 0-9)."""
    if _isal is not None and level <= 3:
        return _isal.compressobj(level, _isal.DEFLATED, 31)
    return zlib.compressobj(level, zlib.DEFLATED, 31)  # 31: gzip container


def fractional_bits_for(extent: float, most: int = DEFAULT_FRACTIONAL_BITS) -> int:
    """Largest number of fractional bits (<= ``most``) whose 24-bit range holds
    |coordinates| <= extent."""
    bits = most
    while bits > 0 and extent >= (2 ** 23 - 1) / 2 ** bits:
        bits -= 1
    return bits


def pack(b: SpzBytes, sh_degree: int, *, version: int = 3, fractional_bits: int = 12,
         level: int = 6, antialiased: bool = False) -> bytes:
    """The gzip-compressed SPZ payload of quantised splats (positions in metres, float64)."""
    return pack_bounded(b, sh_degree, version=version, fractional_bits=fractional_bits,
                        level=level, antialiased=antialiased)[0]


def pack_bounded(b: SpzBytes, sh_degree: int, *, version: int = 3, fractional_bits: int = 12,
                 level: int = 6, antialiased: bool = False, rows: np.ndarray | None = None
                 ) -> tuple[bytes, np.ndarray, np.ndarray]:
    """:func:`pack`, plus the box (lo, hi: (3,) float64, metres) of the positions as they
    decode from the payload, for the glTF POSITION accessor. With ``rows``, the splats packed
    are those rows of ``b``, gathered straight into the payload (no intermediate copy)."""
    n = b.count if rows is None else int(rows.shape[0])
    pos = b.positions if rows is None else np.take(b.positions, rows, axis=0, mode="clip")
    fixed = np.rint(pos * (1 << fractional_bits)).astype(np.int32)
    # per column: numpy's axis-0 reductions of narrow arrays are several times slower
    lo = np.array([fixed[:, i].min() if n else 0 for i in range(3)], np.float64)
    hi = np.array([fixed[:, i].max() if n else 0 for i in range(3)], np.float64)
    lim = 2 ** 23 - 1
    if n and (lo.min() < -lim or hi.max() > lim):
        raise InputError(f"splat positions exceed the SPZ range of ±{lim / (1 << fractional_bits):.0f} m")
    k3 = b.sh.shape[1]
    rot_bytes = 4 if version == 3 else 3
    sizes = [9 * n, n, 3 * n, 3 * n, rot_bytes * n, k3 * n]
    raw = np.empty(16 + sum(sizes), np.uint8)
    raw[:16] = np.frombuffer(struct.pack("<IIIBBBB", MAGIC, version, n, sh_degree,
                                         fractional_bits, 1 if antialiased else 0, 0), np.uint8)
    o = 16
    # 24-bit little-endian: the low three bytes of each int32
    raw[o:o + 9 * n].reshape(n, 3, 3)[:] = fixed.astype("<i4").view(np.uint8).reshape(n, 3, 4)[:, :, :3]
    o += 9 * n
    rot = b.rotations.astype("<u4", copy=False).view(np.uint8).reshape(-1, 4) \
        if version == 3 else b.rotations
    for arr, size in zip((b.alphas, b.colors, b.scales, rot, b.sh), sizes[1:], strict=True):
        dst = raw[o:o + size].reshape((n,) + arr.shape[1:])
        if rows is None:
            dst[:] = arr
        else:   # mode="clip": with "raise", take buffers its output
            np.take(arr, rows, axis=0, out=dst, mode="clip")
        o += size
    comp = compressor(level)
    scale = 1.0 / (1 << fractional_bits)
    return comp.compress(raw.data) + comp.flush(), lo * scale, hi * scale


def decode(data: bytes) -> tuple[Splats, dict]:
    """Decode an SPZ payload (gzip file version 2 or 3) into float splats in its own frame.

    Returns the splats and the header as a dict (version, sh_degree, fractional_bits, flags).
    """
    try:
        raw = gzip.decompress(data)
    except (OSError, EOFError, zlib.error) as exc:
        raise InputError(f"not a gzip SPZ payload ({exc})") from None
    if len(raw) < 16:
        raise InputError("SPZ payload shorter than its 16-byte header")
    magic, version, n, deg, frac, flags, _ = struct.unpack("<IIIBBBB", raw[:16])
    if magic != MAGIC:
        raise InputError(f"SPZ magic number is {magic:#x}, expected {MAGIC:#x}")
    if version not in (2, 3):
        raise InputError(f"SPZ file version {version} is not supported (2 and 3 are)")
    if deg not in SH_COEFFS:
        raise InputError(f"SPZ SH degree {deg} is not supported (0-3 are)")
    k = SH_COEFFS[deg]
    rot_bytes = 4 if version == 3 else 3
    sizes = [9 * n, n, 3 * n, 3 * n, rot_bytes * n, 3 * k * n]
    if len(raw) < 16 + sum(sizes):
        raise InputError(f"SPZ payload truncated: {len(raw)} bytes for {n} points")
    buf = np.frombuffer(raw, np.uint8, offset=16)
    arrs = []
    o = 0
    for s in sizes:
        arrs.append(buf[o:o + s])
        o += s
    p = arrs[0].reshape(n, 3, 3).astype(np.int32)
    fixed = p[:, :, 0] | (p[:, :, 1] << 8) | (p[:, :, 2] << 16)
    fixed = np.where(fixed & 0x800000, fixed - (1 << 24), fixed)
    positions = fixed.astype(np.float64) / (1 << frac)
    # bytes 0 and 255 would be infinite logits; a quarter step keeps them finite and
    # re-encodes to the same byte
    alpha = np.clip(arrs[1].astype(np.float32), 0.25, 254.75) / 255.0
    opac = np.log(alpha) - np.log1p(-alpha)
    colors = (arrs[2].reshape(n, 3).astype(np.float32) / 255.0 - 0.5) / COLOR_SCALE
    scales = arrs[3].reshape(n, 3).astype(np.float32) / 16.0 - 10.0
    if version == 3:
        rot = unpack_rotations_v3(arrs[4].view("<u4"))
    else:
        rot = unpack_rotations_v2(arrs[4].reshape(n, 3))
    sh = ((arrs[5].astype(np.float32) - 128.0) / 128.0).reshape(n, k, 3)
    header = {"version": version, "count": n, "sh_degree": SH_DEGREE_OF[k],
              "fractional_bits": frac, "flags": flags}
    return Splats(positions, scales, rot, opac.astype(np.float32), colors, sh), header


def encode(s: Splats, *, version: int = 3, level: int = 6) -> bytes:
    """Encode splats (positions within the SPZ range) as one SPZ payload."""
    ext = float(np.abs(s.positions).max()) if s.count else 0.0
    return pack(quantize(s, version), s.sh_degree, version=version,
                fractional_bits=fractional_bits_for(ext), level=level)
