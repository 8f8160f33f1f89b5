"""Placements: blocks of input splats -> the root ENU frame of a tileset at the scene centre.

The root frame is the ENU frame (x east, y north, z up, metres) at the scene centre on WGS 84;
a :class:`Placement` turns centres, orientations, sizes and SH coefficients into it.
:class:`RigidPlacement` serves the rigid georeferences (no PROJ);
:class:`gsgeo.tiles.gridplacement.GridPlacement` the projected-CRS one. Both are made by
:meth:`gsgeo.tiles.georef.Georeference.placement`; this module imports neither of those, so
the three form no import cycle.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, enu_rotation
from gsgeo.tiles.splats import Splats, matrix_to_quat, quat_multiply, rotation_angle, sh_rotation

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


def rot_z(angle_deg: float | np.ndarray) -> np.ndarray:
    """Counter-clockwise rotation about z by angle (degrees), (…, 3, 3)."""
    a = np.radians(angle_deg)
    c, s = np.cos(a), np.sin(a)
    z, o = np.zeros_like(c), np.ones_like(c)
    return np.stack([np.stack([c, -s, z], -1), np.stack([s, c, z], -1),
                     np.stack([z, z, o], -1)], axis=-2)


class GeoreferenceLike(Protocol):
    """What a placement reads of a georeference (:class:`gsgeo.tiles.georef.Georeference`)."""

    crs: str | None
    offset: tuple[float, float, float]
    height: str
    vertical_crs: str | None
    geoid: str | None
    axes: str
    warnings: list[str]

    def describe(self) -> str: ...


class Placement:
    """Maps blocks of input splats into the root ENU frame at the scene centre."""

    def __init__(self, georef: GeoreferenceLike, centre_ecef: np.ndarray) -> None:
        self.georef = georef
        self.centre_ecef = np.asarray(centre_ecef, np.float64)
        lon, lat, h = ecef_to_geodetic_closed_form(self.centre_ecef)   # WGS 84 by definition
        self.centre_lonlath = (float(lon), float(lat), float(h))
        self.r_root = enu_rotation(float(lon), float(lat))   # ECEF -> root ENU
        self.operation = ""
        self.operation_accuracy_m: float | None = None
        self._sh_turns: dict[tuple[int, bytes], np.ndarray] = {}

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
            key = (k, sh_rot.tobytes())
            if key not in self._sh_turns:    # one least-squares fit per build, not per block
                self._sh_turns[key] = sh_rotation(sh_rot, k).astype(np.float32)
            sh = np.einsum("ij,njc->nic", self._sh_turns[key], sh, optimize=True)
        return Splats(positions, scales.astype(np.float32, copy=False),
                      rot_q.astype(np.float32, copy=False),
                      s.opacities, s.colors, sh)


class RigidPlacement(Placement):
    """A rigid georeference (origin, transform, none): ECEF = A p + t, A = s R for input p."""

    def __init__(self, georef: GeoreferenceLike, centre_ecef: np.ndarray, a: np.ndarray,
                 t: np.ndarray, s: float) -> None:
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
