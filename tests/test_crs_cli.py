"""`gsgeo solve` with grid output and `gsgeo crs search|info`."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
from conftest import REPO
from pyproj import Transformer

from gsgeo.cli import main
from gsgeo.measure.schema import RECORD_KEYS

EXAMPLE = REPO / "examples" / "session.json"


def test_solve_prints_grid_coordinates_and_the_ensemble_warning(capsys):
    assert main(["solve", str(EXAMPLE), "--crs", "EPSG:27700"]) == 0
    cap = capsys.readouterr()
    assert "Easting" in cap.out and "Northing" in cap.out and "EPSG:27700" in cap.out
    assert "OSGB36 to WGS 84" in cap.out and "accuracy 2 m" in cap.out
    warn = [ln for ln in cap.err.splitlines() if "warning" in ln]
    assert len(warn) == 1 and "accurate to 2 m" in warn[0] and "--source-crs" in warn[0]


def test_solve_json_carries_every_point_schema_field(capsys):
    assert main(["solve", str(EXAMPLE), "--json"]) == 0  # the session's crs is EPSG:27700
    doc = json.loads(capsys.readouterr().out)
    assert [p["point_id"] for p in doc["points"]] == ["P1", "P2", "P3"]
    for p in doc["points"]:
        assert list(p)[:len(RECORD_KEYS)] == list(RECORD_KEYS)
        assert all(p[k] is not None for k in RECORD_KEYS if k not in ("description",))
    # grid coordinates agree with pyproj applied to the solved ECEF point
    p = doc["points"][0]
    e, n, _ = Transformer.from_crs("EPSG:4978", "EPSG:27700", always_xy=True).transform(*p["point_ecef"])
    assert p["easting"] == pytest.approx(e, abs=1e-4) and p["northing"] == pytest.approx(n, abs=1e-4)


def test_solve_declared_source_crs_has_no_warning(capsys):
    assert main(["solve", str(EXAMPLE), "--crs", "EPSG:25830", "--source-crs", "EPSG:4936"]) == 0
    cap = capsys.readouterr()
    assert "exact conversion" in cap.out and "warning" not in cap.err


def test_solve_with_a_geoid_file(tmp_path, capsys):
    import rasterio
    from affine import Affine

    g = tmp_path / "flat.tif"
    with rasterio.open(g, "w", driver="GTiff", width=4, height=4, count=1, dtype="float32",
                       crs="EPSG:4326", transform=Affine(0.5, 0, -1.0, 0, -0.5, 52.5)) as ds:
        ds.write(np.full((4, 4), 47.0, dtype=np.float32), 1)
        ds.update_tags(UNCERTAINTY_M="0.04")
    assert main(["solve", str(EXAMPLE), "--json"]) == 0
    ell = json.loads(capsys.readouterr().out)["points"][0]
    assert main(["solve", str(EXAMPLE), "--json", "--geoid", str(g)]) == 0
    ort = json.loads(capsys.readouterr().out)["points"][0]
    assert ort["height"] == pytest.approx(ell["height"] - 47.0, abs=1e-6)
    assert ort["height_type"] == "orthometric" and "flat.tif" in ort["vertical_datum"]
    assert ort["sigma_h"] == pytest.approx(np.hypot(ell["sigma_h"], 0.04), rel=1e-6)


@pytest.mark.parametrize(
    ("args", "words"),
    [
        (["--crs", "EPSG:999999"], "unknown CRS"),
        (["--crs", "EPSG:4326"], "geographic CRS"),
        (["--crs", "EPSG:27700", "--vertical", "EPSG:5701"], "uk_os_OSGM15_GB.tif"),
        (["--crs", "EPSG:27700+5701"], "--geoid FILE.tif"),
        (["--crs", "EPSG:27700", "--source-crs", "EPSG:4326"], "not geocentric"),
    ],
)
def test_solve_crs_errors_exit_2(args, words, capsys):
    assert main(["solve", str(EXAMPLE), *args]) == 2
    err = capsys.readouterr().err
    assert words in err and "Traceback" not in err


def test_solve_outside_area_of_use_is_a_warning(capsys):
    assert main(["solve", str(EXAMPLE), "--crs", "EPSG:7856"]) == 0  # MGA 56 for London
    assert "outside the area of use of EPSG:7856" in capsys.readouterr().err


def test_crs_search_and_info(capsys):
    assert main(["crs", "search", "british", "national", "grid"]) == 0
    out = capsys.readouterr().out
    assert "EPSG:27700" in out and "EPSG:7405" in out and "United Kingdom" in out
    assert main(["crs", "search", "27700"]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("EPSG:27700")
    assert main(["crs", "search", "utm", "32N", "--json"]) == 0
    assert "EPSG:25832" in [r["code"] for r in json.loads(capsys.readouterr().out)]
    assert main(["crs", "search", "no such crs name xyz"]) == 0  # no match: an answer, not an error
    assert "CRS matches 'no such crs name xyz'" in capsys.readouterr().err
    assert main(["crs", "info", "EPSG:27700"]) == 0
    out = capsys.readouterr().out
    for words in ("metre", "Airy 1830", "Transverse Mercator", "area of use",
                  "OSGB36 to WGS 84 (6)", "accuracy 2 m", "uk_os_OSTN15_NTv2_OSGBtoETRS.tif"):
        assert words in out
    assert main(["crs", "info", "EPSG:25832", "--source-crs", "EPSG:4936", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["operations"][0]["accuracy_m"] == 0.0
    assert main(["crs", "info", "EPSG:123456789"]) == 2
    assert "unknown CRS" in capsys.readouterr().err


def test_crs_command_in_a_subprocess_no_traceback():
    run = subprocess.run([sys.executable, "-m", "gsgeo", "crs", "info", "nonsense"],
                         capture_output=True, text=True, cwd=REPO)
    assert run.returncode == 2 and "unknown CRS" in run.stderr and "Traceback" not in run.stderr
