"""Georeferencing a 3DGS scene: from the file's frame to ECEF and to the tileset's root frame.

The root frame of every tileset gsgeo writes is the ENU frame (x east, y north, z up,
metres) at the scene centre; the root tile transform carries it to ECEF (EPSG:4978,
WGS 84). :class:`Georeference` describes how the input coordinates relate to the Earth;
:meth:`Georeference.placement` fixes the scene centre and returns a placement
(:mod:`gsgeo.tiles.placement`) that turns blocks of splats into the root frame (centres,
orientations, sizes and SH).

Four ways to place a scene:

- ``origin``: the input frame is a local ENU frame at (lat, lon, h), optionally turned so
  that the input +y axis points at ``heading`` degrees clockwise from true north;
- ``crs``: input coordinates are projected-CRS coordinates minus ``offset`` (E, N, H);
  centres go exactly through pyproj; orientations turn by the grid convergence and sizes
  scale by 1/k, k the point scale factor (:mod:`gsgeo.tiles.gridplacement`, the only part
  that loads PROJ);
- ``transform``: a 4x4 input-to-ECEF matrix (rotation and uniform scale, no shear);
- ``none``: like ``origin`` at :data:`DEFAULT_ORIGIN` (a warning says so).

The rigid options (origin, transform, none) are WGS 84 ECEF by definition and need only the
ellipsoid formulas of :mod:`gsgeo.crs.ellipsoid` (PROJ's own, in closed form), so they run
without loading PROJ.

Before any of these, ``axes`` turns scenes exported Y-up or in COLMAP's Y-down convention
into Z-up.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from gsgeo.crs.ellipsoid import enu_rotation, geodetic_to_ecef_closed_form
from gsgeo.errors import CRSError, InputError
from gsgeo.limits import number_text
from gsgeo.tiles.placement import AXES, Placement, RigidPlacement, rot_z

#: Where a scene without georeference is put: latitude, longitude (degrees), ellipsoidal height (m).
DEFAULT_ORIGIN = (0.0, 0.0, 0.0)

def _three(value: str | Sequence[float], what: str) -> tuple[float, float, float]:
    """Three finite numbers from "a,b,c" text or a sequence; InputError naming `what`."""
    if isinstance(value, str):
        try:
            vals = tuple(number_text(v.strip(), what) for v in value.split(","))
        except InputError:
            raise InputError(f"{what} expects 3 comma-separated numbers (ASCII decimals), "
                             f"got {value!r}") from None
    else:
        try:
            vals = tuple(float(v) for v in value)
        except (TypeError, ValueError):
            raise InputError(f"{what} expects 3 numbers, got {value!r}") from None
    if len(vals) != 3 or not all(math.isfinite(v) for v in vals):
        raise InputError(f"{what} expects 3 comma-separated finite numbers, got {value!r}")
    return vals


def load_matrix(path: str | os.PathLike) -> np.ndarray:
    """Read a 4x4 local-to-ECEF matrix from JSON: 16 numbers column-major (3D Tiles order),
    or 4 rows of 4, or {"matrix": ...} holding either."""
    try:
        with open(path, encoding="utf-8") as f:
            obj = json.load(f)
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    except json.JSONDecodeError as exc:
        raise InputError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
    if isinstance(obj, dict):
        obj = obj.get("matrix", obj.get("transform"))
    try:
        a = np.asarray(obj, dtype=np.float64)
    except (TypeError, ValueError):
        raise InputError(f"{path}: the matrix must be numbers") from None
    if a.shape == (16,):
        m = a.reshape(4, 4).T  # column-major
    elif a.shape == (4, 4):
        m = a
    else:
        raise InputError(f"{path}: expected 16 numbers (column-major) or 4 rows of 4, "
                         f"got shape {a.shape}")
    if not np.isfinite(m).all():
        raise InputError(f"{path}: the matrix has non-finite values")
    if not np.allclose(m[3], [0, 0, 0, 1]):
        raise InputError(f"{path}: the last row must be 0 0 0 1 (an affine transform)")
    return m


def _similarity(m3: np.ndarray, what: str) -> tuple[np.ndarray, float]:
    """Split a 3x3 matrix into rotation and uniform scale; reject shear/mirror."""
    s = np.cbrt(np.linalg.det(m3))
    if not s > 0:
        raise InputError(f"{what}: the matrix mirrors or collapses space (determinant <= 0)")
    r = m3 / s
    if not np.allclose(r @ r.T, np.eye(3), atol=1e-6):
        raise InputError(f"{what}: the matrix is not a rotation with a uniform scale "
                         "(splats cannot be sheared)")
    u, _, vt = np.linalg.svd(r)
    return u @ vt, float(s)


@dataclass
class Georeference:
    """How the input coordinates sit on the Earth (see the module docstring)."""
    kind: str = "none"                       # origin | crs | transform | none
    origin: tuple[float, float, float] | None = None   # lat, lon (deg), h (m)
    heading: float = 0.0                     # degrees clockwise from true north
    crs: str | None = None
    offset: tuple[float, float, float] = (0.0, 0.0, 0.0)
    height: str = "ellipsoidal"              # ellipsoidal | vertical | geoid
    vertical_crs: str | None = None
    geoid: str | None = None
    matrix: np.ndarray | None = None         # 4x4 input -> ECEF (row-major numpy)
    axes: str = "z-up"
    warnings: list[str] = field(default_factory=list)

    @classmethod
    def from_options(cls, *, origin: str | Sequence[float] | None = None, heading: float = 0.0,
                     crs: str | None = None, offset: str | Sequence[float] | None = None,
                     transform: str | os.PathLike | np.ndarray | None = None,
                     height: str | None = None, vertical: str | None = None,
                     geoid: str | None = None, axes: str = "z-up") -> Georeference:
        """The georeference of `gsgeo tiles`'s options, checked as the command checks them.

        origin "LAT,LON,H" (degrees, metres; text or 3 numbers) with heading (degrees clockwise
        from true north of the input +y axis); or crs with offset "E,N,H" (grid units) and at
        most one of height "ellipsoidal", vertical (a vertical CRS) or geoid (a geoid grid
        file); or transform (a JSON file of a 4x4 local-to-ECEF matrix, or the matrix).
        Nothing: the default origin, with a warning. Messages name the command's options.
        """
        chosen = [n for n, v in (("--origin", origin), ("--crs", crs), ("--transform", transform))
                  if v is not None and not (isinstance(v, str) and not v)]
        if len(chosen) > 1:
            raise InputError(f"choose one georeference: {' and '.join(chosen)} were both given")
        if heading and not origin:
            raise InputError("--heading needs --origin")
        if (offset or vertical or geoid or height) and not crs:
            raise InputError("--offset, --height, --vertical and --geoid need --crs")
        if origin:
            return cls("origin", origin=_three(origin, "--origin"), heading=heading, axes=axes)
        if crs:
            if offset is None:
                raise InputError("--crs needs --offset E,N,H (use 0,0,0 when the PLY holds full "
                                 "grid coordinates)")
            kind = "vertical" if vertical else "geoid" if geoid else "ellipsoidal"
            g = cls("crs", crs=crs, offset=_three(offset, "--offset"), height=kind,
                    vertical_crs=vertical, geoid=geoid, axes=axes)
            # a compound --crs switches to its vertical part; a 2-D one assumes ellipsoidal
            if g.height == "ellipsoidal" and not height:
                g.warnings.append("heights taken as ellipsoidal (no --vertical or --geoid "
                                  "given); pass --height ellipsoidal to silence this")
            return g
        if transform is not None:
            m = transform if isinstance(transform, np.ndarray) else load_matrix(transform)
            return cls("transform", matrix=m, axes=axes)
        return cls("none", axes=axes)

    def __post_init__(self) -> None:
        if self.axes not in AXES:
            raise InputError(f"unknown axis convention {self.axes!r}; use one of {', '.join(AXES)}")
        if self.kind == "origin":
            if self.origin is None:
                raise InputError("origin georeference needs LAT,LON,H")
            lat, lon, h = self.origin
            if not (-90 <= lat <= 90 and -180 <= lon <= 360 and math.isfinite(h)):
                raise InputError(f"--origin {lat},{lon},{h}: latitude must be in [-90, 90], "
                                 "longitude in [-180, 360], height finite")
        elif self.kind == "crs":
            if self.crs is None:
                raise InputError("--crs is required with --offset")
            from gsgeo.crs.resolve import parse_crs
            c = parse_crs(self.crs)
            horiz = c.sub_crs_list[0] if c.is_compound else c
            if not horiz.is_projected:
                raise CRSError(f"{self.crs} is not a projected CRS; --crs expects grid "
                               "coordinates (E, N) such as a UTM zone or a national grid")
            if self.height not in ("ellipsoidal", "vertical", "geoid"):
                raise InputError(f"unknown height kind {self.height!r}")
            if self.height == "geoid" and not (self.geoid and os.path.isfile(self.geoid)):
                raise InputError(f"geoid grid {self.geoid!r} not found")
            if c.is_compound and self.height == "ellipsoidal":
                self.height, self.vertical_crs = "vertical", c.sub_crs_list[1].to_string()
        elif self.kind == "transform":
            if self.matrix is None or np.asarray(self.matrix).shape != (4, 4):
                raise InputError("transform georeference needs a 4x4 matrix")
        elif self.kind == "none":
            self.origin = DEFAULT_ORIGIN
            self.warnings.append(
                "no georeference given: the scene is placed as a local ENU frame at the "
                f"default origin lat {DEFAULT_ORIGIN[0]}, lon {DEFAULT_ORIGIN[1]}, "
                f"h {DEFAULT_ORIGIN[2]} m; measurements will not be on the Earth (nor in metres "
                "if the scene's scale is arbitrary). Georeference it next: measure control "
                "points in the viewer's Georeference panel or run `gsgeo georef --project PID "
                "--apply`; `gsgeo georef --scale-only` fixes the scale alone")
        else:
            raise InputError(f"unknown georeference kind {self.kind!r}")

    def describe(self) -> str:
        ax = {"z-up": "Z-up (ENU)", "y-up": "Y-up", "y-down": "Y-down (COLMAP)"}[self.axes]
        if self.kind in ("origin", "none"):
            assert self.origin is not None  # set for these kinds
            lat, lon, h = self.origin
            d = (f"local ENU at lat {lat:.8f}, lon {lon:.8f}, h {h:.3f} m"
                 + (f", heading {self.heading:g} deg" if self.heading else ""))
            if self.kind == "none":
                d += " (default origin: no georeference)"
        elif self.kind == "crs":
            hv = {"ellipsoidal": "ellipsoidal heights",
                  "vertical": f"heights in {self.vertical_crs}",
                  "geoid": f"orthometric heights with geoid {self.geoid}"}[self.height]
            d = f"{self.crs} grid coordinates minus offset {tuple(self.offset)}, {hv}"
        else:
            d = "4x4 local-to-ECEF matrix"
        return f"{d}; input axes {ax}"

    # --- the rigid part -----------------------------------------------------------------
    def _rigid_to_ecef(self) -> tuple[np.ndarray, np.ndarray, float]:
        """(A, t, s): ECEF = A p + t for input p (after the axis turn), A = s R."""
        ax = AXES[self.axes]
        if self.kind == "transform":
            m = np.asarray(self.matrix, np.float64)
            r, s = _similarity(m[:3, :3] @ ax.T, "--transform")
            return m[:3, :3] @ ax.T, m[:3, 3], s
        assert self.origin is not None  # set for every kind but "transform"
        lat, lon, h = self.origin
        r = enu_rotation(lon, lat).T @ rot_z(-self.heading) @ ax
        t = geodetic_to_ecef_closed_form(lon, lat, h)
        return r, t, 1.0

    def placement(self, lo: np.ndarray, hi: np.ndarray) -> Placement:
        """Fix the scene centre from the input bounds (input coordinates) and return the
        Placement that carries blocks of splats into the root ENU frame there."""
        c_in = (np.asarray(lo, float) + np.asarray(hi, float)) / 2
        if self.kind == "crs":
            from gsgeo.tiles.gridplacement import GridPlacement
            return GridPlacement(self, c_in)
        a, t, s = self._rigid_to_ecef()
        c_ecef = a @ c_in + t
        return RigidPlacement(self, c_ecef, a, t, s)
