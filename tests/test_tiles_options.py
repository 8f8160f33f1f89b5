"""Georeference.from_options: the one place `gsgeo tiles`'s georeference options are checked,
used by the command and by `gsgeo demo` (which no longer runs the CLI)."""

from __future__ import annotations

import ast
import json

import numpy as np
import pytest
from conftest import REPO

from gsgeo.errors import InputError
from gsgeo.tiles.georef import Georeference


def test_options_make_each_kind_of_georeference(tmp_path):
    g = Georeference.from_options(origin="52.0,0.1,30", heading=15.0, axes="y-up")
    assert (g.kind, g.origin, g.heading, g.axes) == ("origin", (52.0, 0.1, 30.0), 15.0, "y-up")
    assert Georeference.from_options(origin=(52.0, 0.1, 30.0)).origin == (52.0, 0.1, 30.0)
    g = Georeference.from_options(crs="EPSG:32617", offset=(330000, 4430000, 200))
    assert (g.kind, g.offset, g.height) == ("crs", (330000.0, 4430000.0, 200.0), "ellipsoidal")
    assert any("heights taken as ellipsoidal" in w for w in g.warnings)
    quiet = Georeference.from_options(crs="EPSG:32617", offset="0,0,0", height="ellipsoidal")
    assert quiet.warnings == []
    m = np.eye(4)
    m[:3, 3] = [6378137.0, 0.0, 0.0]
    (tmp_path / "m.json").write_text(json.dumps(m.T.reshape(-1).tolist()))
    for given in (tmp_path / "m.json", str(tmp_path / "m.json"), m):
        g = Georeference.from_options(transform=given)
        assert g.kind == "transform" and np.array_equal(g.matrix, m)
    g = Georeference.from_options()
    assert g.kind == "none" and g.warnings


@pytest.mark.parametrize("options, message", [
    ({"origin": "1,2,3", "crs": "EPSG:32617"}, "choose one georeference: --origin and --crs"),
    ({"heading": 10.0}, "--heading needs --origin"),
    ({"offset": "1,2,3"}, "need --crs"),
    ({"crs": "EPSG:32617"}, "--crs needs --offset"),
    ({"origin": "1,2"}, "--origin expects 3 comma-separated"),
    ({"origin": "a,b,c"}, "--origin expects 3 comma-separated numbers"),
    ({"crs": "EPSG:32617", "offset": (1.0, float("nan"), 0.0)}, "--offset expects 3"),
])
def test_bad_options_are_refused_by_name(options, message):
    with pytest.raises(InputError, match=message):
        Georeference.from_options(**options)


def test_the_demo_does_not_run_the_cli():
    """gsgeo.demo builds its scene with build_tileset and from_options, not the CLI parser."""
    found = []
    for path in sorted((REPO / "gsgeo" / "demo").rglob("*.py")):
        for n in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            mods = ([a.name for a in n.names] if isinstance(n, ast.Import)
                    else [n.module or ""] if isinstance(n, ast.ImportFrom) else [])
            found += [f"{path.name}: {m}" for m in mods
                      if m == "gsgeo.cli" or m.startswith("gsgeo.commands")]
    assert found == []
