"""`gsgeo solve SESSION.json --crs CRS -o out.city.json`: LoD2 buildings of a session as CityJSON.

The held-out case of issue 19: a gable house (12 m x 8 m, eaves at 6 m, ridge 3 m higher)
measured by noisy rays becomes one CityJSON 2.0 Building with a closed, outward LoD2 Solid of
the right volume and roof; a roof naming an unknown point exits 2 naming it and writes nothing.
"""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pyogrio
import pytest
from building_helpers import CRS, GROUND, VOLUME, house_session, truth
from cityjson_helpers import validate_city_json

from gsgeo.cli import main
from gsgeo.export.tables import BUILDING_TYPES


def write(tmp_path, doc, name="house.json"):
    p = tmp_path / name
    p.write_text(json.dumps(doc))
    return p


def vertices(doc: dict) -> np.ndarray:
    """The document's vertices in real coordinates (its transform applied)."""
    t = doc["transform"]
    return np.asarray(doc["vertices"], dtype=float) * t["scale"] + t["translate"]


def shell_faces(geometry: dict) -> list[list[int]]:
    """The outer rings of the faces of a Solid's outer shell."""
    return [face[0] for face in geometry["boundaries"][0]]


def directed_edges(faces: list[list[int]]) -> Counter:
    return Counter((a, b) for f in faces for a, b in zip(f, f[1:] + f[:1], strict=True))


def signed_volume(xyz: np.ndarray, faces: list[list[int]]) -> float:
    """Divergence theorem over fan triangles (positive for outward-facing rings)."""
    c = xyz.mean(axis=0)
    v = 0.0
    for f in faces:
        p = xyz[f] - c
        for k in range(1, len(f) - 1):
            v += np.dot(p[0], np.cross(p[k], p[k + 1])) / 6.0
    return float(v)


def test_gable_house_measured_by_noisy_rays_becomes_a_valid_cityjson_lod2_solid(tmp_path,
                                                                                capsys):
    session = write(tmp_path, house_session())
    out = tmp_path / "out.city.json"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 0
    assert "building B1" in capsys.readouterr().out
    doc = json.loads(out.read_text())
    validate_city_json(doc)  # the official CityJSON 2.0 schema
    assert doc["type"] == "CityJSON" and doc["version"] == "2.0"
    assert doc["metadata"]["referenceSystem"].endswith("/def/crs/EPSG/0/27700")
    assert doc["transform"]["scale"] == [0.001, 0.001, 0.001]
    buildings = {k: v for k, v in doc["CityObjects"].items() if v["type"] == "Building"}
    assert list(buildings) == ["B1"]
    (geom,) = buildings["B1"]["geometry"]
    assert geom["type"] == "Solid" and str(geom["lod"]).startswith("2")
    assert len(geom["boundaries"]) == 1  # one shell, no cavities

    faces = shell_faces(geom)
    xyz = vertices(doc)
    edges = directed_edges(faces)
    # closed 2-manifold, consistently oriented: each edge once in each direction
    assert all(n == 1 for n in edges.values())
    assert all(edges[(b, a)] == 1 for a, b in edges)
    volume = signed_volume(xyz, faces)
    assert volume > 0  # outward normals
    assert volume == pytest.approx(VOLUME, rel=0.02)
    assert buildings["B1"]["attributes"]["volume"] == pytest.approx(VOLUME, rel=0.02)
    assert buildings["B1"]["attributes"]["function"] == "residential"

    kinds = [geom["semantics"]["surfaces"][v]["type"] for v in geom["semantics"]["values"][0]]
    count = Counter(kinds)
    assert count["RoofSurface"] == 2 and count["GroundSurface"] == 1
    assert count["WallSurface"] >= 4 and set(count) == {"RoofSurface", "GroundSurface",
                                                        "WallSurface"}
    # every roof vertex within 5 cm of the truth; the ground at the given height
    roof_vertices = {i for f, k in zip(faces, kinds, strict=True) if k == "RoofSurface"
                     for i in f}
    assert len(roof_vertices) == len(truth()) == 6
    roof_xyz = xyz[sorted(roof_vertices)]
    nearest = {pid: int(np.argmin(np.linalg.norm(roof_xyz - true, axis=1)))
               for pid, true in truth().items()}
    assert sorted(nearest.values()) == list(range(6))  # one vertex per corner
    for pid, true in truth().items():
        assert np.linalg.norm(roof_xyz[nearest[pid]] - true) < 0.05, pid
    ground = [i for f, k in zip(faces, kinds, strict=True) if k == "GroundSurface" for i in f]
    assert np.allclose(xyz[ground, 2], GROUND, atol=0.001)


@pytest.mark.parametrize("where", ["roofs", "ground"])
def test_a_building_naming_an_unknown_point_exits_2_naming_it_and_writes_no_file(
        tmp_path, capsys, where):
    change = ({"roofs": [["E1", "E2", "R2", "X9"], ["E3", "E4", "R1", "R2"]]}
              if where == "roofs" else {"ground": "X9"})
    session = write(tmp_path, house_session(**change))
    out = tmp_path / "out.city.json"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "'X9'" in err and "B1" in err and "Traceback" not in err
    assert not out.exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["house.json"]  # no partial file


def test_a_failed_build_leaves_an_earlier_export_untouched(tmp_path, capsys):
    out = tmp_path / "out.city.json"
    out.write_text("earlier")
    session = write(tmp_path, house_session(roofs=[["E1", "E2", "R2"], ["E1", "R2", "R1"],
                                                   ["E1", "E2", "E3"]]))
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 2
    assert "B1" in capsys.readouterr().err
    assert out.read_text() == "earlier"


def test_export_format_cityjson_overrides_the_suffix(tmp_path):
    session = write(tmp_path, house_session())
    out = tmp_path / "model.json"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out),
                 "--export-format", "cityjson"]) == 0
    doc = json.loads(out.read_text())
    assert doc["type"] == "CityJSON" and "B1" in doc["CityObjects"]


def test_cityjson_of_a_session_without_buildings_exits_2_before_solving(tmp_path, capsys):
    doc = house_session()
    del doc["buildings"]
    out = tmp_path / "out.city.json"
    assert main(["solve", str(write(tmp_path, doc)), "--crs", CRS, "-o", str(out)]) == 2
    assert "no buildings" in capsys.readouterr().err
    assert not out.exists()


def test_duplicate_building_ids_are_refused_naming_the_second(tmp_path, capsys):
    doc = house_session()
    doc["buildings"].append(dict(doc["buildings"][0]))
    assert main(["solve", str(write(tmp_path, doc)), "--crs", CRS]) == 2
    err = capsys.readouterr().err
    assert "buildings[1].id" in err and "duplicate building id 'B1'" in err


def test_the_geopackage_export_holds_the_buildings_surfaces(tmp_path):
    session = write(tmp_path, house_session())
    out = tmp_path / "out.gpkg"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 0
    df = pyogrio.read_dataframe(out, layer="buildings")
    assert list(df.columns[:-1]) == list(BUILDING_TYPES)
    assert df.crs.to_epsg() == 27700
    assert Counter(df["surface_type"]) == Counter(
        {"RoofSurface": 2, "GroundSurface": 1, "WallSurface": len(df) - 3})
    assert set(df["building_id"]) == {"B1"} and set(df["roof_type"]) == {"gable"}
    assert df["volume"].iloc[0] == pytest.approx(VOLUME, rel=0.02)
    assert (df["sigma_volume"] > 0).all()
    assert all(g.has_z and g.geom_type == "Polygon" for g in df.geometry)
    ground = df[df["surface_type"] == "GroundSurface"].geometry.iloc[0]
    assert ground.area == pytest.approx(96.0, rel=0.02)  # 12 m x 8 m footprint
    info = pyogrio.read_info(out, layer="buildings")
    assert info["geometry_type"] == "Polygon Z"


def test_json_output_carries_the_buildings(tmp_path, capsys):
    session = write(tmp_path, house_session())
    assert main(["solve", str(session), "--crs", CRS, "--json"]) == 0
    doc = json.loads(capsys.readouterr().out)
    (b,) = doc["buildings"]
    assert b["id"] == "B1" and b["measures"]["volume"] == pytest.approx(VOLUME, rel=0.02)


def write_flat_dtm(path, height: float) -> None:
    """A 60 m x 60 m GeoTIFF (1 m pixels, EPSG:27700) at ``height`` around the house."""
    import rasterio
    from rasterio.transform import from_origin

    e0, n0 = truth()["E1"][:2]
    path.parent.mkdir(parents=True, exist_ok=True)
    with rasterio.open(path, "w", driver="GTiff", width=60, height=60, count=1,
                       dtype="float32", crs=CRS,
                       transform=from_origin(e0 - 30, n0 + 30, 1.0, 1.0)) as ds:
        ds.write(np.full((1, 60, 60), height, dtype="float32"))


def test_a_dtm_ground_is_read_relative_to_the_session_file(tmp_path, monkeypatch):
    write_flat_dtm(tmp_path / "terrain" / "dtm.tif", GROUND)
    session = write(tmp_path, house_session(ground={"dtm": "terrain/dtm.tif"}))
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)
    out = tmp_path / "out.city.json"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 0
    doc = json.loads(out.read_text())
    assert doc["CityObjects"]["B1"]["attributes"]["volume"] == pytest.approx(VOLUME, rel=0.02)


def test_a_missing_dtm_exits_2_naming_it(tmp_path, capsys):
    session = write(tmp_path, house_session(ground={"dtm": "nowhere.tif"}))
    out = tmp_path / "out.city.json"
    assert main(["solve", str(session), "--crs", CRS, "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert "ground.dtm" in err and "nowhere.tif" in err
    assert not out.exists()


def test_a_dtm_under_a_roof_without_plan_area_exits_2(tmp_path, capsys):
    write_flat_dtm(tmp_path / "dtm.tif", GROUND)
    vertical = [["E1", "R1", "E4"]]  # E1, E4 and R1 lie on one vertical gable line in plan
    session = write(tmp_path, house_session(roofs=vertical, ground={"dtm": "dtm.tif"}))
    assert main(["solve", str(session), "--crs", CRS]) == 2
    err = capsys.readouterr().err
    assert "B1" in err and "Traceback" not in err and "internal" not in err
