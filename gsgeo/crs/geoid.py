"""User geoid models as rasters (GeoTIFF, or any GDAL raster such as PROJ's .gtx), read with rasterio.

Band 1 holds the geoid undulation N in metres (height of the geoid above the ellipsoid), so
an orthometric height is H = h - N, with h the ellipsoidal height on the same ellipsoid and
realisation the geoid model refers to (for gsgeo: the scene's source CRS, see grid.py).

Stated uncertainty of N (1 sigma, metres), in this order of precedence:

1. a band whose description is ``uncertainty`` (or starts with ``sigma``): per-pixel sigma of
   N, interpolated like N;
2. a metadata tag ``UNCERTAINTY_M`` on band 1 or on the dataset: one sigma for the grid.

Without either, the geoid adds nothing to sigma_h (and the record says so).
Interpolation is bilinear between pixel centres; a raster without a CRS is taken to be in
longitude/latitude degrees.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import DatumError, InputError

UNCERTAINTY_TAG = "UNCERTAINTY_M"


@dataclass(frozen=True)
class GeoidGrid:
    path: Path
    undulation: np.ndarray  # (rows, cols) metres, NaN where no data
    sigma: np.ndarray | None  # (rows, cols) per-pixel 1 sigma, metres
    sigma_const: float | None  # one 1 sigma for the whole grid, metres
    inverse: tuple  # affine coefficients (a, b, c, d, e, f) of world -> pixel
    crs_wkt: str | None  # None: longitude/latitude degrees
    bounds: tuple[float, float, float, float]  # west, south, east, north in raster CRS
    global_lon: bool  # spans 360 degrees of longitude (wraps)
    name: str

    @property
    def label(self) -> str:
        return f"geoid grid {self.name}"

    def sample(self, x: ArrayLike, y: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Undulation N and its 1-sigma (0 when not stated) at raster-CRS coordinates x, y.

        Raises DatumError for points outside the grid or on no-data cells.
        """
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        if self.global_lon:
            x = (x - self.bounds[0]) % 360.0 + self.bounds[0]
        a, b, c, d, e, f = self.inverse
        col = a * x + b * y + c - 0.5
        row = d * x + e * y + f - 0.5
        rows, cols = self.undulation.shape
        if self.global_lon:
            col = np.where(col < 0, col + cols, col)
        n = _bilinear(self.undulation, row, col, wrap=self.global_lon)
        bad = ~np.isfinite(n)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            w, so, ee, nn = self.bounds
            raise DatumError(
                f"the point at {float(np.ravel(x)[i]):.6f}, {float(np.ravel(y)[i]):.6f} lies "
                f"outside the geoid grid {self.path} (it covers x {w:g}..{ee:g}, "
                f"y {so:g}..{nn:g}) or on a no-data cell"
            )
        if self.sigma is not None:
            s = _bilinear(self.sigma, row, col, wrap=self.global_lon)
            s = np.where(np.isfinite(s), s, 0.0)
        else:
            s = np.full_like(n, self.sigma_const or 0.0)
        return n, s


def _bilinear(grid: np.ndarray, row: np.ndarray, col: np.ndarray, wrap: bool) -> np.ndarray:
    """Bilinear interpolation between pixel centres; NaN outside [0, rows-1] x [0, cols-1]."""
    rows, cols = grid.shape
    r0 = np.floor(row)
    c0 = np.floor(col)
    fr = row - r0
    fc = col - c0
    r0 = r0.astype(np.int64)
    c0 = c0.astype(np.int64)
    # A point within half a pixel of the edge uses the edge value (clamp), as GDAL does.
    edge_r = (row >= -0.5) & (row <= rows - 0.5)
    r0c = np.clip(r0, 0, rows - 1)
    r1c = np.clip(r0 + 1, 0, rows - 1)
    if wrap:
        c0c = c0 % cols
        c1c = (c0 + 1) % cols
        inside = edge_r
    else:
        inside = edge_r & (col >= -0.5) & (col <= cols - 0.5)
        c0c = np.clip(c0, 0, cols - 1)
        c1c = np.clip(c0 + 1, 0, cols - 1)
    v = ((1 - fr) * (1 - fc) * grid[r0c, c0c] + (1 - fr) * fc * grid[r0c, c1c]
         + fr * (1 - fc) * grid[r1c, c0c] + fr * fc * grid[r1c, c1c])
    return np.where(inside, v, np.nan)


def load_geoid(path: str | os.PathLike) -> GeoidGrid:
    """Read a geoid raster (cached by path and modification time)."""
    p = Path(path).expanduser()
    try:
        st = p.stat()
    except OSError:
        raise InputError(f"geoid file {p}: no such file") from None
    return _load(str(p.resolve()), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=8)
def _load(path: str, mtime_ns: int, size: int) -> GeoidGrid:
    import rasterio
    from rasterio.errors import RasterioIOError

    try:
        ds = rasterio.open(path)
    except RasterioIOError as exc:
        raise InputError(f"geoid file {path}: not a raster GDAL can read ({exc})") from None
    with ds:
        und = ds.read(1, masked=True).astype(np.float64).filled(np.nan)
        sigma = None
        for i, desc in enumerate(ds.descriptions or (), start=1):
            if i > 1 and desc and desc.strip().lower().startswith(("uncertainty", "sigma")):
                sigma = ds.read(i, masked=True).astype(np.float64).filled(np.nan)
                break
        tag = ds.tags(1).get(UNCERTAINTY_TAG) or ds.tags().get(UNCERTAINTY_TAG)
        sigma_const = None
        if tag is not None:
            try:
                sigma_const = float(tag)
            except ValueError:
                raise InputError(
                    f"geoid file {path}: tag {UNCERTAINTY_TAG}={tag!r} is not a number of metres"
                ) from None
            if not np.isfinite(sigma_const) or sigma_const < 0:
                raise InputError(f"geoid file {path}: {UNCERTAINTY_TAG} must be >= 0 metres")
        inv = ~ds.transform
        crs_wkt = None
        if ds.crs is not None and not ds.crs.is_geographic:
            crs_wkt = ds.crs.to_wkt()
        b = ds.bounds
        geographic = crs_wkt is None
        span = b.right - b.left
        global_lon = geographic and abs(span - 360.0) < 1.5 * abs(ds.transform.a)
    if und.ndim != 2 or und.size == 0:
        raise InputError(f"geoid file {path}: band 1 is empty")
    return GeoidGrid(
        path=Path(path),
        undulation=und,
        sigma=sigma,
        sigma_const=sigma_const,
        inverse=(inv.a, inv.b, inv.c, inv.d, inv.e, inv.f),
        crs_wkt=crs_wkt,
        bounds=(b.left, b.bottom, b.right, b.top),
        global_lon=bool(global_lon),
        name=Path(path).name,
    )
