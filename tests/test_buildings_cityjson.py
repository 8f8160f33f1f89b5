"""CityJSON 2.0 of LoD2 buildings: valid against the official schema, read back by cjio."""

from __future__ import annotations

import json

import numpy as np
import orjson
import pyproj
import pytest
from buildings_helpers import GABLE, GABLE_ROOFS, GABLE_VOLUME, GROUND, HIP, HIP_ROOFS, measured
from cityjson_helpers import validate_city_json

from gsgeo.buildings.cityjson import (
    city_json,
    city_json_bytes,
    metadata_reference_system,
    reference_system_uri,
)
from gsgeo.buildings.model import build_building
from gsgeo.buildings.solid import Surface
from gsgeo.buildings.solidcheck import solid_problems
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import GeometryError, InputError

BNG = "https://www.opengis.net/def/crs/EPSG/0/27700"


def gable(bid="B1", seed=7, **extra):
    spec = parse_building({"id": bid, "roofs": GABLE_ROOFS, "ground": GROUND, **extra})
    return build_building(spec, measured(GABLE, 0.02, np.random.default_rng(seed)))


def decoded(doc, obj):
    """The solid's vertices (real coordinates) and faces of city object ``obj``."""
    scale = np.array(doc["transform"]["scale"])
    translate = np.array(doc["transform"]["translate"])
    verts = np.array(doc["vertices"], dtype=float) * scale + translate
    geom = doc["CityObjects"][obj]["geometry"][0]
    faces = [surface[0] for surface in geom["boundaries"][0]]
    return verts, faces, geom


def test_a_gable_house_is_a_valid_cityjson_2_building_with_an_lod2_solid():
    doc = city_json([gable(attributes={"function": "residential"})], BNG, title="test")
    validate_city_json(doc)
    assert doc["type"] == "CityJSON" and doc["version"] == "2.0"
    assert doc["transform"]["scale"] == [0.001, 0.001, 0.001]
    assert doc["metadata"]["referenceSystem"] == BNG
    building = doc["CityObjects"]["B1"]
    assert building["type"] == "Building"
    verts, faces, geom = decoded(doc, "B1")
    assert geom["type"] == "Solid" and geom["lod"] == "2.2"
    kinds = [geom["semantics"]["surfaces"][v]["type"] for v in geom["semantics"]["values"][0]]
    assert kinds.count("RoofSurface") == 2 and kinds.count("GroundSurface") == 1
    assert kinds.count("WallSurface") == 4
    # closed, 2-manifold and outward after millimetre quantisation
    assert solid_problems(verts - verts.mean(axis=0), faces, planarity_m=0.002) == []
    attrs = building["attributes"]
    assert attrs["function"] == "residential" and attrs["roofType"] == "gable"
    assert abs(attrs["volume"] - GABLE_VOLUME) < 0.02 * GABLE_VOLUME
    assert abs(attrs["measuredHeight"] - 9) < 0.05 and attrs["sigmaMeasuredHeight"] > 0


#: cjio's reader, run in a child process: importing cjio replaces the json module's float
#: encoder for the whole process (6 decimals, no C encoder), which would leak into other tests.
CJIO_READ = """
import json, sys
from cjio import cityjson
with open(sys.argv[1], encoding="utf-8") as f:
    cm = cityjson.reader(f)
cm.check_version()
info = "\\n".join(cm.get_info())
cm.decompress()
print(repr({"version": cm.get_version(), "epsg": cm.get_epsg(), "info": info,
            "vertices": cm.j["vertices"]}))
"""


def test_cjio_reads_the_file_back(tmp_path):
    import ast
    import subprocess
    import sys

    models = [gable("B1"), gable("B2", seed=8)]
    path = tmp_path / "b.city.json"
    path.write_bytes(city_json_bytes(models, BNG))
    run = subprocess.run([sys.executable, "-c", CJIO_READ, str(path)], capture_output=True,
                         text=True, timeout=120)
    assert run.returncode == 0, run.stderr
    got = ast.literal_eval(run.stdout.strip())
    assert got["version"] == "2.0" and got["epsg"] == 27700
    assert "Building (2)" in got["info"]
    vertices = np.array(got["vertices"], dtype=float)  # cjio applied the transform
    want = np.vstack([m.vertices for m in models])
    assert vertices.shape == want.shape
    assert np.abs(vertices - want).max() < 0.001


def test_cjio_command_line_reads_the_file(tmp_path):
    import subprocess
    import sys
    from pathlib import Path

    path = tmp_path / "b.city.json"
    path.write_bytes(city_json_bytes([gable()], BNG))
    run = subprocess.run([str(Path(sys.executable).parent / "cjio"), str(path), "info"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 0, run.stderr
    assert "CityJSON version = 2.0" in run.stdout and "Building (1)" in run.stdout
    assert "EPSG = 27700" in run.stdout


def test_the_schema_check_catches_a_wrong_document():
    doc = json.loads(orjson.dumps(city_json([gable()], BNG)))
    doc["CityObjects"]["B1"]["geometry"][0]["lod"] = 2  # must be text
    with pytest.raises(AssertionError):
        validate_city_json(doc)


def test_several_buildings_share_one_vertex_list_and_hips_are_valid():
    hip = build_building(parse_building({"id": "H", "roofs": HIP_ROOFS, "ground": GROUND}),
                         measured(HIP, 0.02, np.random.default_rng(3)))
    doc = city_json([gable(), hip], BNG)
    validate_city_json(doc)
    assert len(doc["vertices"]) == 10 + 10


def test_two_buildings_with_one_id_are_refused():
    with pytest.raises(InputError, match="two buildings have the id 'B1'"):
        city_json([gable(), gable()], BNG)


def test_an_invalid_solid_is_never_written():
    model = gable()
    model.surfaces = [s for s in model.surfaces if s.kind != "GroundSurface"]
    with pytest.raises(GeometryError, match="not closed"):
        city_json([model], BNG)
    model = gable()
    model.surfaces = [Surface(tuple(reversed(s.ring)), s.kind) for s in model.surfaces]
    with pytest.raises(GeometryError, match="inward"):
        city_json([model], BNG)


@pytest.mark.parametrize("crs, uri", [
    ("EPSG:27700", BNG),
    ("EPSG:7405", "https://www.opengis.net/def/crs/EPSG/0/7405"),  # BNG + ODN height
    ("EPSG:27700+3855", "https://www.opengis.net/def/crs-compound?"
                        "1=https://www.opengis.net/def/crs/EPSG/0/27700&"
                        "2=https://www.opengis.net/def/crs/EPSG/0/3855"),
])
def test_reference_system_uris(crs, uri):
    assert reference_system_uri(pyproj.CRS.from_user_input(crs)) == uri
    meta = metadata_reference_system(uri)
    assert meta.startswith("https://www.opengis.net/def/crs/EPSG/0/")


def test_a_crs_without_epsg_code_is_refused():
    crs = pyproj.CRS.from_proj4("+proj=tmerc +lat_0=49 +lon_0=-2.1 +k=0.99 +x_0=400000 "
                                "+y_0=-100000 +ellps=airy +units=m")
    with pytest.raises(InputError, match="no EPSG code"):
        reference_system_uri(crs)


def test_the_solid_checks_name_what_is_wrong():
    cube = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0],
                     [0, 0, 1], [1, 0, 1], [1, 1, 1], [0, 1, 1]], dtype=float)
    faces = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
    assert solid_problems(cube, faces) == []
    bowtie = [*faces[:1], (4, 5, 7, 6), *faces[2:]]
    assert any("face 1 crosses itself" in p for p in solid_problems(cube, bowtie))
    bent = cube.copy()
    bent[6, 2] = 1.1
    assert any("face 1 is not planar" in p for p in solid_problems(bent, faces))
    assert any("not closed" in p for p in solid_problems(cube, faces[:-1]))
    flipped = [faces[0][::-1], *faces[1:]]
    assert any("runs the same way" in p for p in solid_problems(cube, flipped))
    inward = [f[::-1] for f in faces]
    assert any("inward" in p for p in solid_problems(cube, inward))
