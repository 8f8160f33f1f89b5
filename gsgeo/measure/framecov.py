"""The uncertainty of a scene's georeference, and what it adds to a measured point's covariance.

A scene georeferenced by control points carries a fitted similarity whose seven parameters are
uncertain. That uncertainty is expressed as a small perturbation of the georeferenced (ECEF)
frame about a centre c (the weighted centroid of the control), in metres and radians:

    y = y0 + dt + dw x (y0 - c) + ds (y0 - c)

dt (3,) a shift, dw (3,) a small rotation about the ECEF axes, ds a relative scale change, with a
7 x 7 covariance in that order. Every point measured in the scene shares it, so a point's total
covariance is its measurement covariance plus J C J^T with J = [I, -[y0 - c]x, (y0 - c)]: a
point far from the control is less certain than one inside it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.solve.linalg import FloatArray

#: Names of the seven parameters, in the covariance's order.
PARAMETERS = ("tx", "ty", "tz", "rx", "ry", "rz", "ds")


def frame_jacobian(points_ecef: ArrayLike, centre_ecef: ArrayLike) -> FloatArray:
    """(M, 3, 7) d(point)/d(dt, dw, ds) at ECEF points (M, 3) for a frame centred at c (3,)."""
    p = np.asarray(points_ecef, dtype=np.float64).reshape(-1, 3)
    r = p - np.asarray(centre_ecef, dtype=np.float64).reshape(3)
    j = np.zeros((p.shape[0], 3, 7))
    j[:, 0, 0] = j[:, 1, 1] = j[:, 2, 2] = 1.0
    # dw x r = -[r]x dw
    j[:, 0, 4], j[:, 0, 5] = r[:, 2], -r[:, 1]
    j[:, 1, 3], j[:, 1, 5] = -r[:, 2], r[:, 0]
    j[:, 2, 3], j[:, 2, 4] = r[:, 1], -r[:, 0]
    j[:, :, 6] = r
    return j


@dataclass(frozen=True, eq=False)
class FrameCovariance:
    """The georeference's parameter covariance: ``centre_ecef`` (3,) metres, ``covariance``
    (7, 7) of (dt m, dw rad, ds) about it (see the module docstring)."""

    centre_ecef: FloatArray
    covariance: FloatArray

    def __post_init__(self) -> None:
        c = np.asarray(self.centre_ecef, dtype=np.float64).reshape(-1)
        v = np.asarray(self.covariance, dtype=np.float64)
        if c.shape != (3,) or v.shape != (7, 7) or not (np.isfinite(c).all()
                                                          and np.isfinite(v).all()):
            raise InputError("a frame covariance needs a finite centre (3) and a 7x7 covariance")
        v = 0.5 * (v + v.T)
        c.setflags(write=False)
        v.setflags(write=False)
        object.__setattr__(self, "centre_ecef", c)
        object.__setattr__(self, "covariance", v)

    def point_covariances(self, points_ecef: ArrayLike) -> FloatArray:
        """(M, 3, 3) ECEF covariance (m²) the frame adds at points (M, 3)."""
        j = frame_jacobian(points_ecef, self.centre_ecef)
        return np.einsum("mik,kl,mjl->mij", j, self.covariance, j)

    def point_covariance(self, point_ecef: ArrayLike) -> FloatArray:
        """(3, 3) ECEF covariance (m²) the frame adds at one point (3,)."""
        return self.point_covariances(np.asarray(point_ecef, dtype=np.float64).reshape(1, 3))[0]

    def to_json(self) -> JSONObject:
        """{"centre_ecef", "covariance", "parameters"} as stored in a tileset's extras."""
        return {"centre_ecef": self.centre_ecef.tolist(),
                "covariance": self.covariance.tolist(), "parameters": list(PARAMETERS)}

    @classmethod
    def from_json(cls, doc: JSON) -> FrameCovariance:
        """The inverse of :meth:`to_json`; InputError when the document is malformed."""
        if not isinstance(doc, dict):
            raise InputError("a frame covariance must be an object")
        try:
            return cls(np.asarray(doc["centre_ecef"], dtype=np.float64),
                       np.asarray(doc["covariance"], dtype=np.float64))
        except (KeyError, TypeError, ValueError):
            raise InputError("a frame covariance needs centre_ecef (3 numbers) and "
                             "covariance (7x7 numbers)") from None
