"""Heights: a synthetic geoid GeoTIFF, PROJ's silent ballpark refused, egm96 two ways."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyproj
import pytest
import rasterio
from affine import Affine

from gsgeo.crs.frames import geodetic_to_ecef
from gsgeo.crs.geoid import UNCERTAINTY_TAG
from gsgeo.crs.grid import to_grid, to_grid_many
from gsgeo.errors import DatumError, InputError

EGM96 = Path("/usr/share/proj/egm96_15.gtx")


def undulation(lon, lat):
    """A smooth, non-linear geoid (m) whose bilinear interpolation error is below 0.2 mm."""
    return 45.0 + 2.0 * (lon + 2.0) - 3.0 * (lat - 52.0) + 0.5 * np.sin(lon) * np.cos(lat)


def write_geoid(path, *, tag=None, sigma_band=None, res=0.01, nodata_at=None):
    west, north = -2.0, 53.0
    cols, rows = 100, 100
    lon = west + (np.arange(cols) + 0.5) * res  # pixel centres
    lat = north - (np.arange(rows) + 0.5) * res
    n = undulation(lon[None, :], lat[:, None]).astype(np.float32)
    if nodata_at is not None:
        n[nodata_at] = -9999
    bands = 1 if sigma_band is None else 2
    with rasterio.open(path, "w", driver="GTiff", width=cols, height=rows, count=bands,
                       dtype="float32", crs="EPSG:4326", transform=Affine(res, 0.0, west, 0.0, -res, north),
                       nodata=-9999) as ds:
        ds.write(n, 1)
        if sigma_band is not None:
            ds.write(np.full((rows, cols), sigma_band, dtype=np.float32), 2)
            ds.set_band_description(2, "uncertainty")
        if tag is not None:
            ds.update_tags(**{UNCERTAINTY_TAG: str(tag)})
    return path


COV = np.diag([0.02, 0.02, 0.03]) ** 2


def test_geoid_geotiff_gives_h_minus_n_and_adds_its_uncertainty(tmp_path):
    geoid = write_geoid(tmp_path / "geoid.tif", tag=0.05)
    lon, lat, h = -1.237, 52.481, 80.0
    p = geodetic_to_ecef(lon, lat, h)
    ell = to_grid(p, COV, "EPSG:27700")
    ort = to_grid(p, COV, "EPSG:27700", geoid=geoid)
    assert ort.height == pytest.approx(h - undulation(lon, lat), abs=3e-4)
    assert ort.height_type == "orthometric" and "geoid.tif" in ort.vertical_datum
    assert ell.height_type == "ellipsoidal" and ell.height == pytest.approx(h, abs=1e-6)
    assert (ort.easting, ort.northing) == (ell.easting, ell.northing)
    assert ort.sigma_h == pytest.approx(np.sqrt(ell.sigma_h**2 + 0.05**2), rel=1e-9)
    assert ort.sigma_e == pytest.approx(ell.sigma_e)


def test_geoid_uncertainty_band_and_no_stated_uncertainty(tmp_path):
    p = geodetic_to_ecef(-1.5, 52.5, 80.0)
    band = to_grid(p, COV, "EPSG:27700", geoid=write_geoid(tmp_path / "b.tif", sigma_band=0.12))
    none = to_grid(p, COV, "EPSG:27700", geoid=write_geoid(tmp_path / "n.tif"))
    ell = to_grid(p, COV, "EPSG:27700")
    assert band.sigma_h == pytest.approx(np.sqrt(ell.sigma_h**2 + 0.12**2), rel=1e-6)
    assert none.sigma_h == pytest.approx(ell.sigma_h)
    assert "no stated uncertainty" in none.vertical_datum


def test_bilinear_uses_pixel_centres(tmp_path):
    """Many points: the interpolated N follows the analytic surface (half-pixel shifts would not)."""
    geoid = write_geoid(tmp_path / "g.tif")
    rng = np.random.default_rng(2)
    lon = rng.uniform(-1.99, -1.01, 500)
    lat = rng.uniform(52.01, 52.99, 500)
    p = geodetic_to_ecef(lon, lat, np.full(500, 50.0))
    g = to_grid_many(p, None, "EPSG:27700", geoid=geoid)
    np.testing.assert_allclose(50.0 - g.height, undulation(lon, lat), atol=3e-4)


def test_point_outside_or_on_nodata_is_a_clear_error(tmp_path):
    geoid = write_geoid(tmp_path / "g.tif", nodata_at=(50, 50))
    with pytest.raises(DatumError, match="outside the geoid grid"):
        to_grid(geodetic_to_ecef(-3.5, 52.5, 10.0), None, "EPSG:27700", geoid=geoid)
    with pytest.raises(DatumError, match="no-data"):
        to_grid(geodetic_to_ecef(-1.495, 52.495, 10.0), None, "EPSG:27700", geoid=geoid)
    with pytest.raises(InputError, match="no such file"):
        to_grid(geodetic_to_ecef(-1.5, 52.5, 10.0), None, "EPSG:27700", geoid=tmp_path / "nope.tif")
    bad = tmp_path / "bad.tif"
    bad.write_text("not a raster")
    with pytest.raises(InputError, match="not a raster"):
        to_grid(geodetic_to_ecef(-1.5, 52.5, 10.0), None, "EPSG:27700", geoid=bad)


@pytest.mark.parametrize("crs", ["EPSG:27700+5701", "EPSG:7405"])
def test_compound_with_missing_grid_refuses_the_ballpark(crs):
    p = geodetic_to_ecef(-1.5, 52.5, 80.0)
    # PROJ itself silently returns H = h here (the trap) ...
    t = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:27700+5701", always_xy=True)
    assert t.transform(-1.5, 52.5, 80.0)[2] == pytest.approx(80.0)
    # ... gsgeo names the grid and both ways to supply it
    with pytest.raises(DatumError) as err:
        to_grid(p, None, crs)
    msg = str(err.value)
    assert "uk_os_OSGM15_GB.tif" in msg
    assert "PROJ data directory" in msg and "--geoid FILE.tif" in msg
    with pytest.raises(DatumError, match="uk_os_OSGM15_GB.tif"):
        to_grid(p, None, "EPSG:27700", vertical="EPSG:5701")


@pytest.mark.skipif(not EGM96.is_file(), reason="Debian proj-data's egm96_15.gtx is not installed")
def test_vertical_crs_with_grid_in_proj_path_equals_geoid_file():
    """EGM96 height via PROJ (grid found in an added data directory) = the same file via rasterio."""
    p = geodetic_to_ecef(np.array([-1.5, -1.43]), np.array([52.5, 52.61]), np.array([80.0, 95.0]))
    by_file = to_grid_many(p, None, "EPSG:32630", geoid=EGM96)
    with pytest.raises(DatumError, match="egm96"):
        to_grid_many(p, None, "EPSG:32630", vertical="EPSG:5773")
    original = pyproj.datadir.get_data_dir()
    try:
        pyproj.datadir.append_data_dir(str(EGM96.parent))
        by_proj = to_grid_many(p, None, "EPSG:32630", vertical="EPSG:5773")
    finally:
        pyproj.datadir.set_data_dir(original)
    np.testing.assert_allclose(by_proj.height, by_file.height, atol=1e-6)
    assert np.all(np.abs(by_proj.height - by_proj.h_ellipsoidal) > 40)  # N is ~47 m here
    assert by_proj.height_type == "orthometric" and by_proj.crs == "EPSG:32630+5773"
    assert "EGM96" in by_proj.operation
