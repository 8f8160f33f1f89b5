"""The web client's pure JavaScript (web/js/linalg.js, web/js/rays.js) run in Node.js and
checked against numpy: the eigen-decomposition that orients and sizes the error ellipsoid,
covariance propagation through a model matrix, and the angular size of a pixel."""

from __future__ import annotations

import json
import shutil
import subprocess

import numpy as np
import pytest

from tests.conftest import REPO

WEB_JS = REPO / "web" / "js"
pytestmark = pytest.mark.skipif(shutil.which("node") is None, reason="Node.js is not installed")


def run_js(body: str, data) -> object:
    """Run an ES module snippet with `data` bound; it must print one JSON value."""
    src = (f"import * as L from '{(WEB_JS / 'linalg.js').as_uri()}';\n"
           f"import * as R from '{(WEB_JS / 'rays.js').as_uri()}';\n"
           f"const data = {json.dumps(data)};\n{body}\n")
    out = subprocess.run(["node", "--input-type=module", "-e", src], capture_output=True,
                         text=True, check=True, timeout=60)
    return json.loads(out.stdout)


def test_eigsym3_matches_numpy(rng):
    mats = []
    for _ in range(50):
        a = rng.normal(size=(3, 3)) * rng.uniform(1e-4, 1e-1)
        mats.append((a @ a.T).tolist())
    mats.append(np.diag([4e-6, 9e-6, 1e-6]).tolist())          # already diagonal
    mats.append((np.eye(3) * 2.5e-5).tolist())                   # isotropic
    res = run_js("console.log(JSON.stringify(data.map((m) => L.eigSym3(m))));", mats)
    for m, r in zip(mats, res, strict=True):
        m = np.array(m)
        w = np.sort(np.linalg.eigvalsh(m))[::-1]
        assert np.allclose(r["values"], w, rtol=1e-9, atol=1e-18)
        v = np.array(r["vectors"])  # rows are the unit eigenvectors
        assert np.allclose(v @ v.T, np.eye(3), atol=1e-9)
        assert np.linalg.det(v) == pytest.approx(1.0, abs=1e-9)  # right-handed: a rotation
        assert np.allclose(v @ m @ v.T, np.diag(r["values"]), atol=1e-12 * np.abs(m).max() + 1e-20)


def test_covariance_through_model_matrix(rng):
    a = rng.normal(size=(3, 3))
    cov = a @ a.T * 1e-5
    q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    m = np.eye(4)
    m[:3, :3] = 1.7 * q
    m[:3, 3] = [10.0, -5.0, 3.0]
    col_major = m.T.reshape(-1).tolist()
    got = run_js("console.log(JSON.stringify([L.transformCovariance(data[0], data[1]), "
                 "L.applyPoint(data[0], [1, 2, 3])]));", [col_major, cov.tolist()])
    assert np.allclose(got[0], m[:3, :3] @ cov @ m[:3, :3].T, rtol=1e-12)
    assert np.allclose(got[1], m[:3, :3] @ [1, 2, 3] + m[:3, 3])


def _solid_angle(a, b, c) -> float:
    """Solid angle of the spherical triangle of unit vectors a, b, c (Van Oosterom-Strackee)."""
    num = abs(np.dot(a, np.cross(b, c)))
    den = 1 + np.dot(a, b) + np.dot(b, c) + np.dot(c, a)
    return 2 * np.arctan2(num, den)


def test_pixel_angle_is_sqrt_of_pixel_solid_angle():
    """ifov recorded with each ray: the square root of the solid angle of the clicked pixel of
    a pinhole camera, computed here from the pixel's four corner rays."""
    fovy, w, h = np.radians(60.0), 1000, 700
    f = h / (2 * np.tan(fovy / 2))
    pixels = [(500, 350), (0.5, 0.5), (999.5, 10.2), (123.4, 654.3), (700, 350)]
    got = run_js("console.log(JSON.stringify(data.px.map(([x, y]) => "
                 "R.pixelAngle(data.fovy, data.w, data.h, x, y))));",
                 {"px": pixels, "fovy": fovy, "w": w, "h": h})

    def ray(x, y):
        d = np.array([x - w / 2, -(y - h / 2), -f])
        return d / np.linalg.norm(d)

    for (x, y), g in zip(pixels, got, strict=True):
        c = [ray(x - 0.5, y - 0.5), ray(x + 0.5, y - 0.5), ray(x + 0.5, y + 0.5), ray(x - 0.5, y + 0.5)]
        omega = _solid_angle(c[0], c[1], c[2]) + _solid_angle(c[0], c[2], c[3])
        assert g == pytest.approx(np.sqrt(omega), rel=1e-5)
    assert got[0] == pytest.approx(2 * np.tan(fovy / 2) / h, rel=1e-12)
