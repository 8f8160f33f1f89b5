"""How the geodesy is laid out (checked on the source, function-level code included): one ENU
rotation in (lon, lat) order, distinct names for the closed-form and the PROJ geodetic
conversions, one parse_crs taking anything pyproj takes, one transformer factory."""

from __future__ import annotations

import ast
import functools
from pathlib import Path

import numpy as np
import pyproj
import pytest
from conftest import REPO

from gsgeo.crs import ellipsoid, frames
from gsgeo.crs.resolve import parse_crs
from gsgeo.crs.transformers import transformer
from gsgeo.errors import CRSError
from gsgeo.tiles import georef


@functools.cache
def _modules() -> tuple[tuple[Path, ast.Module], ...]:
    """Every module of gsgeo/ parsed, once for this module's tests (each walks them all)."""
    return tuple((path, ast.parse(path.read_text(encoding="utf-8")))
                 for path in sorted((REPO / "gsgeo").rglob("*.py")))


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


def _defined(name: str) -> list[str]:
    return [str(p.relative_to(REPO)) for p, tree in _modules() for n in ast.walk(tree)
            if isinstance(n, ast.FunctionDef) and n.name == name]


def test_closed_form_and_proj_conversions_have_distinct_names():
    assert _defined("geodetic_to_ecef") == ["gsgeo/crs/frames.py"]
    assert _defined("ecef_to_geodetic") == ["gsgeo/crs/frames.py"]
    assert _defined("geodetic_to_ecef_closed_form") == ["gsgeo/crs/ellipsoid.py"]
    assert _defined("ecef_to_geodetic_closed_form") == ["gsgeo/crs/ellipsoid.py"]
    # nothing re-exports one under the other's name
    for path, tree in _modules():
        for n in ast.walk(tree):
            if isinstance(n, ast.ImportFrom) and n.module == "gsgeo.crs.ellipsoid":
                assert all(a.asname is None for a in n.names), path


def test_one_parse_crs_for_anything_pyproj_takes():
    assert _defined("parse_crs") == ["gsgeo/crs/resolve.py"]
    bng = pyproj.CRS("EPSG:27700")
    assert parse_crs(bng) is bng
    for given in (27700, "27700", "EPSG:27700", bng.to_wkt(), bng.to_json_dict()):
        assert parse_crs(given).equals(bng), given
    compound = parse_crs("EPSG:27700+5701")
    assert compound.is_compound and compound.sub_crs_list[1].is_vertical
    for bad in ("EPSG:999999", 999999, {"type": "nonsense"}, None, ""):
        with pytest.raises(CRSError):
            parse_crs(bad)


_BUILDERS = {"from_crs", "from_proj", "from_pipeline", "from_user_input", "TransformerGroup",
             "Proj", "Transformer"}


def test_every_transformer_comes_from_the_factory():
    """Only gsgeo.crs.transformers builds pyproj Transformers, Projs and TransformerGroups."""
    offenders = []
    for path, tree in _modules():
        rel = str(path.relative_to(REPO))
        if rel in ("gsgeo/crs/transformers.py", "gsgeo/crs/resolve.py"):
            continue
        for n in ast.walk(tree):
            if isinstance(n, ast.Call):
                f = n.func
                name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")
                if name in _BUILDERS:
                    offenders.append(f"{rel}:{n.lineno} {name}")
    assert offenders == []


def test_the_factory_takes_crs_objects_and_text_alike():
    t = transformer(pyproj.CRS("EPSG:4979"), pyproj.CRS("EPSG:4978"))
    assert t is transformer(pyproj.CRS("EPSG:4979"), pyproj.CRS("EPSG:4978"))  # cached
    assert transformer(4979, "EPSG:4978") is transformer("EPSG:4979", "EPSG:4978")
    x, _, _ = t.transform(0.0, 0.0, 0.0)
    assert x == pytest.approx(6378137.0)


def _imports(path, tree) -> set[str]:
    """gsgeo modules a module imports anywhere (function-level and TYPE_CHECKING included)."""
    out = set()
    for n in ast.walk(tree):
        if isinstance(n, ast.Import):
            out |= {a.name for a in n.names}
        elif isinstance(n, ast.ImportFrom) and n.module:
            out.add(n.module)
            out |= {f"{n.module}.{a.name}" for a in n.names}
    return {m for m in out if m.startswith("gsgeo.")}


def test_no_import_cycle_in_the_geodesy_and_tiles_stack():
    mods = {}
    for path, tree in _modules():
        rel = path.relative_to(REPO).with_suffix("")
        name = ".".join(rel.parts[:-1] if rel.name == "__init__" else rel.parts)
        mods[name] = (path, tree)
    graph = {m: {i for i in _imports(*mods[m]) if i in mods and i != m} for m in mods}
    ours = ("gsgeo.crs", "gsgeo.tiles", "gsgeo.demo", "gsgeo.commands.tiles", "gsgeo.commands.demo")
    cycles = []

    def visit(m: str, stack: list[str]) -> None:
        for d in sorted(graph[m]):
            if not d.startswith(ours):
                continue
            if d in stack:
                cycles.append(stack[stack.index(d):] + [d])
            elif d not in done:
                visit(d, stack + [d])
        done.add(m)

    done: set[str] = set()
    for m in sorted(graph):
        if m.startswith(ours) and m not in done:
            visit(m, [m])
    assert cycles == []
    # and the tiles stack stays above crs
    assert not [m for m in graph if m.startswith("gsgeo.crs")
                for d in graph[m] if d.startswith("gsgeo.tiles")]
