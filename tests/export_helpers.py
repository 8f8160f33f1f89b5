"""A synthetic measured scene for export tests: points around a house near Coventry (lon -1.5,
lat 52.5, inside EPSG:27700, UTM zone 30N and EGM96), lines and polygons by point id, and a fake
OSGM15 geoid so EPSG:27700+5701 heights can be computed offline."""

from __future__ import annotations

import contextlib

import numpy as np
import pyproj
import rasterio
from affine import Affine
from crs_helpers import camera_origins, noisy_directions

from gsgeo.crs.frames import EnuFrame, geodetic_to_ecef
from gsgeo.session import parse_session

LON0, LAT0, H0 = -1.5, 52.5, 95.0
IFOV = 0.0008
#: Local east, north, up offsets (m) of the points from (LON0, LAT0, H0).
LAYOUT = {
    "P1": (0.0, 0.0, 0.0), "P2": (10.0, 0.0, 0.5), "P3": (10.0, 8.0, 1.0),
    "P4": (0.0, 8.0, 0.2), "P5": (5.0, 4.0, 6.0), "P6": (15.0, -3.0, 0.0),
}
UNWEIGHTED = {"P6"}  # no ifov: unweighted model, max_residual_px null


def session_doc(rng, *, crs=None, lines=None, polygons=None, points=LAYOUT) -> dict:
    centre = geodetic_to_ecef(LON0, LAT0, H0).reshape(3)
    frame = EnuFrame(centre)
    pts = []
    for k, (pid, enu) in enumerate(points.items()):
        p = frame.to_ecef(np.array(enu, dtype=float))
        o = camera_origins(p, 4 + k % 2, rng)
        d = noisy_directions(o, p, IFOV, rng)
        rays = []
        for oo, dd in zip(o, d, strict=True):
            ray = {"origin": oo.tolist(), "direction": dd.tolist()}
            if pid not in UNWEIGHTED:
                ray["ifov"] = IFOV
            rays.append(ray)
        pts.append({"id": pid, "code": "roof" if pid == "P5" else "corner",
                    "description": f"synthetic point {pid}", "rays": rays})
    doc = {"source_crs": "EPSG:4978", "crs": crs, "sigma_px": 1.0, "points": pts,
           "lines": [{"id": "L1", "points": ["P1", "P2", "P3"]}, {"id": "L2", "points": ["P5", "P6"]}]
           if lines is None else lines,
           # given clockwise in (E, N); exports must write it counterclockwise
           "polygons": [{"id": "A1", "points": ["P1", "P4", "P3", "P2"]}] if polygons is None else polygons}
    return doc


def session(rng, **kw):
    return parse_session(session_doc(rng, **kw))


def undulation(lon, lat):
    """Fake geoid undulation (m): smooth, about 48 m near the scene."""
    return 45.0 + 0.5 * (lon + 9.0) + 0.2 * (lat - 49.0)


def write_fake_osgm15(directory) -> None:
    """A GeoTIFF named as PROJ's OSGM15 grid (ETRS89 -> ODN), bilinear-exact for `undulation`."""
    res = 0.25
    west, north, cols, rows = -9.0, 61.0, 49, 49  # pixel centres on multiples of res
    lon = west + np.arange(cols) * res
    lat = north - np.arange(rows) * res
    n = undulation(lon[None, :], lat[:, None]).astype(np.float64)
    with rasterio.open(directory / "uk_os_OSGM15_GB.tif", "w", driver="GTiff", width=cols,
                       height=rows, count=1, dtype="float32", crs="EPSG:4258",
                       transform=Affine(res, 0, west - res / 2, 0, -res, north + res / 2)) as ds:
        ds.write(n.astype(np.float32), 1)


@contextlib.contextmanager
def proj_data_dir(path):
    """PROJ finds grids in `path` too, for the duration of the block."""
    original = pyproj.datadir.get_data_dir()
    try:
        pyproj.datadir.append_data_dir(str(path))
        yield
    finally:
        pyproj.datadir.set_data_dir(original)
