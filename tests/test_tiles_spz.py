"""SPZ encoding/decoding against hand-computed bytes and quantisation bounds."""

from __future__ import annotations

import gzip
import struct

import numpy as np
import pytest

from gsgeo.errors import InputError
from gsgeo.tiles import spz
from gsgeo.tiles.splats import Splats, quat_to_matrix
from tests.tiles_helpers import (
    TOL_ALPHA,
    TOL_COLOR,
    TOL_LOG_SCALE,
    random_splats,
    rotation_error_deg,
    sigmoid,
)


def _one(pos, scale=(-2, -3, -4), q=(0, 0, 0, 1), opacity=0.0, color=(0, 0, 0)):
    return Splats(np.array([pos], float), np.array([scale], np.float32),
                  np.array([q], np.float32), np.array([opacity], np.float32),
                  np.array([color], np.float32), np.zeros((1, 0, 3), np.float32))


def test_bytes_of_one_splat_match_the_format_by_hand():
    s = _one((1.0, -2.0, 0.5), scale=(-2.0, -10.0, 6.0), q=(0.6, 0.0, 0.0, 0.8),
             opacity=0.0, color=(1.0, -1.0, 0.0))
    raw = gzip.decompress(spz.encode(s, version=3))
    assert struct.unpack("<IIIBBBB", raw[:16]) == (0x5053474E, 3, 1, 0, 12, 0, 0)
    body = raw[16:]
    # positions: 24-bit two's complement of value * 4096, little endian
    assert body[0:3] == (4096).to_bytes(3, "little")
    assert body[3:6] == ((1 << 24) - 8192).to_bytes(3, "little")
    assert body[6:9] == (2048).to_bytes(3, "little")
    assert body[9] == 128                          # sigmoid(0) * 255 = 127.5 -> 128
    assert list(body[10:13]) == [166, 89, 128]     # 1*0.15*255+127.5 = 165.75
    assert list(body[13:16]) == [128, 0, 255]      # (ln s + 10) * 16, clamped
    # rotation: largest |c| is w (index 3); x = 0.6 -> round(511 * 0.6 / sqrt(1/2)) = 434
    comp = struct.unpack("<I", body[16:20])[0]
    assert comp == (3 << 30) | (434 << 20)
    assert len(body) == 20


def test_rotation_v3_identity_and_negative_components():
    assert spz.pack_rotations_v3(np.array([[0, 0, 0, 1.0]]))[0] == 3 << 30
    # -q is the same rotation: the largest component is made positive
    q = np.array([[-0.1, 0.2, -0.9, 0.3]])
    q /= np.linalg.norm(q)
    a = spz.unpack_rotations_v3(spz.pack_rotations_v3(q))
    b = spz.unpack_rotations_v3(spz.pack_rotations_v3(-q))
    np.testing.assert_allclose(a, b)
    assert abs(abs((a[0] * q[0]).sum()) - 1) < 1e-5


def _pack_one_v3(q) -> int:
    """The SPZ v3 rotation word of one quaternion, step by step as the format describes
    (float32 arithmetic in the reference encoder's order)."""
    q = np.asarray(q, np.float32)
    q = q / np.float32(np.sqrt(np.float32(sum(np.float32(c) * np.float32(c) for c in q))))
    largest = int(np.argmax(np.abs(q)))
    negate = q[largest] < 0
    word = largest
    for i in range(4):
        if i == largest:
            continue
        c = -q[i] if negate else q[i]
        mag = min(int(np.float32(511.0) * (abs(c) / spz.SQRT1_2) + np.float32(0.5)), 511)
        word = (word << 10) | (int(c < 0) << 9) | mag
    return word


def test_rotation_v3_words_equal_a_one_at_a_time_encoder(rng):
    q = rng.normal(size=(3000, 4)).astype(np.float32)
    q[:500] = np.round(q[:500])                   # ties between components, zeros
    q[500:600, 3] = 0.0
    q[600:700] *= np.float32(1e-3)                # unnormalised input
    q = q[np.abs(q).sum(axis=1) > 0]
    got = spz.pack_rotations_v3(q)
    assert [int(v) for v in got] == [_pack_one_v3(r) for r in q]


def test_rotation_v3_zero_quaternion_is_the_identity():
    got = spz.pack_rotations_v3(np.zeros((2, 4), np.float32))
    np.testing.assert_array_equal(spz.unpack_rotations_v3(got), [[0, 0, 0, 1]] * 2)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("degree", [0, 1, 2, 3])
def test_round_trip_within_quantisation(rng, version, degree):
    s = random_splats(rng, 3000, degree, extent=1000.0)
    d, header = spz.decode(spz.encode(s, version=version))
    assert header == {"version": version, "count": 3000, "sh_degree": degree,
                      "fractional_bits": 12, "flags": 0}
    assert np.abs(d.positions - s.positions).max() <= 0.5 / 4096 + 1e-9
    assert np.abs(d.scales - s.scales).max() <= TOL_LOG_SCALE
    assert np.abs(sigmoid(d.opacities) - sigmoid(s.opacities)).max() <= TOL_ALPHA
    assert np.abs(d.colors - s.colors).max() <= TOL_COLOR
    err = rotation_error_deg(quat_to_matrix(s.rotations.astype(float)), d.rotations)
    # v2 keeps x, y, z to 8 bits: coarse when w is small
    assert err.max() <= (0.25 if version == 3 else 12.0)
    if degree:
        bound = 4 / 128 + 0.5 / 128 if degree == 1 else 8 / 128 + 0.5 / 128
        assert np.abs(d.sh - s.sh).max() <= bound + 1e-6


@pytest.mark.parametrize("k", [3, 8, 15])
def test_sh_bytes_equal_the_bucket_formula_in_both_layouts(rng, k):
    n = 3 * spz.SH_CHUNK // 2 + 7                  # more than one pass, a partial last one
    cm = rng.normal(scale=0.7, size=(n, 3, k)).astype(np.float32)
    cm[:50] = rng.choice(np.float32([-3, 3, 0, 1 / 32, -1 / 32]), size=(50, 3, k))
    sh = cm.transpose(0, 2, 1)                    # (N, K, 3) as a view, the way PLY blocks come
    # degree 1: 5 bits (bucket 8); degrees 2-3: 4 bits (bucket 16); x*128 + 128 to the
    # nearest multiple of the bucket, clamped to [0, 256 - bucket]; coefficient-major bytes
    bucket = np.array([8] * 3 + [16] * 12)[:k, None]
    idx = np.floor(sh.astype(np.float64) * 128 / bucket + 128 / bucket + 0.5)
    want = (np.clip(idx, 0, 256 / bucket - 1) * bucket).astype(np.uint8).reshape(n, 3 * k)
    np.testing.assert_array_equal(spz.quantize_sh(sh), want)
    np.testing.assert_array_equal(spz.quantize_sh(np.ascontiguousarray(sh)), want)


def test_fractional_bits_shrink_for_large_extents(rng):
    s = random_splats(rng, 100, 0, extent=3000.0)
    d, header = spz.decode(spz.encode(s))
    assert header["fractional_bits"] == 11
    assert np.abs(d.positions - s.positions).max() <= 0.5 / 2048 + 1e-9


def test_real_tile_header_and_plausible_values(white_sculpture):
    from gsgeo.tiles.gltf import parse_glb
    (blob, m), = parse_glb((white_sculpture / "tile_2_0_0_1_gs.glb").read_bytes())
    s, h = spz.decode(blob)
    assert h == {"version": 3, "count": 191, "sh_degree": 3, "fractional_bits": 12, "flags": 0}
    assert np.allclose(np.linalg.norm(s.rotations, axis=1), 1, atol=1e-3)
    # content heights are about 128-145 m in the root ENU frame (data README)
    assert 120 < s.positions[:, 2].mean() < 150


@pytest.mark.parametrize("blob, msg", [
    (b"not gzip", "gzip"),
    (gzip.compress(b"\0" * 8), "header"),
    (gzip.compress(struct.pack("<IIIBBBB", 0x12345678, 3, 0, 0, 12, 0, 0)), "magic"),
    (gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 4, 0, 0, 12, 0, 0)), "version 4"),
    (gzip.compress(struct.pack("<IIIBBBB", 0x5053474E, 3, 10, 0, 12, 0, 0)), "truncated"),
], ids=["not gzip", "short header", "magic", "version 4", "truncated"])  # gzip's bytes hold the time
def test_bad_payloads_are_named(blob, msg):
    with pytest.raises(InputError, match=msg):
        spz.decode(blob)
