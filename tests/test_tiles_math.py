"""Rotation algebra used to turn splats: quaternions and real SH of the INRIA renderer."""

from __future__ import annotations

import numpy as np

from gsgeo.tiles.splats import matrix_to_quat, quat_multiply, quat_to_matrix, sh_eval, sh_rotation


def _random_rotations(rng, n):
    q = rng.normal(size=(n, 4))
    return q / np.linalg.norm(q, axis=1, keepdims=True)


def test_quaternion_matrix_round_trip_and_product(rng):
    q = _random_rotations(rng, 2000)
    m = quat_to_matrix(q)
    assert np.allclose(m @ np.swapaxes(m, 1, 2), np.eye(3), atol=1e-12)
    assert np.allclose(np.linalg.det(m), 1)
    back = matrix_to_quat(m)
    assert np.allclose(np.abs((back * q).sum(axis=1)), 1, atol=1e-12)
    a, b = q[:1000], q[1000:]
    assert np.allclose(quat_to_matrix(quat_multiply(a, b)), m[:1000] @ m[1000:], atol=1e-12)
    # x, y, z, w order: 90 degrees about z turns x into y
    qz = np.array([0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    assert np.allclose(quat_to_matrix(qz) @ [1, 0, 0], [0, 1, 0])


def test_sh_rotation_turns_the_view_dependent_colour(rng):
    """After turning splats by R, the colour seen along R d equals the old one along d."""
    sh = rng.normal(size=(300, 15, 3))
    d = rng.normal(size=(300, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    for r in quat_to_matrix(_random_rotations(rng, 5)):
        new = np.einsum("ij,njc->nic", sh_rotation(r), sh)
        assert np.allclose(sh_eval(new, d @ r.T), sh_eval(sh, d), atol=1e-9)
        # degree 1 only (first 3 coefficients) is closed under rotation too
        d1 = sh_rotation(r, 3)
        assert np.allclose(sh_eval(np.einsum("ij,njc->nic", d1, sh[:, :3]), d @ r.T),
                           sh_eval(sh[:, :3], d), atol=1e-9)


def test_sh_basis_is_orthonormal_on_the_sphere(rng):
    """Monte Carlo: the INRIA constants make the real SH orthonormal (so D is orthogonal)."""
    from gsgeo.tiles.splats import sh_basis
    d = rng.normal(size=(400_000, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    b = sh_basis(d)
    gram = 4 * np.pi * (b.T @ b) / d.shape[0]
    assert np.allclose(gram, np.eye(15), atol=0.03)
