"""The ground height of a building from a DTM GeoTIFF (read with rasterio).

``dtm_ground`` samples the DTM under the building's footprint: at the footprint's vertices and
at every pixel whose centre lies inside it, and takes the MINIMUM of these samples (a building
stands on its lowest ground; on a slope the walls reach down to it). Its sigma is the standard
deviation of the samples: how much the ground varies under the building, the uncertainty of
"the" ground height when the DTM itself states none.

The DTM's values are taken as heights in the project's height system (same vertical datum and
units); the footprint is transformed into the DTM's CRS when the two differ (a DTM without a
CRS is taken to be in the project's grid CRS).
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pyproj

from gsgeo.crs.transformers import transform_xy, transformer
from gsgeo.errors import InputError
from gsgeo.solve.linalg import FloatArray

FIELD = "ground.dtm"


def _horizontal(crs: pyproj.CRS) -> pyproj.CRS:
    """The horizontal part of a compound CRS (the CRS itself otherwise)."""
    if crs.is_compound and crs.sub_crs_list:
        return crs.sub_crs_list[0]
    return crs


def dtm_ground(path: str | os.PathLike[str], footprint_en: FloatArray,
               crs: pyproj.CRS) -> tuple[float, float]:
    """(ground height, 1-sigma in the DTM's units) under the footprint ``footprint_en`` (k, 2):
    the grid E, N of the building's outline in order, in ``crs`` (the project's CRS).

    InputError (field ``ground.dtm``) when the file is missing or unreadable, the footprint
    lies (partly) outside the DTM, or the DTM has no data under it.
    """
    import rasterio
    import rasterio.features
    from affine import Affine
    from rasterio.errors import RasterioError
    from rasterio.windows import Window

    p = Path(path).expanduser()
    if not p.is_file():
        raise InputError(f"DTM file {str(path)!r}: no such file", field=FIELD)
    fp = np.asarray(footprint_en, dtype=np.float64).reshape(-1, 2)
    if fp.shape[0] < 3 or not np.all(np.isfinite(fp)):
        raise InputError("the building's footprint needs at least 3 finite points",
                         field=FIELD)
    try:
        ds = rasterio.open(p)
    except RasterioError as exc:
        raise InputError(f"DTM file {str(path)!r}: not a raster GDAL can read ({exc})",
                         field=FIELD) from None
    with ds:
        if ds.count < 1 or ds.width == 0 or ds.height == 0:
            raise InputError(f"DTM file {str(path)!r} has no band", field=FIELD)
        x, y = fp[:, 0], fp[:, 1]
        if ds.crs is not None:
            dtm_crs = pyproj.CRS.from_wkt(ds.crs.to_wkt())
            src = _horizontal(crs)
            if not _horizontal(dtm_crs).equals(src, ignore_axis_order=True):
                x, y = transform_xy(transformer(src, _horizontal(dtm_crs)), x, y)
                if not (np.all(np.isfinite(x)) and np.all(np.isfinite(y))):
                    raise InputError(f"DTM file {str(path)!r}: the footprint cannot be "
                                     "transformed into the DTM's CRS", field=FIELD)
        inv = ~ds.transform
        cols = np.floor(inv.a * x + inv.b * y + inv.c).astype(np.int64)
        rows = np.floor(inv.d * x + inv.e * y + inv.f).astype(np.int64)
        if (cols.min() < 0 or rows.min() < 0 or cols.max() >= ds.width
                or rows.max() >= ds.height):
            raise InputError(f"the building's footprint lies outside the DTM {p.name} "
                             f"(bounds {tuple(round(v, 3) for v in ds.bounds)})", field=FIELD)
        c0, r0 = int(cols.min()), int(rows.min())
        window = Window(c0, r0, int(cols.max()) - c0 + 1, int(rows.max()) - r0 + 1)
        try:
            data = ds.read(1, window=window, masked=True).astype(np.float64)
        except RasterioError as exc:
            raise InputError(f"DTM file {str(path)!r}: cannot read its pixels ({exc})",
                             field=FIELD) from None
        shape = (int(window.height), int(window.width))
        polygon = {"type": "Polygon",
                   "coordinates": [[(float(a), float(b)) for a, b in zip(x, y, strict=True)]
                                   + [(float(x[0]), float(y[0]))]]}
        t = ds.transform
        corner = Affine(t.a, t.b, t.c + t.a * c0 + t.b * r0, t.d, t.e, t.f + t.d * c0 + t.e * r0)
        inside = rasterio.features.geometry_mask([polygon], out_shape=shape, transform=corner,
                                                 invert=True)
    values = np.ma.filled(data, np.nan)
    samples = np.concatenate([values[rows - r0, cols - c0], values[inside]])
    samples = samples[np.isfinite(samples)]
    if samples.size == 0:
        raise InputError(f"the DTM {p.name} has no data under the building's footprint",
                         field=FIELD)
    return float(samples.min()), float(samples.std())
