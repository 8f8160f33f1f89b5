"""Grid coordinates (easting, northing, height) with covariance, from ECEF points.

Path of a point (docs/architecture.md, "PROJ"):

1. ECEF on the scene's geocentric CRS (``source_crs``) -> longitude, latitude and
   ellipsoidal height h on the same datum (a conversion).
2. E, N from the **horizontal** path: the source geographic 3D CRS -> the projected CRS alone, the
   best PROJ operation whose area of use holds the points; its name and accuracy are
   recorded. (A compound target may pick a different, even ballpark, horizontal operation.)
3. Height:

   - default: h, ellipsoidal, on the source CRS's datum and ellipsoid (WGS 84 for EPSG:4978,
     GRS 1980 for ETRS89 / NAD83(2011) / GDA2020). No datum change is applied to heights.
   - ``vertical`` (a vertical CRS such as EPSG:5701): H from PROJ's transformation to the
     compound CRS, only when an operation with a real geoid model is available. PROJ's
     "ballpark" vertical transformation (H = h, silently) is refused with a DatumError that
     names the missing grid and the two ways to supply it.
   - ``geoid`` (a raster of undulations N, see gsgeo.crs.geoid): H = h - N, bilinear, with N
     on the same ellipsoid as h; the geoid's stated uncertainty adds to sigma_h.

4. Covariance Sigma_grid = J Sigma_ecef J^T with J = d(E, N, H)/d(X, Y, Z): the E, N rows are
   forward differences through the same cached transformer in longitude, latitude and h,
   chained with the closed-form d(lon, lat, h)/d(X, Y, Z) (radii of curvature); the H row is
   the local up vector (geoid slope, ~1e-5, neglected). Sigmas and covariances are in
   metres and m^2 even where the CRS's unit is the foot; E, N, H are in the CRS's units.

The operation's accuracy (1-3 m from WGS 84, an ensemble) is a systematic offset shared by the
whole scene; it is recorded, warned about, and not added to the covariance.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike
from pyproj.exceptions import ProjError

from gsgeo.crs.confidence import ellipse_95, ellipsoid_axes_95
from gsgeo.crs.ellipsoid import WGS84_A, WGS84_F
from gsgeo.crs.frames import ecef_to_geodetic, enu_rotation, geodetic_jacobian
from gsgeo.crs.geoid import load_geoid
from gsgeo.crs.resolve import GridCRS, SourceCRS, grid_crs, source_crs
from gsgeo.crs.transformers import (
    Candidates,
    accuracy_m,
    candidates,
    choose,
    in_area,
    is_ballpark,
    projection,
    transform_xy,
    transformer,
)
from gsgeo.errors import CRSError, DatumError, InputError

if TYPE_CHECKING:
    from pyproj import Transformer

#: Step of the differences in longitude and latitude, degrees (~0.1 m on the ground: small
#: against the curvature, large against float rounding of 1e6 m coordinates).
JACOBIAN_STEP_DEG = 1e-6
#: Step in ellipsoidal height, metres (h enters 3-D Helmert steps of datum transformations).
JACOBIAN_STEP_H = 1.0
#: Operation accuracy (m) above which a result carries a warning.
ACCURACY_WARNING_M = 0.1


@dataclass
class GridPoints:
    """Many points in a grid CRS (arrays over M points). See `to_grid_many`."""

    easting: np.ndarray
    northing: np.ndarray
    height: np.ndarray
    covariance: np.ndarray | None  # (M, 3, 3) in (E, N, H), m^2
    crs: str
    height_type: str  # 'ellipsoidal' | 'orthometric'
    vertical_datum: str
    operation: str
    operation_accuracy_m: float | None  # None: unknown (ballpark)
    lon: np.ndarray  # WGS 84, degrees
    lat: np.ndarray
    h_wgs84: np.ndarray  # WGS 84 ellipsoidal height, m
    h_ellipsoidal: np.ndarray  # on the source CRS's ellipsoid, m
    jacobian: np.ndarray  # (M, 3, 3) d(E, N, H)/d(X, Y, Z) in metres per metre
    warnings: list[str] = field(default_factory=list)

    def __len__(self) -> int:
        return int(self.easting.shape[0])

    @property
    def sigmas(self) -> np.ndarray:
        assert self.covariance is not None, "no covariance"
        return np.sqrt(np.einsum("mii->mi", self.covariance))

    def point(self, i: int) -> GridPoint:
        """The i-th point as a GridPoint."""
        cov = None if self.covariance is None else self.covariance[i]
        return GridPoint.build(
            float(self.easting[i]), float(self.northing[i]), float(self.height[i]), cov,
            self.crs, self.height_type, self.vertical_datum, self.operation,
            self.operation_accuracy_m, float(self.lon[i]), float(self.lat[i]),
            float(self.h_wgs84[i]), float(self.h_ellipsoidal[i]), list(self.warnings),
        )


@dataclass
class GridPoint:
    """One point in a grid CRS: coordinates in the CRS's units, covariance in m^2 (E, N, H)."""

    easting: float
    northing: float
    height: float
    covariance: np.ndarray | None
    crs: str
    height_type: str
    vertical_datum: str
    operation: str
    operation_accuracy_m: float | None
    lon: float
    lat: float
    h_wgs84: float
    h_ellipsoidal: float
    sigma_e: float | None
    sigma_n: float | None
    sigma_h: float | None
    ellipse_major_95: float | None
    ellipse_minor_95: float | None
    ellipse_bearing_deg: float | None
    ellipsoid_axes_95: np.ndarray | None  # (3, 3) rows: semi-axis vectors in E, N, H, m
    warnings: list[str] = field(default_factory=list)

    @classmethod
    def build(cls, e: float, n: float, h: float, cov: np.ndarray | None, crs: str,
              height_type: str, vdatum: str, op: str, acc: float | None, lon: float,
              lat: float, hw: float, he: float, warnings: list[str]) -> GridPoint:
        if cov is None:
            s: tuple[float | None, float | None, float | None] = (None, None, None)
            ell: tuple[float | None, float | None, float | None] = (None, None, None)
            axes = None
        else:
            s0, s1, s2 = (float(math.sqrt(max(cov[i, i], 0.0))) for i in range(3))
            s = (s0, s1, s2)
            a, b, t = ellipse_95(cov[:2, :2])
            ell = (float(a), float(b), float(t))
            axes = ellipsoid_axes_95(cov)
        return cls(e, n, h, cov, crs, height_type, vdatum, op, acc, lon, lat, hw, he,
                   *s, *ell, axes, warnings)

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        out = {}
        for k, v in self.__dict__.items():
            out[k] = v.tolist() if isinstance(v, np.ndarray) else v
        return out


def to_grid(point_ecef: ArrayLike, cov_ecef: ArrayLike | None, crs: str, *, vertical: str | None = None,
            geoid: str | Path | None = None, source_crs: str = "EPSG:4978") -> GridPoint:
    """One ECEF point (3,) and its covariance (3, 3) (m, m^2) into a grid CRS.

    Parameters
    ----------
    point_ecef : (3,) on the geocentric ``source_crs`` (the scene's realisation), metres.
    cov_ecef : (3, 3) m^2 in the same frame, or None.
    crs : projected CRS ("EPSG:27700"); a compound CRS brings its vertical part.
    vertical : vertical CRS ("EPSG:5701") needing its geoid grid in PROJ's data directory.
    geoid : a geoid raster file instead (undulation N on the source ellipsoid, metres).
    source_crs : geocentric CRS of the scene, EPSG:4978 (WGS 84) by default.

    Returns a GridPoint; raises CRSError / DatumError / InputError with a clear message.
    """
    p = np.asarray(point_ecef, dtype=np.float64).reshape(1, 3)
    c = None if cov_ecef is None else np.asarray(cov_ecef, dtype=np.float64).reshape(1, 3, 3)
    return to_grid_many(p, c, crs, vertical=vertical, geoid=geoid, source_crs=source_crs).point(0)


def to_grid_many(points_ecef: ArrayLike, cov_ecef: ArrayLike | None, crs: str, *, vertical: str | None = None,
                 geoid: str | Path | None = None, source_crs: str = "EPSG:4978") -> GridPoints:
    """`to_grid` for M points at once: points (M, 3), covariances (M, 3, 3) or None.

    One operation is chosen for the whole set (at the points' centroid), so keep a call to
    one scene. Vectorised: a handful of PROJ calls on whole arrays, no loop over points.
    """
    pts = np.asarray(points_ecef, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] == 0:
        raise InputError(f"points must be an M x 3 array of ECEF metres (got shape {pts.shape})")
    if not np.all(np.isfinite(pts)):
        raise InputError("points contain NaN or infinite coordinates")
    cov = None
    if cov_ecef is not None:
        cov = np.asarray(cov_ecef, dtype=np.float64)
        if cov.shape != (pts.shape[0], 3, 3):
            raise InputError(f"covariances must be M x 3 x 3 (got shape {cov.shape})")
    if vertical is not None and geoid is not None:
        raise InputError("give either a vertical CRS (--vertical) or a geoid file (--geoid), not both")
    src = _source(source_crs)
    g = grid_crs(crs, vertical)
    if geoid is not None and g.vertical is not None:
        raise InputError(f"'{crs}' is a compound CRS with a vertical datum; do not also give a geoid file")
    warnings: list[str] = []

    lon, lat, h = ecef_to_geodetic(pts, src.id)
    lon0, lat0 = _centroid(lon, lat)

    # 1. E, N from the horizontal path: source geographic 3D (h feeds 3-D Helmert steps)
    #    -> the projected CRS alone, never the compound.
    g3 = src.geographic_3d_id
    t2, inside_op = choose(g3, g.id, lon0, lat0)
    e, n = _en(t2, lon, lat, h)
    if not (np.all(np.isfinite(e)) and np.all(np.isfinite(n))):
        raise CRSError(f"PROJ could not project the point(s) into {g.id} ({g.horizontal.name})")
    op = t2.description
    acc = accuracy_m(t2)
    _area_warnings(warnings, g, t2, lon, lat, inside_op)

    # 2. Jacobian of E, N w.r.t. longitude, latitude (per radian) and h (per metre), by
    #    forward differences through the same transformer. Truncation error is step x
    #    curvature (~1e-8 relative for 0.1 m steps), rounding ~1e-9: central differences would
    #    cost three more PROJ calls for nothing visible in a covariance.
    d = JACOBIAN_STEP_DEG
    per_rad = 180.0 / math.pi / d * g.unit_factor  # metres per radian
    per_m = g.unit_factor / JACOBIAN_STEP_H
    j_llh = np.empty((pts.shape[0], 2, 3))
    steps = ((d, 0, 0, per_rad), (0, d, 0, per_rad), (0, 0, JACOBIAN_STEP_H, per_m))
    for col, (dl, dp, dh, scale) in enumerate(steps):
        ep, np_ = _en(t2, lon + dl, lat + dp, h + dh)
        j_llh[:, 0, col] = (ep - e) * scale
        j_llh[:, 1, col] = (np_ - n) * scale
    jac = full_jacobian(j_llh, lon, lat, h, src.a, src.f)

    # 3. Heights.
    height, height_type, vdatum, v_var, v_op, v_acc = _heights(src, g, lon, lat, h, geoid, crs)
    if v_op:
        op = f"{op} | vertical: {v_op}"
        acc = None if (acc is None or v_acc is None) else max(acc, v_acc)
    out_crs = g.id if g.vertical_id is None else _compound_id(g)

    cov_grid = None
    if cov is not None:
        cov_grid = jac @ cov @ np.swapaxes(jac, -1, -2)
        if v_var is not None:
            cov_grid[:, 2, 2] += v_var

    # 4. WGS 84 longitude, latitude, height for GeoJSON.
    if src.is_wgs84:
        lon84, lat84, h84 = lon, lat, h
    else:
        t84 = transformer(src.id, "EPSG:4979")
        lon84, lat84, h84 = (np.asarray(v) for v in t84.transform(
            pts[:, 0], pts[:, 1], pts[:, 2], errcheck=False))

    if acc is None:
        warnings.append(
            f"the operation to {g.id} has unknown accuracy ({op}); PROJ has no real datum "
            f"transformation from {src.id} here, so the coordinates may be off by metres"
        )
    elif acc > ACCURACY_WARNING_M:
        hint = ""
        if src.is_wgs84:
            hint = (" WGS 84 is a datum ensemble; if the scene is really georeferenced in the "
                    "national realisation (ETRS89, NAD83(2011), GDA2020, ...), declare it with "
                    "--source-crs (e.g. EPSG:4936) for a pure conversion")
        warnings.append(
            f"{src.id} -> {g.id} goes through '{t2.description}', accurate to {acc:g} m only: "
            f"every coordinate shares this offset.{hint}"
        )
    return GridPoints(
        easting=e, northing=n, height=height, covariance=cov_grid, crs=out_crs,
        height_type=height_type, vertical_datum=vdatum, operation=op,
        operation_accuracy_m=acc, lon=np.asarray(lon84, dtype=float),
        lat=np.asarray(lat84, dtype=float), h_wgs84=np.asarray(h84, dtype=float),
        h_ellipsoidal=h, jacobian=jac, warnings=warnings,
    )


def full_jacobian(j_llh: np.ndarray, lon: ArrayLike, lat: ArrayLike, h: np.ndarray | float, a: float,
                  f: float) -> np.ndarray:
    """d(E, N, h)/d(X, Y, Z) (M, 3, 3), metres per metre.

    j_llh: d(E, N)/d(lon, lat, h) (M, 2, 3), metres per radian and per metre; chained with
    the closed-form d(lon, lat, h)/d(X, Y, Z) of the ellipsoid (a, f).
    """
    r = enu_rotation(lon, lat)
    k_lon, k_lat = geodetic_jacobian(lat, h, a, f)
    a_llh = np.stack([r[:, 0, :] * k_lon[:, None], r[:, 1, :] * k_lat[:, None], r[:, 2, :]],
                     axis=1)
    jac = np.empty((j_llh.shape[0], 3, 3))
    jac[:, :2, :] = j_llh @ a_llh
    jac[:, 2, :] = r[:, 2, :]
    return jac


def analytic_jacobian(points_ecef: ArrayLike, crs: str, source_crs: str = "EPSG:4978") -> np.ndarray:
    """d(E, N, h)/d(X, Y, Z) from the projection's point scale factor and meridian convergence.

    Where meridians and parallels stay perpendicular on the map (conformal projections, and
    conics such as Albers), d(E, N) = R(gamma) diag(k_parallel, k_meridian) d(e, n) with the
    scale factors and the meridian convergence gamma from pyproj's ``get_factors``, evaluated
    on the source datum's longitude and latitude (a datum shift of ~100 m changes k by ~1e-9).
    A datum transformation's own scale and rotation (a few 1e-5 for a Helmert) are not in it.
    Independent of the numerical path in `to_grid`; the tests use it to check that path.
    """
    src = _source(source_crs)
    g = grid_crs(crs)
    pts = np.asarray(points_ecef, dtype=np.float64).reshape(-1, 3)
    lon, lat, h = ecef_to_geodetic(pts, src.id)
    fac = projection(g.horizontal).get_factors(lon, lat, errcheck=True)
    k = np.asarray(fac.meridional_scale)  # = parallel scale for a conformal projection
    kp = np.asarray(fac.parallel_scale)
    gam = np.radians(np.asarray(fac.meridian_convergence))
    # PROJ's convergence: a true-north step dn maps to (E, N) = k dn (-sin gamma, cos gamma).
    r = enu_rotation(lon, lat)
    jac = np.empty((pts.shape[0], 3, 3))
    c, s = np.cos(gam), np.sin(gam)
    m2 = np.empty((pts.shape[0], 2, 2))
    m2[:, 0, 0] = kp * c
    m2[:, 0, 1] = -k * s
    m2[:, 1, 0] = kp * s
    m2[:, 1, 1] = k * c
    # The ellipsoid scale (N + h)/N, (M + h)/M: a step of 1 m at height h is 1 m * R/(R+h)
    # on the ellipsoid.
    k_lon, k_lat = geodetic_jacobian(lat, h, src.a, src.f)
    k_lon0, k_lat0 = geodetic_jacobian(lat, 0.0, src.a, src.f)
    sc = np.stack([k_lon / k_lon0, k_lat / k_lat0], axis=-1)
    jac[:, :2, :] = (m2 * sc[:, None, :]) @ r[:, :2, :]
    jac[:, 2, :] = r[:, 2, :]
    return jac


def datum_text(src: SourceCRS) -> str:
    """The source's geographic 3-D CRS as "WGS 84 (EPSG:4979)": its name and id, and its
    ellipsoid only where the name does not already say it ("ETRS89 (EPSG:4937, ellipsoid
    GRS 1980)")."""
    crs = src.geographic_3d
    ell = crs.ellipsoid.name if crs.ellipsoid else None
    extra = f", ellipsoid {ell}" if ell and ell.casefold() not in crs.name.casefold() else ""
    return f"{crs.name} ({src.geographic_3d_id}{extra})"


def _heights(src: SourceCRS, g: GridCRS, lon: np.ndarray, lat: np.ndarray, h: np.ndarray,
             geoid: str | Path | None, crs_text: str
             ) -> tuple[np.ndarray, str, str, np.ndarray | None, str | None, float | None]:
    """(height, height_type, vertical_datum, extra variance, vertical op, its accuracy)."""
    if g.vertical is None and geoid is None:
        return h, "ellipsoidal", f"ellipsoidal height on {datum_text(src)}", None, None, None
    if geoid is not None:
        grid = load_geoid(geoid)
        x, y = lon, lat
        if grid.crs_wkt is not None:
            t = transformer(src.geographic_2d_id, grid.crs_wkt)
            x, y = transform_xy(t, lon, lat)
        und, sig = grid.sample(x, y)
        stated = grid.sigma is not None or grid.sigma_const is not None
        label = (f"{grid.label} (H = h - N, h on {datum_text(src)}"
                 f"{'' if stated else '; no stated uncertainty'})")
        return h - und, "orthometric", label, sig**2, None, None
    # A vertical CRS through PROJ: refuse the ballpark H = h.
    comp = _compound_id(g)
    src3 = src.geographic_3d_id
    cands = candidates(src3, comp)
    lon0, lat0 = _centroid(lon, lat)
    real = [t for t in cands.available if "ballpark vertical" not in t.description.lower()]
    inside = [t for t in real if in_area(t, lon0, lat0)]
    if not inside:
        raise DatumError(_missing_grid_message(g, cands, comp))
    # Prefer one without any ballpark step (horizontal ballpark moves lon/lat by ~100 m,
    # which changes a geoid value by millimetres; E, N never come from here).
    inside.sort(key=lambda t: is_ballpark(t.description))
    t = inside[0]
    _, _, hh = t.transform(lon, lat, h, errcheck=False)
    hh = np.asarray(hh, dtype=np.float64)
    assert g.vertical is not None  # the geoid-less compound path
    if not np.all(np.isfinite(hh)) or np.any(np.abs(hh) > 1e30):
        raise DatumError(
            f"PROJ could not compute {g.vertical.name} heights here (outside its geoid grid?)"
        )
    return (hh, "orthometric", f"{g.vertical.name} ({g.vertical_id})", None,
            t.description, accuracy_m(t))


def _missing_grid_message(g: GridCRS, cands: Candidates, comp: str) -> str:
    missing: list[list[str]] = []
    for op in cands.unavailable:
        if "ballpark vertical" in op.name.lower():
            continue
        names = [gr.short_name for gr in op.grids if not gr.available]
        if names:
            missing.append(names)
    missing.sort(key=len)
    if missing:
        first = missing[0]
        others = sorted({n for m in missing for n in m} - set(first))
        grids = " and ".join(first)
        extra = f" (better operations also use {', '.join(others)})" if others else ""
        what = f"the geoid grid {grids}{extra}"
    else:
        what = "a geoid grid PROJ does not know of"
        grids = "the geoid grid"
    assert g.vertical is not None  # called for a compound target only
    return (
        f"{g.vertical.name} ({g.vertical_id}) heights need {what}, which is not installed; "
        "PROJ would silently return the ellipsoidal height as H (a 'ballpark' transformation), "
        "so gsgeo refuses. Supply the grid either (1) by putting the file into a PROJ data "
        "directory (PROJ_DATA, e.g. `projsync --file NAME` or copying it from cdn.proj.org on "
        f"another machine), or (2) by giving the geoid as a raster with --geoid FILE.tif "
        "(undulation in metres). Without either, leave out --vertical for ellipsoidal heights."
    ).replace("`projsync --file NAME`", f"`projsync --file {grids.split(' and ')[0]}`")


def _area_warnings(warnings: list[str], g: GridCRS, t2: Transformer, lon: np.ndarray,
                   lat: np.ndarray, inside_op: bool) -> None:
    a = g.horizontal.area_of_use
    if a is not None:
        w, s, e, n = a.west, a.south, a.east, a.north
        lon_ok = (lon >= w) & (lon <= e) if w <= e else (lon >= w) | (lon <= e)
        out = ~(lon_ok & (lat >= s) & (lat <= n))
        if out.any():
            who = "the point lies" if out.size == 1 else f"{int(out.sum())} of {out.size} points lie"
            area = a.name if len(a.name) <= 60 else a.name[:57] + "..."
            warnings.append(
                f"{who} outside the area of use of {g.id} ({g.horizontal.name}: {area}; "
                f"lon {w:g}..{e:g}, lat {s:g}..{n:g}); distortion and datum errors may be large"
            )
    if not inside_op:
        warnings.append(
            f"no transformation to {g.id} covers this location; used '{t2.description}' "
            "outside its area of use"
        )


def _en(t: Transformer, lon: np.ndarray, lat: np.ndarray, h: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    x, y, _ = t.transform(lon, lat, h, errcheck=False)
    return np.asarray(x, dtype=np.float64), np.asarray(y, dtype=np.float64)


def _centroid(lon: np.ndarray, lat: np.ndarray) -> tuple[float, float]:
    # Points of a call belong to one scene; the mean is a fine representative.
    return float(np.mean(lon)), float(np.mean(lat))


def _compound_id(g: GridCRS) -> str:
    a, b = g.id, g.vertical_id or ""
    if a.startswith("EPSG:") and b.startswith("EPSG:"):
        return f"{a}+{b.split(':')[1]}"
    from pyproj.crs import CompoundCRS

    assert g.vertical is not None  # called for a compound target only
    return CompoundCRS(f"{g.horizontal.name} + {g.vertical.name}",
                       [g.horizontal, g.vertical]).to_wkt()


def _source(text: str) -> SourceCRS:
    return source_crs(text or "EPSG:4978")


@dataclass(frozen=True)
class ScaleFactors:
    """Scale between grid and ground at points (arrays of N): ``point`` the projection's point
    scale factor k (from PROJ's ``get_factors``: the square root of the areal scale, which is
    k in every direction for a conformal projection and an average over directions for
    others), ``elevation`` R / (R + h) with R the Gaussian mean
    radius sqrt(M N) of the WGS 84 ellipsoid at the latitude and h the ellipsoidal height (m),
    ``combined`` their product. A ground distance is the grid distance divided by ``combined``;
    a ground area the grid area divided by its square."""

    point: np.ndarray
    elevation: np.ndarray
    combined: np.ndarray


def scale_factors(lon: ArrayLike, lat: ArrayLike, h: ArrayLike, crs: str) -> ScaleFactors:
    """Grid-to-ground scale factors of projected CRS ``crs`` at WGS 84 longitudes, latitudes
    (degrees) and ellipsoidal heights (m). The datum's own shift (metres) changes k by about
    1e-9, below anything a survey reads."""
    g = grid_crs(crs)
    lon_a, lat_a, h_a = (np.atleast_1d(np.asarray(v, dtype=np.float64)) for v in (lon, lat, h))
    proj = projection(g.horizontal)
    try:
        fac = proj.get_factors(lon_a, lat_a, errcheck=True)
    except ProjError as exc:
        raise CRSError(f"{crs}: no scale factors at these points ({exc})") from exc
    # the square root of the areal scale: k itself where the projection is conformal (areal =
    # k squared), an average over directions where it is not
    k = np.sqrt(np.asarray(fac.areal_scale, dtype=np.float64))
    e2 = WGS84_F * (2.0 - WGS84_F)
    s2 = np.sin(np.radians(lat_a)) ** 2
    radius = WGS84_A * np.sqrt(1.0 - e2) / (1.0 - e2 * s2)  # sqrt(M N)
    elev = radius / (radius + h_a)
    return ScaleFactors(point=k, elevation=elev, combined=k * elev)
