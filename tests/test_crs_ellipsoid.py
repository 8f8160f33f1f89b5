"""Closed-form WGS 84 geodetic <-> ECEF (gsgeo.crs.ellipsoid) against PROJ, and the rule that
PROJ is loaded only with the network off, and only where it is needed."""

from __future__ import annotations

import os
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


#: Every public way gsgeo reaches PROJ; each must turn the network off before PROJ works.
PROJ_PATHS = {
    "parse_crs": "from gsgeo.crs.resolve import parse_crs; parse_crs('EPSG:27700')",
    "transformer": "from gsgeo.crs.transformers import transformer; "
                   "transformer('EPSG:4979', 'EPSG:4978')",
    "pipeline": "from gsgeo.crs.transformers import pipeline; pipeline('+proj=noop')",
    "candidates": "from gsgeo.crs.transformers import candidates; "
                  "candidates('EPSG:4979', 'EPSG:27700')",
    "projection": "from gsgeo.crs.transformers import projection; projection('EPSG:27700')",
    "EnuFrame": "from gsgeo.crs.frames import EnuFrame; EnuFrame.from_geodetic(0.0, 51.0, 0.0)",
    "to_grid": "from gsgeo.crs import to_grid, geodetic_to_ecef; "
               "to_grid(geodetic_to_ecef(-1.5, 52.5, 80.0), None, 'EPSG:27700')",
    "grid placement": "import numpy as np; from gsgeo.tiles.georef import Georeference; "
                      "Georeference('crs', crs='EPSG:32617', offset=(330000.0, 4430000.0, 0.0))"
                      ".placement(np.zeros(3), np.ones(3))",
    "demo truth": "from gsgeo.demo.place import local_to_ecef; local_to_ecef([[0.0, 0.0, 0.0]])",
}


def test_every_module_using_pyproj_turns_the_network_off_first():
    """PROJ_NETWORK=OFF is an explicit call (gsgeo.crs.resolve.network_off) made by parse_crs
    and the transformer factory, which every pyproj user goes through (tests/test_crs_layout.py
    checks that on the source); here each public path is run in a fresh process whose
    environment asks PROJ for the network, and must end with the network off."""
    env = {**os.environ, "PROJ_NETWORK": "ON"}
    probe = "; import os, pyproj; print(pyproj.network.is_network_enabled(), os.environ['PROJ_NETWORK'])"
    control = subprocess.run([sys.executable, "-c", "import gsgeo.crs.resolve" + probe],
                             cwd=REPO, env=env, capture_output=True, text=True)
    assert control.stdout.split() == ["True", "ON"], control.stderr  # importing alone: no change
    runs = {name: subprocess.Popen([sys.executable, "-c", code + probe], cwd=REPO, env=env,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
            for name, code in PROJ_PATHS.items()}
    found = {}
    for name, run in runs.items():
        out, err = run.communicate(timeout=120)
        assert run.returncode == 0, f"{name}: {err}"
        found[name] = out.split()
    assert found == {name: ["False", "OFF"] for name in PROJ_PATHS}


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
