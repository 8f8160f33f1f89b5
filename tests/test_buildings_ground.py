"""The ground of a building from a DTM GeoTIFF (written here with rasterio)."""

from __future__ import annotations

import numpy as np
import pyproj
import pytest
import rasterio
from affine import Affine
from buildings_helpers import GABLE, GABLE_ROOFS, GABLE_VOLUME, OFFSET, measured

from gsgeo.buildings.ground import dtm_ground
from gsgeo.buildings.model import build_building, footprint_en
from gsgeo.buildings.spec import parse_building
from gsgeo.errors import InputError

BNG = pyproj.CRS("EPSG:27700")


def write_dtm(path, crs, west, north, pixel, heights):
    rows, cols = heights.shape
    with rasterio.open(path, "w", driver="GTiff", width=cols, height=rows, count=1,
                       dtype="float32", crs=crs, transform=Affine(pixel, 0, west, 0, -pixel, north),
                       nodata=-9999.0) as ds:
        ds.write(heights.astype(np.float32), 1)


def sloped_dtm(path):
    """0.5 m pixels from 10 m west/south of the house; H = 10 + 0.1 * (E - E0) (rises east)."""
    west, north, pixel = OFFSET[0] - 10, OFFSET[1] + 20, 0.5
    cols, rows = 64, 60
    e = west + pixel * (np.arange(cols) + 0.5)
    heights = np.tile(10.0 + 0.1 * (e - OFFSET[0]), (rows, 1))
    write_dtm(path, "EPSG:27700", west, north, pixel, heights)


def test_the_ground_is_the_lowest_dtm_sample_under_the_footprint(tmp_path):
    path = tmp_path / "dtm.tif"
    sloped_dtm(path)
    spec = parse_building({"id": "B", "roofs": GABLE_ROOFS, "ground": {"dtm": str(path)}})
    pts = measured(GABLE, 0.01, np.random.default_rng(1), ground=10.0)
    fp = footprint_en(spec, pts)
    height, sigma = dtm_ground(path, fp, BNG)
    # the west wall stands at E0 (measured within a centimetre): its pixel, centred 0.25 m
    # west or east of E0, reads 9.975 or 10.025, the lowest under the footprint
    assert height == pytest.approx(9.975, abs=1e-4) or height == pytest.approx(10.025, abs=1e-4)
    assert 0.3 < sigma < 0.4  # 12 m of a 10 % slope: a spread of about 0.35 m
    model = build_building(spec, pts, ground_height=height, ground_sigma=sigma)
    assert model.measures["ground_height"] == height
    assert abs(model.measures["volume"] - GABLE_VOLUME) < 0.02 * GABLE_VOLUME
    assert model.measures["sigma_measured_height"] > sigma


def test_a_dtm_in_another_crs_is_sampled_where_the_building_is(tmp_path):
    utm = pyproj.CRS("EPSG:32631")
    to_utm = pyproj.Transformer.from_crs(BNG, utm, always_xy=True)
    x0, y0 = to_utm.transform(OFFSET[0] + 6, OFFSET[1] + 4)
    heights = np.full((80, 80), 12.5)
    heights[40:, :] = 11.0  # the southern half is lower, the house's centre is on the line
    write_dtm(tmp_path / "utm.tif", "EPSG:32631", x0 - 20, y0 + 20, 0.5, heights)
    fp = np.array([[OFFSET[0], OFFSET[1]], [OFFSET[0] + 12, OFFSET[1]],
                   [OFFSET[0] + 12, OFFSET[1] + 8], [OFFSET[0], OFFSET[1] + 8]])
    height, _ = dtm_ground(tmp_path / "utm.tif", fp, BNG)
    assert height == pytest.approx(11.0)
    north_only = fp + np.array([0.0, 6.0])
    assert dtm_ground(tmp_path / "utm.tif", north_only, BNG)[0] == pytest.approx(12.5)


def test_bad_dtms_are_refused_with_a_message(tmp_path):
    fp = np.array([[OFFSET[0], OFFSET[1]], [OFFSET[0] + 12, OFFSET[1]],
                   [OFFSET[0] + 12, OFFSET[1] + 8]])
    with pytest.raises(InputError, match="no such file") as err:
        dtm_ground(tmp_path / "missing.tif", fp, BNG)
    assert err.value.field == "ground.dtm"
    (tmp_path / "junk.tif").write_bytes(b"not a raster")
    with pytest.raises(InputError, match="not a raster"):
        dtm_ground(tmp_path / "junk.tif", fp, BNG)
    sloped_dtm(tmp_path / "dtm.tif")
    with pytest.raises(InputError, match="outside the DTM"):
        dtm_ground(tmp_path / "dtm.tif", fp + 100.0, BNG)
    write_dtm(tmp_path / "empty.tif", "EPSG:27700", OFFSET[0] - 10, OFFSET[1] + 20, 0.5,
              np.full((60, 64), -9999.0))
    with pytest.raises(InputError, match="no data under"):
        dtm_ground(tmp_path / "empty.tif", fp, BNG)
