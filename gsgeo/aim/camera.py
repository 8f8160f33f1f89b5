"""The viewer's pinhole camera (CesiumJS's centred PerspectiveFrustum) in rendered ECEF.

Window coordinates are Cesium's: continuous, origin at the top-left edge of the canvas, x
right, y down, CSS pixels; the centre of image column i / row j is at x = i + 0.5,
y = j + 0.5. A point P projects to x = W/2 + f (d.right)/(d.direction),
y = H/2 - f (d.up)/(d.direction), with d = P - position, right = direction x up and
f = H / (2 tan(fovy / 2)); :meth:`Camera.pick_ray` is its exact inverse (Cesium's
camera.getPickRay).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import InputError
from gsgeo.solve.linalg import FloatArray

#: Points closer than this in front of the camera (metres along its axis) do not project.
MIN_DEPTH_M = 1e-3


def _unit(v: ArrayLike, field: str) -> FloatArray:
    a = np.asarray(v, dtype=np.float64).reshape(3)
    n = float(np.linalg.norm(a))
    if not math.isfinite(n) or n < 1e-9:
        raise InputError("must be a non-zero vector of finite numbers", field=field)
    return a / n


@dataclass(frozen=True, eq=False)
class Camera:
    """position (3,) rendered ECEF metres; direction, up (3,) unit and orthogonal; fovy
    radians; width, height canvas size in CSS pixels."""

    position: FloatArray
    direction: FloatArray
    up: FloatArray
    fovy: float
    width: float
    height: float

    @classmethod
    def checked(cls, position: ArrayLike, direction: ArrayLike, up: ArrayLike, fovy: float,
                width: float, height: float, field: str = "camera") -> Camera:
        """A camera from JSON-like values; ``up`` is made orthogonal to ``direction``.
        InputError names ``<field>.<member>`` for a value that makes no camera."""
        pos = np.asarray(position, dtype=np.float64).reshape(3)
        if not np.all(np.isfinite(pos)):
            raise InputError("must be finite numbers", field=f"{field}.position")
        d = _unit(direction, f"{field}.direction")
        u = _unit(up, f"{field}.up")
        u = u - (u @ d) * d
        if np.linalg.norm(u) < 1e-6:
            raise InputError("is parallel to the direction", field=f"{field}.up")
        if not (math.isfinite(fovy) and 1e-4 < fovy < math.pi - 1e-3):
            raise InputError("must be an angle between 0 and pi radians", field=f"{field}.fovy")
        for name, v in (("width", width), ("height", height)):
            if not (math.isfinite(v) and 1 <= v <= 100_000):
                raise InputError("must be a canvas size from 1 to 100000 px",
                                 field=f"{field}.{name}")
        return cls(pos, d, u / np.linalg.norm(u), float(fovy), float(width), float(height))

    @classmethod
    def look_at(cls, position: ArrayLike, target: ArrayLike, up_hint: ArrayLike, fovy: float,
                width: float, height: float) -> Camera:
        """A camera at ``position`` looking at ``target`` whose up is ``up_hint`` as far as
        it is orthogonal to the view (any perpendicular when they are parallel)."""
        pos = np.asarray(position, dtype=np.float64)
        d = np.asarray(target, dtype=np.float64) - pos
        d = d / np.linalg.norm(d)
        u = np.asarray(up_hint, dtype=np.float64)
        u = u - (u @ d) * d
        if np.linalg.norm(u) < 1e-6:
            u = np.cross(d, [1.0, 0.0, 0.0] if abs(d[0]) < 0.9 else [0.0, 1.0, 0.0])
        return cls(pos, d, u / np.linalg.norm(u), float(fovy), float(width), float(height))

    @cached_property
    def right(self) -> FloatArray:
        """direction x up (unit), made once: every projection needs it."""
        d, u = self.direction, self.up
        return np.array([d[1] * u[2] - d[2] * u[1], d[2] * u[0] - d[0] * u[2],
                         d[0] * u[1] - d[1] * u[0]])

    @property
    def focal_px(self) -> float:
        """f = H / (2 tan(fovy / 2)), pixels."""
        return self.height / (2.0 * math.tan(self.fovy / 2.0))

    @property
    def ifov(self) -> float:
        """The angle of one pixel at the image centre, radians (as the viewer's rays carry)."""
        return 1.0 / self.focal_px

    def to_json(self) -> dict[str, object]:
        return {"position": self.position.tolist(), "direction": self.direction.tolist(),
                "up": self.up.tolist(), "fovy": self.fovy, "width": self.width,
                "height": self.height}

    def project(self, points: ArrayLike) -> tuple[FloatArray, FloatArray]:
        """Window coordinates (N, 2) of points (N, 3) and their depth along the camera axis
        (N,) in metres; coordinates are NaN where the depth is below MIN_DEPTH_M."""
        p = np.asarray(points, dtype=np.float64).reshape(-1, 3) - self.position
        z = p @ self.direction
        f = self.focal_px
        with np.errstate(divide="ignore", invalid="ignore"):
            x = self.width / 2 + f * (p @ self.right) / z
            y = self.height / 2 - f * (p @ self.up) / z
        xy = np.stack([x, y], axis=1)
        xy[z < MIN_DEPTH_M] = np.nan
        return xy, z

    def pick_ray(self, pixels: ArrayLike) -> FloatArray:
        """Unit directions (N, 3) of the rays through window coordinates (N, 2)."""
        px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        f = self.focal_px
        d = (f * self.direction[None, :] + (px[:, :1] - self.width / 2) * self.right[None, :]
             - (px[:, 1:] - self.height / 2) * self.up[None, :])
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def in_image(self, pixels: ArrayLike, margin: float = 0.0) -> np.ndarray:
        """Whether window coordinates (N, 2) lie on the canvas, ``margin`` px inside it."""
        px = np.asarray(pixels, dtype=np.float64).reshape(-1, 2)
        with np.errstate(invalid="ignore"):
            return ((px[:, 0] >= margin) & (px[:, 0] <= self.width - margin)
                    & (px[:, 1] >= margin) & (px[:, 1] <= self.height - margin))

    def visible_span(self, origin: ArrayLike, direction: ArrayLike, near: float,
                     far: float) -> tuple[float, float] | None:
        """The part [t0, t1] of the 3-D segment origin + t direction, near <= t <= far, in
        front of the camera (depth >= MIN_DEPTH_M); None when none is."""
        o = np.asarray(origin, dtype=np.float64) - self.position
        d = np.asarray(direction, dtype=np.float64)
        z0, dz = float(o @ self.direction), float(d @ self.direction)
        lo, hi = near, far
        if abs(dz) < 1e-12:
            return (lo, hi) if z0 >= MIN_DEPTH_M else None
        t_edge = (MIN_DEPTH_M - z0) / dz
        if dz > 0:
            lo = max(lo, t_edge)
        else:
            hi = min(hi, t_edge)
        return (lo, hi) if lo <= hi else None

    def epipolar_segment(self, origin: ArrayLike, direction: ArrayLike, near: float,
                         far: float) -> tuple[FloatArray, FloatArray] | None:
        """Window coordinates of the ends of the 3-D segment origin + t direction (unit
        direction, near <= t <= far) as this camera sees it, cut to the part in front of the
        camera; None when it is all behind."""
        span = self.visible_span(origin, direction, near, far)
        if span is None:
            return None
        o = np.asarray(origin, dtype=np.float64)
        d = np.asarray(direction, dtype=np.float64)
        ends, _ = self.project(np.stack([o + span[0] * d, o + span[1] * d]))
        if not np.all(np.isfinite(ends)):
            return None
        return ends[0], ends[1]


def closest_on_first(o1: FloatArray, d1: FloatArray, o2: FloatArray, d2: FloatArray) -> float:
    """The parameter t along the first line (o1 + t d1, unit d1) of its point closest to the
    second line (o2 + s d2, unit d2); NaN for parallel lines."""
    w = o1 - o2
    b = float(d1 @ d2)
    den = 1.0 - b * b
    if den < 1e-12:
        return math.nan
    return (b * float(d2 @ w) - float(d1 @ w)) / den
