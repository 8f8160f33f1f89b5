"""Closed-form WGS 84 geodetic <-> ECEF (gsgeo.crs.ellipsoid) against PROJ, and the rule that
PROJ is loaded only with the network off, and only where it is needed."""

from __future__ import annotations

import ast
import subprocess
import sys

import numpy as np
import pyproj
import pytest
from conftest import REPO

from gsgeo.crs import ellipsoid

FWD = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)
INV = pyproj.Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)


def _points(rng, n, hmin, hmax):
    lon = rng.uniform(-180, 180, n)
    lat = np.concatenate([rng.uniform(-90, 90, n - 6), [90, -90, 89.9999999, -89.9999999, 0, 0]])
    return lon, lat, rng.uniform(hmin, hmax, n)


def test_forward_equals_proj(rng):
    lon, lat, h = _points(rng, 50_000, -1e4, 4e7)
    want = np.stack(FWD.transform(lon, lat, h), axis=-1)
    np.testing.assert_allclose(ellipsoid.geodetic_to_ecef_closed_form(lon, lat, h), want, rtol=0, atol=1e-8)


def test_inverse_equals_proj_on_the_earth(rng):
    # PROJ's inverse is exact to a few nm for terrestrial heights (it loses accuracy above
    # ~100 km; the closed form does not, see the next test)
    lon, lat, h = _points(rng, 50_000, -1e4, 1e4)
    x = np.stack(FWD.transform(lon, lat, h), axis=-1)
    got = ellipsoid.ecef_to_geodetic_closed_form(x)
    plon, plat, ph = INV.transform(x[:, 0], x[:, 1], x[:, 2])
    polar = np.abs(plat) > 89.99999
    np.testing.assert_allclose(got[0][~polar], plon[~polar], rtol=0, atol=1e-11)
    np.testing.assert_allclose(got[1], plat, rtol=0, atol=1e-11)   # 1e-11 deg ~ 1 um
    np.testing.assert_allclose(got[2], ph, rtol=0, atol=5e-6)     # PROJ: ~1 um at 10 km


def test_inverse_recovers_the_input_to_orbit_heights(rng):
    lon, lat, h = _points(rng, 50_000, -1e4, 4e7)
    got_lon, got_lat, got_h = ellipsoid.ecef_to_geodetic_closed_form(
        ellipsoid.geodetic_to_ecef_closed_form(lon, lat, h))
    dlon = (got_lon - lon + 180) % 360 - 180
    assert np.abs(dlon[np.abs(lat) < 89.9]).max() < 1e-12
    assert np.abs(got_lat - lat).max() < 1e-12
    assert np.abs(got_h - h).max() < 1e-7


def test_poles_and_equator_by_hand():
    a, b = ellipsoid.WGS84_A, ellipsoid.WGS84_A * (1 - ellipsoid.WGS84_F)
    np.testing.assert_allclose(ellipsoid.geodetic_to_ecef_closed_form(0.0, 90.0, 10.0), [0, 0, b + 10],
                               atol=1e-9)
    np.testing.assert_allclose(ellipsoid.geodetic_to_ecef_closed_form(90.0, 0.0, -5.0), [0, a - 5, 0],
                               atol=1e-9)
    lon, lat, h = ellipsoid.ecef_to_geodetic_closed_form(np.array([[0.0, 0.0, -(b + 2.0)]]))
    assert lat[0] == pytest.approx(-90.0, abs=1e-12) and h[0] == pytest.approx(2.0, abs=1e-9)


def test_every_module_using_pyproj_turns_the_network_off_first():
    """PROJ_NETWORK=OFF is set by importing gsgeo.crs.resolve; gsgeo.crs itself no longer
    imports it (so gsgeo.crs.ellipsoid is cheap), so each pyproj user must."""
    offenders = []
    for path in sorted((REPO / "gsgeo").rglob("*.py")):
        tree = ast.parse(path.read_text(encoding="utf-8"))
        names = set()
        for node in ast.walk(tree):
            if isinstance(node, ast.Import):
                names |= {a.name for a in node.names}
            elif isinstance(node, ast.ImportFrom) and node.module:
                names.add(node.module)
                names |= {f"{node.module}.{a.name}" for a in node.names}
        uses_proj = any(n == "pyproj" or n.startswith("pyproj.") for n in names)
        if uses_proj and path.name != "resolve.py" and not any(
                n.startswith("gsgeo.crs.resolve") for n in names):
            offenders.append(str(path.relative_to(REPO)))
    assert offenders == []


def _run(code: str) -> str:
    run = subprocess.run([sys.executable, "-c", code], cwd=REPO, capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    return run.stdout.strip()


def test_rigid_tiles_path_does_not_load_proj(tmp_path):
    code = f"""
import sys
import numpy as np
from gsgeo.tiles.build import build_tileset
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.ply import write_ply
sys.path.insert(0, "tests")
from tiles_helpers import random_splats
write_ply({str(tmp_path / 'a.ply')!r}, random_splats(np.random.default_rng(1), 2000, 1))
build_tileset({str(tmp_path / 'a.ply')!r}, {str(tmp_path / 'out')!r},
              Georeference("origin", origin=(52.0, 0.1, 30.0)), progress=None)
print("pyproj" in sys.modules)
"""
    assert _run(code) == "False"


def test_grid_placement_loads_proj_with_the_network_off():
    code = """
import numpy as np
from gsgeo.tiles.georef import Georeference
g = Georeference("crs", crs="EPSG:32617", offset=(330000.0, 4430000.0, 200.0))
g.placement(np.zeros(3), np.ones(3))
import pyproj
print(pyproj.network.is_network_enabled())
"""
    assert _run(code) == "False"
