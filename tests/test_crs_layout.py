"""How the geodesy is laid out: one ENU rotation in (lon, lat) order, ... (checked on the source,
function-level code included)."""

from __future__ import annotations

import ast

import numpy as np
from conftest import REPO

from gsgeo.crs import ellipsoid, frames
from gsgeo.tiles import georef


def _modules():
    for path in sorted((REPO / "gsgeo").rglob("*.py")):
        yield path, ast.parse(path.read_text(encoding="utf-8"))


def test_one_enu_rotation_in_lon_lat_order():
    defined = [(str(p.relative_to(REPO)), [a.arg for a in n.args.args])
               for p, tree in _modules() for n in ast.walk(tree)
               if isinstance(n, ast.FunctionDef) and n.name == "enu_rotation"]
    assert defined == [("gsgeo/crs/ellipsoid.py", ["lon_deg", "lat_deg"])]
    assert frames.enu_rotation is ellipsoid.enu_rotation
    assert getattr(georef, "enu_rotation", ellipsoid.enu_rotation) is ellipsoid.enu_rotation
    # (lon, lat) = (90, 0): east is +y of ECEF; with the order swapped it would be +x
    np.testing.assert_allclose(ellipsoid.enu_rotation(90.0, 0.0)[0], [-1.0, 0.0, 0.0], atol=1e-15)
    np.testing.assert_allclose(ellipsoid.enu_rotation(0.0, 90.0)[2], [0.0, 0.0, 1.0], atol=1e-15)
