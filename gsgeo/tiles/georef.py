"""Georeferencing a 3DGS scene: from the file's frame to ECEF and to the tileset's root frame.

The root frame of every tileset gsgeo writes is the ENU frame (x east, y north, z up,
metres) at the scene centre; the root tile transform carries it to ECEF (EPSG:4978,
WGS 84). :class:`Georeference` describes how the input coordinates relate to the Earth;
:meth:`Georeference.placement` fixes the scene centre and returns a :class:`Placement` that
turns blocks of splats into the root frame (centres, orientations, sizes and SH).

Four ways to place a scene:

- ``origin``: the input frame is a local ENU frame at (lat, lon, h), optionally turned so
  that the input +y axis points at ``heading`` degrees clockwise from true north;
- ``crs``: input coordinates are projected-CRS coordinates minus ``offset`` (E, N, H);
  centres go exactly through pyproj; orientations turn by the grid convergence and sizes
  scale by 1/k, k the point scale factor;
- ``transform``: a 4x4 input-to-ECEF matrix (rotation and uniform scale, no shear);
- ``none``: like ``origin`` at :data:`DEFAULT_ORIGIN` (a warning says so).

Before any of these, ``axes`` turns scenes exported Y-up or in COLMAP's Y-down convention
into Z-up.
"""

from __future__ import annotations

import json
import math
import os
import warnings
from dataclasses import dataclass, field

import numpy as np
import pyproj
from pyproj.exceptions import CRSError as PyprojCRSError
from pyproj.exceptions import ProjError

from gsgeo.crs import frames as _frames
from gsgeo.crs.frames import ecef_to_geodetic, geodetic_to_ecef
from gsgeo.crs.transformers import accuracy_m, choose
from gsgeo.errors import CRSError, DatumError, InputError
from gsgeo.tiles.splats import Splats, matrix_to_quat, quat_multiply, rotation_angle, sh_rotation

#: Where a scene without georeference is put: latitude, longitude (degrees), ellipsoidal height (m).
DEFAULT_ORIGIN = (0.0, 0.0, 0.0)

#: Input axes -> Z-up (x east, y north, z up) for each axis convention.
AXES = {
    "z-up": np.eye(3),
    # glTF/three.js style: y up, -z forward; (x, y, z) -> (x, -z, y)
    "y-up": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    # COLMAP / OpenCV: y down, z forward; (x, y, z) -> (x, z, -y)
    "y-down": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
}

#: Below this angle (radians) SH coefficients are not turned: SPZ keeps them to 4-5 bits.
SH_ROTATION_MIN_ANGLE = 1e-4


def enu_rotation(lat_deg, lon_deg) -> np.ndarray:
    """Rotation (…, 3, 3) whose rows are east, north, up at (lat, lon): v_enu = R v_ecef."""
    return _frames.enu_rotation(lon_deg, lat_deg)


def rot_z(angle_deg: float | np.ndarray) -> np.ndarray:
    """Counter-clockwise rotation about z by angle (degrees), (…, 3, 3)."""
    a = np.radians(angle_deg)
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], axis=-2)


def enu_to_ecef_matrix(lat: float, lon: float, h: float) -> np.ndarray:
    """4x4 matrix taking ENU coordinates at (lat, lon, h) to ECEF (row-major numpy)."""
    m = np.eye(4)
    m[:3, :3] = enu_rotation(lat, lon).T
    m[:3, 3] = geodetic_to_ecef(lon, lat, h)
    return m


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


def _crs(text: str) -> pyproj.CRS:
    try:
        return pyproj.CRS.from_user_input(text)
    except PyprojCRSError as exc:
        raise CRSError(f"unknown CRS {text!r} ({exc})") from None


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
            c = _crs(self.crs)
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
                f"h {DEFAULT_ORIGIN[2]} m; measurements will not be on the Earth")
        else:
            raise InputError(f"unknown georeference kind {self.kind!r}")

    def describe(self) -> str:
        ax = {"z-up": "Z-up (ENU)", "y-up": "Y-up", "y-down": "Y-down (COLMAP)"}[self.axes]
        if self.kind in ("origin", "none"):
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
        lat, lon, h = self.origin
        r = enu_rotation(lat, lon).T @ rot_z(-self.heading) @ ax
        t = geodetic_to_ecef(lon, lat, h)
        return r, t, 1.0

    def placement(self, lo: np.ndarray, hi: np.ndarray) -> Placement:
        """Fix the scene centre from the input bounds (input coordinates) and return the
        Placement that carries blocks of splats into the root ENU frame there."""
        c_in = (np.asarray(lo, float) + np.asarray(hi, float)) / 2
        if self.kind == "crs":
            return _GridPlacement(self, c_in)
        a, t, s = self._rigid_to_ecef()
        c_ecef = a @ c_in + t
        return _RigidPlacement(self, c_ecef, a, t, s)


class Placement:
    """Maps blocks of input splats into the root ENU frame at the scene centre."""

    def __init__(self, georef: Georeference, centre_ecef: np.ndarray) -> None:
        self.georef = georef
        self.centre_ecef = np.asarray(centre_ecef, np.float64)
        lon, lat, h = ecef_to_geodetic(self.centre_ecef)
        self.centre_lonlath = (float(lon), float(lat), float(h))
        self.r_root = enu_rotation(float(lat), float(lon))   # ECEF -> root ENU
        self.operation = ""
        self.operation_accuracy_m: float | None = None

    @property
    def root_transform(self) -> np.ndarray:
        """4x4 root ENU -> ECEF (row-major numpy; the tileset stores it column-major)."""
        m = np.eye(4)
        m[:3, :3] = self.r_root.T
        m[:3, 3] = self.centre_ecef
        return m

    def apply(self, s: Splats) -> Splats:  # pragma: no cover - abstract
        raise NotImplementedError

    def _turn(self, s: Splats, rot: np.ndarray, log_scale: np.ndarray | float,
              positions: np.ndarray, sh_rot: np.ndarray) -> Splats:
        """Shared tail: turn orientations by rot ((3,3) or (N,3,3)), shift log sizes, turn SH."""
        q = matrix_to_quat(rot)
        if q.ndim == 1:
            # one turn for all: q * r is linear in r, a single (N, 4) x (4, 4) product
            rot_q = s.rotations @ quat_multiply(q, np.eye(4)).astype(np.float32)
        else:
            rot_q = quat_multiply(q.astype(np.float32), s.rotations)
        ls = np.asarray(log_scale, np.float32)
        scales = s.scales + ls.reshape(-1, 1) if ls.ndim or ls != 0 else s.scales
        sh = s.sh
        k = sh.shape[1]
        if k and rotation_angle(sh_rot) > SH_ROTATION_MIN_ANGLE:
            d = sh_rotation(sh_rot, k).astype(np.float32)
            sh = np.einsum("ij,njc->nic", d, sh, optimize=True)
        return Splats(positions, scales.astype(np.float32), rot_q.astype(np.float32),
                      s.opacities, s.colors, sh)


class _RigidPlacement(Placement):
    def __init__(self, georef, centre_ecef, a, t, s):
        super().__init__(georef, centre_ecef)
        self.lin = self.r_root @ a                     # input -> root, linear part
        self.off = self.r_root @ (t - self.centre_ecef)
        self.rot = self.lin / s
        self.log_scale = math.log(s)
        self.operation = georef.describe()
        self.operation_accuracy_m = 0.0

    def apply(self, s: Splats) -> Splats:
        pos = s.positions @ self.lin.T + self.off
        return self._turn(s, self.rot, self.log_scale, pos, self.rot)

    def to_ecef(self, p: np.ndarray) -> np.ndarray:
        """Input coordinates -> ECEF, for reporting."""
        return (p @ self.lin.T + self.off) @ self.r_root + self.centre_ecef


class _GridPlacement(Placement):
    """Projected-CRS input: exact pyproj path for centres, convergence and scale factor."""

    def __init__(self, georef: Georeference, c_in: np.ndarray) -> None:
        self.g = georef
        c = _crs(georef.crs)
        self.horiz = c.sub_crs_list[0] if c.is_compound else c
        self.geog = self.horiz.geodetic_crs
        try:
            self.inv = pyproj.Transformer.from_crs(self.horiz, self.geog, always_xy=True)
            # The same explicit operation the measurements take back to the grid
            # (gsgeo.crs.transformers.choose at the scene centre), so a point measured in the
            # tileset returns to the input's own grid coordinates.
            lon_c, lat_c = self.inv.transform(c_in[0] + georef.offset[0],
                                              c_in[1] + georef.offset[1], errcheck=False)
            self.to_ecef_t, _ = choose(self.geog.to_3d().to_wkt(), "EPSG:4978",
                                       float(lon_c), float(lat_c))
            self.proj = pyproj.Proj(self.horiz)
        except (ProjError, PyprojCRSError) as exc:
            raise CRSError(f"cannot build the transformation from {georef.crs}: {exc}") from None
        self.vert = None
        if georef.height == "vertical":
            comp = pyproj.CRS.from_user_input(
                {"$schema": "https://proj.org/schemas/v0.7/projjson.schema.json",
                 "type": "CompoundCRS", "name": "grid + vertical",
                 "components": [self.horiz.to_json_dict(),
                                _crs(georef.vertical_crs).to_json_dict()]})
            if not comp.sub_crs_list[1].is_vertical:
                raise CRSError(f"{georef.vertical_crs} is not a vertical CRS")
            try:
                self.vert = pyproj.Transformer.from_crs(comp, self.geog.to_3d(), always_xy=True,
                                                        allow_ballpark=False)
            except ProjError:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")   # the message below names the grid
                    grp = pyproj.transformer.TransformerGroup(comp, self.geog.to_3d(),
                                                              always_xy=True)
                why = "; ".join(str(w) for w in grp.unavailable_operations[:1]) or \
                    "no transformation without a geoid grid"
                raise DatumError(
                    f"heights in {georef.vertical_crs} need a geoid grid that is not "
                    f"installed ({why}); pass --geoid FILE.tif or --height ellipsoidal") from None
        elif georef.height == "geoid":
            path = os.path.abspath(georef.geoid)
            try:
                self.vert = pyproj.Transformer.from_pipeline(
                    "+proj=pipeline +step +proj=unitconvert +xy_in=deg +xy_out=rad "
                    f"+step +proj=vgridshift +grids={path} +multiplier=1 "
                    "+step +proj=unitconvert +xy_in=rad +xy_out=deg")
            except ProjError as exc:
                raise DatumError(f"cannot use geoid grid {georef.geoid}: {exc}") from None
        centre = self._ecef(c_in[None])[0][0]
        super().__init__(georef, centre)
        self.operation = georef.describe() + "; " + self.to_ecef_t.description
        acc = accuracy_m(self.to_ecef_t)
        self.operation_accuracy_m = acc
        if acc is None or acc > 0:
            georef.warnings.append(
                f"{self.geog.name} -> WGS 84 goes through '{self.to_ecef_t.description}' "
                f"(accuracy {'unknown' if acc is None else f'{acc:g} m'})")
        self.ax = AXES[georef.axes]
        # SH coefficients turn by the grid-to-root rotation at the scene centre (one turn for
        # all: across a tileset's +/-2 km it varies far less than SPZ's SH precision)
        _, lon_c, lat_c = self._ecef(c_in[None])
        conv_c = float(np.asarray(self.proj.get_factors(lon_c, lat_c, errcheck=False)
                                  .meridian_convergence, float)[0])
        self.sh_rot = self.r_root @ enu_rotation(lat_c[0], lon_c[0]).T @ rot_z(-conv_c) @ self.ax

    def _ecef(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Input (axes already Z-up) -> ECEF (N, 3), and geodetic lon, lat on the grid's datum."""
        e = p[:, 0] + self.g.offset[0]
        n = p[:, 1] + self.g.offset[1]
        hh = p[:, 2] + self.g.offset[2]
        lon, lat = self.inv.transform(e, n, errcheck=False)
        lon, lat = np.asarray(lon, float), np.asarray(lat, float)
        if self.g.height == "vertical":
            _, _, h = self.vert.transform(e, n, hh, errcheck=False)
        elif self.g.height == "geoid":
            _, _, h = self.vert.transform(lon, lat, hh, errcheck=False)
        else:
            h = hh
        h = np.asarray(h, float)
        x, y, z = self.to_ecef_t.transform(lon, lat, h, errcheck=False)
        out = np.stack([np.asarray(x, float), np.asarray(y, float), np.asarray(z, float)], -1)
        if not np.isfinite(out).all():
            bad = int((~np.isfinite(out).all(axis=1)).sum())
            raise CRSError(f"{bad} splat centre(s) fall outside the area where {self.g.crs}"
                           + (" or the geoid grid" if self.g.height != "ellipsoidal" else "")
                           + " can be transformed; check --crs and --offset")
        return out, lon, lat

    def apply(self, s: Splats) -> Splats:
        p_in = s.positions @ self.ax.T
        ecef, lon, lat = self._ecef(p_in)
        pos = (ecef - self.centre_ecef) @ self.r_root.T
        f = self.proj.get_factors(lon, lat, errcheck=False)
        conv = np.asarray(f.meridian_convergence, float)
        k = np.sqrt(np.asarray(f.areal_scale, float))
        # grid axes at the splat -> local ENU (turn by -convergence) -> ECEF -> root ENU
        rot = self.r_root @ np.swapaxes(enu_rotation(lat, lon), -1, -2) @ rot_z(-conv) @ self.ax
        return self._turn(s, rot, -np.log(k), pos, self.sh_rot)

    def to_ecef(self, p: np.ndarray) -> np.ndarray:
        return self._ecef(p @ self.ax.T)[0]
