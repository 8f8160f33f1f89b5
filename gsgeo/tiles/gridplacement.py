"""Placement of scenes whose coordinates are projected-CRS (grid) coordinates, through PROJ.

Loaded only for ``gsgeo tiles --crs``: the other georeference options need no PROJ (see
:mod:`gsgeo.tiles.georef`). Splat centres go exactly through pyproj to ECEF; orientations
turn by the grid convergence at each splat and sizes scale by 1/k, k the point scale factor.
"""

from __future__ import annotations

import os

import numpy as np
from pyproj import Transformer
from pyproj.exceptions import CRSError as PyprojCRSError
from pyproj.exceptions import ProjError

from gsgeo.crs.ellipsoid import enu_rotation
from gsgeo.crs.resolve import parse_crs
from gsgeo.crs.transformers import accuracy_m, candidates, choose, pipeline, projection, transformer
from gsgeo.errors import CRSError, DatumError
from gsgeo.tiles.placement import AXES, GeoreferenceLike, Placement, rot_z
from gsgeo.tiles.splats import Splats


class GridPlacement(Placement):
    """Projected-CRS input: exact pyproj path for centres, convergence and scale factor."""

    def __init__(self, georef: GeoreferenceLike, c_in: np.ndarray) -> None:
        self.g = georef
        c = parse_crs(georef.crs)
        self.horiz = c.sub_crs_list[0] if c.is_compound else c
        geog = self.horiz.geodetic_crs
        assert geog is not None  # a projected or geographic CRS has one
        self.geog = geog
        try:
            self.inv = transformer(self.horiz, self.geog)
            # The same explicit operation the measurements take back to the grid
            # (gsgeo.crs.transformers.choose at the scene centre), so a point measured in the
            # tileset returns to the input's own grid coordinates.
            lon_c, lat_c = self.inv.transform(c_in[0] + georef.offset[0],
                                              c_in[1] + georef.offset[1], errcheck=False)
            self.to_ecef_t, _ = choose(self.geog.to_3d(), "EPSG:4978", float(lon_c), float(lat_c))
            self.proj = projection(self.horiz)
        except (ProjError, PyprojCRSError) as exc:
            raise CRSError(f"cannot build the transformation from {georef.crs}: {exc}") from None
        self.vert: Transformer | None = None
        if georef.height == "vertical":
            comp = parse_crs(
                {"$schema": "https://proj.org/schemas/v0.7/projjson.schema.json",
                 "type": "CompoundCRS", "name": "grid + vertical",
                 "components": [self.horiz.to_json_dict(),
                                parse_crs(georef.vertical_crs).to_json_dict()]})
            if not comp.sub_crs_list[1].is_vertical:
                raise CRSError(f"{georef.vertical_crs} is not a vertical CRS")
            try:
                self.vert = transformer(comp, self.geog.to_3d(), allow_ballpark=False)
            except ProjError:
                grp = candidates(comp, self.geog.to_3d())
                why = "; ".join(str(w) for w in grp.unavailable[:1]) or \
                    "no transformation without a geoid grid"
                raise DatumError(
                    f"heights in {georef.vertical_crs} need a geoid grid that is not "
                    f"installed ({why}); pass --geoid FILE.tif or --height ellipsoidal") from None
        elif georef.height == "geoid":
            assert georef.geoid is not None  # the georeference checks the geoid file exists
            path = os.path.abspath(georef.geoid)
            try:
                self.vert = pipeline(
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
        self.sh_rot = self.r_root @ enu_rotation(lon_c[0], lat_c[0]).T @ rot_z(-conv_c) @ self.ax

    def _ecef(self, p: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Input (axes already Z-up) -> ECEF (N, 3), and geodetic lon, lat on the grid's datum."""
        e = p[:, 0] + self.g.offset[0]
        n = p[:, 1] + self.g.offset[1]
        hh = p[:, 2] + self.g.offset[2]
        lon, lat = self.inv.transform(e, n, errcheck=False)
        lon, lat = np.asarray(lon, float), np.asarray(lat, float)
        if self.g.height == "vertical":
            assert self.vert is not None
            _, _, h = self.vert.transform(e, n, hh, errcheck=False)
        elif self.g.height == "geoid":
            assert self.vert is not None
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
        rot = self.r_root @ np.swapaxes(enu_rotation(lon, lat), -1, -2) @ rot_z(-conv) @ self.ax
        return self._turn(s, rot, -np.log(k), pos, self.sh_rot)

    def to_ecef(self, p: np.ndarray) -> np.ndarray:
        return self._ecef(p @ self.ax.T)[0]
