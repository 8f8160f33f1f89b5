"""The demo scene in an arbitrary local frame, as 3DGS trainers leave a scene.

gsplat, nerfstudio, Postshot, OpenSplat and Inria's trainer work in the frame of their
structure-from-motion solution: the real world up to an unknown similarity (origin,
orientation and scale). The local variant of the demo is the georeferenced demo's true
geometry carried into such a frame by a similarity this module knows exactly:

    q = SCALE * ROTATION @ M.T @ (X - C) + SHIFT

X: true ECEF (m, WGS 84) of a point of the demo, through the georeferenced demo's grid path
(:func:`gsgeo.demo.place.local_to_ecef`); C: the ECEF of the demo's scene origin; M: the
rotation of the demo's scene frame into ECEF at C (ENU turned by the grid convergence, from
the path's Jacobian); q: the local coordinates (local units) written to the local PLY.
Because q is defined from X, the local scene is exactly a similarity of the true one (the
grid's scale factor and the Earth's curvature stay in X).

Tiled without georeference the local frame is put as ENU at lat 0, lon 0, h 0
(:data:`gsgeo.tiles.georef.DEFAULT_ORIGIN`): rendered ECEF Y = E0.T @ q + O0. The
similarity that georeferences it, Y -> X, is :func:`true_similarity` (4x4, the form of a
georeference fit's ``matrix``).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.crs.ellipsoid import enu_rotation, geodetic_to_ecef_closed_form
from gsgeo.demo import place
from gsgeo.demo.splats import Part
from gsgeo.tiles.georef import DEFAULT_ORIGIN

#: Local units per true metre. 1/SCALE = 3.33 true metres per local unit keeps the tiles'
#: position quantum (1/4096 local unit) at 0.8 mm on the ground.
SCALE = 0.3
#: The local frame's turn: about this axis (true scene frame: east, north, up; normalised
#: below), by this angle (degrees, right-handed). The scene's up tilts by about 42 degrees.
AXIS = (0.45, -0.55, 0.70)
ANGLE_DEG = 61.0
#: Where the demo's scene origin lands in the local frame (local units).
SHIFT = (2.71, -1.38, 0.64)
#: Step of the central differences that give the grid path's Jacobian at the origin (m).
JACOBIAN_STEP_M = 1.0


def rotation() -> np.ndarray:
    """The 3x3 rotation of :data:`AXIS` and :data:`ANGLE_DEG` (Rodrigues' formula)."""
    k = np.asarray(AXIS, np.float64)
    k = k / np.linalg.norm(k)
    a = np.radians(ANGLE_DEG)
    kx = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + np.sin(a) * kx + (1.0 - np.cos(a)) * (kx @ kx)


@dataclass(frozen=True)
class SiteFrame:
    """The demo's scene frame at its origin: ``centre`` ECEF (m), ``rotation`` scene -> ECEF
    (3x3), ``scale`` the path's mean scale there (ECEF metres per scene metre, cube root of
    the Jacobian's determinant; 1 - 1e-4 or so, the grid's scale factor)."""

    centre: np.ndarray
    rotation: np.ndarray
    scale: float


@cache
def site_frame() -> SiteFrame:
    """The :class:`SiteFrame` of the georeferenced demo (pyproj, once per process)."""
    h = JACOBIAN_STEP_M
    steps = np.vstack([np.zeros(3), h * np.eye(3), -h * np.eye(3)])
    e = place.local_to_ecef(steps)
    jac = ((e[1:4] - e[4:7]) / (2 * h)).T          # columns: d ECEF / d x, y, z
    u, _, vt = np.linalg.svd(jac)
    return SiteFrame(e[0], u @ vt, float(np.cbrt(np.linalg.det(jac))))


def homogeneous(linear: ArrayLike, translation: ArrayLike) -> np.ndarray:
    """4x4 of y = linear @ x + translation."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(linear, np.float64)
    m[:3, 3] = np.asarray(translation, np.float64)
    return m


def ecef_to_local() -> np.ndarray:
    """4x4: true ECEF (m) -> local coordinates q (local units)."""
    f = site_frame()
    lin = SCALE * rotation() @ f.rotation.T
    return homogeneous(lin, np.asarray(SHIFT) - lin @ f.centre)


def local_to_rendered() -> np.ndarray:
    """4x4: local coordinates q -> the ECEF where an un-georeferenced tileset puts them
    (local ENU at :data:`DEFAULT_ORIGIN`, as ``gsgeo tiles`` without georeference does)."""
    lat, lon, h = DEFAULT_ORIGIN
    return homogeneous(enu_rotation(lon, lat).T, geodetic_to_ecef_closed_form(lon, lat, h))


def true_similarity() -> np.ndarray:
    """4x4 S: rendered ECEF of the un-georeferenced local tileset -> true ECEF (X = S Y).
    Scale 1/SCALE; what a perfect georeference by control finds."""
    return np.linalg.inv(local_to_rendered() @ ecef_to_local())


def column_major(m: np.ndarray) -> list[float]:
    """A 4x4 as the 16 numbers of 3D Tiles (column-major)."""
    return [float(v) for v in np.asarray(m, np.float64).T.ravel()]


def apply(m: np.ndarray, points: ArrayLike) -> np.ndarray:
    """Points (N, 3) through the 4x4 ``m``."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    return p @ m[:3, :3].T + m[:3, 3]


def local_part(part: Part) -> Part:
    """The demo's splats (scene frame) in the local frame: centres exactly through the true
    ECEF, orientations turned by ROTATION (the site's turn cancels in M.T @ M), sizes scaled by
    SCALE times the path's scale."""
    f = site_frame()
    q = apply(ecef_to_local(), place.local_to_ecef(part.positions))
    axes = np.einsum("ij,njk->nik", rotation(), part.axes)
    return Part(q, part.sigmas * (SCALE * f.scale), axes, part.rgb, part.alpha)
