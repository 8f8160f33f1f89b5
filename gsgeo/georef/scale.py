"""Scale-only georeferencing: a scene without control gets metres from known distances.

A scene trained in a COLMAP frame has an arbitrary scale. Given measured points and the true
distances between some pairs (a tape, a scale bar, a known building width), the scale s is the
weighted mean of the ratios D_k / d_k, each with variance (sigma_D^2 + s^2 sigma_d^2) / d_k^2:
sigma_d from the two points' covariances along their line, sigma_D as stated. The scene keeps
its local frame (no grid): the similarity scales about the scene's origin o, y = o + s (x - o).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import GeometryError, InputError
from gsgeo.georef.fit import Measured
from gsgeo.georef.helmert import Similarity
from gsgeo.jsontypes import JSONObject
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.solve.linalg import FloatArray

#: Sigma assumed for a distance stated without one (metres), with a warning.
DEFAULT_DISTANCE_SIGMA = 0.001


@dataclass(frozen=True)
class Distance:
    """A known distance between two measured points: ids, metres, 1-sigma (None: not stated)."""

    a: str
    b: str
    distance: float
    sigma: float | None = None


@dataclass
class ScaleSolution:
    similarity: Similarity
    frame: FrameCovariance
    report: JSONObject


def fit_scale(measured: Measured, distances: Sequence[Distance],
              origin_ecef: ArrayLike) -> ScaleSolution:
    """The scale of a scene from known distances between measured points (module docstring).

    ``origin_ecef`` (3,): the scene's origin, the fixed point of the scaling. Raises
    InputError for unknown ids or non-positive distances, GeometryError for coincident points.
    """
    if not distances:
        raise InputError("give at least one known distance between two measured points",
                         field="distances")
    at = measured.index()
    o = np.asarray(origin_ecef, dtype=np.float64).reshape(3)
    ratios: list[float] = []
    variances: list[float] = []
    measured_d: list[tuple[Distance, float, float]] = []
    warnings: list[str] = []
    for k, dist in enumerate(distances):
        where = f"distances[{k}]"
        for pid in (dist.a, dist.b):
            if pid not in at:
                raise InputError(f"point '{pid}' is not measured", field=where)
        if dist.a == dist.b:
            raise InputError("a distance needs two different points", field=where)
        if not (math.isfinite(dist.distance) and dist.distance > 0):
            raise InputError("the distance must be a positive number of metres", field=where)
        if dist.sigma is not None and not (math.isfinite(dist.sigma) and dist.sigma > 0):
            raise InputError("the distance's sigma must be a positive number of metres",
                             field=where)
        ia, ib = at[dist.a], at[dist.b]
        v = measured.ecef[ib] - measured.ecef[ia]
        d = float(np.linalg.norm(v))
        if not d > 0:
            raise GeometryError(f"points '{dist.a}' and '{dist.b}' coincide", field=where)
        u = v / d
        var_d = float(u @ (measured.cov[ia] + measured.cov[ib]) @ u)
        sig = dist.sigma if dist.sigma is not None else DEFAULT_DISTANCE_SIGMA
        if dist.sigma is None:
            warnings.append(f"{dist.a}-{dist.b}: no sigma stated, taken as "
                            f"{DEFAULT_DISTANCE_SIGMA} m")
        r = dist.distance / d
        ratios.append(r)
        variances.append((sig**2 + r**2 * var_d) / d**2)
        measured_d.append((dist, d, sig))
    w = 1.0 / np.asarray(variances)
    s = float(np.sum(w * np.asarray(ratios)) / np.sum(w))
    s_sigma = float(1.0 / math.sqrt(np.sum(w)))
    rows: list[JSONObject] = [
        {"from": dist.a, "to": dist.b, "distance": dist.distance, "measured": d, "sigma": sig,
         "scaled": s * d, "residual": s * d - dist.distance} for dist, d, sig in measured_d]
    dof = len(rows) - 1
    vtpv = float(np.sum(w * (np.asarray(ratios) - s) ** 2))
    sim = Similarity(s, np.eye(3), o - s * o)
    cov = np.zeros((7, 7))
    cov[6, 6] = (s_sigma / s) ** 2
    frame = FrameCovariance(o, cov)
    report: JSONObject = {
        "kind": "scale", "scale": s, "scale_sigma": s_sigma, "scale_ppm": (s - 1.0) * 1e6,
        "rotation": np.eye(3).tolist(), "rotation_sigma_deg": [0.0, 0.0, 0.0],
        "translation": sim.translation.tolist(), "translation_sigma": [0.0, 0.0, 0.0],
        "matrix": [float(v) for v in sim.matrix().T.reshape(-1)],
        "sigma0": math.sqrt(vtpv / dof) if dof > 0 else None, "dof": dof,
        "distances": rows, "control": [], "check": [], "rmse_control": None,
        "rmse_check": None, "outliers": [], "without_outliers": None, "grid_crs": None,
        "frame_covariance": frame.to_json(), "warnings": warnings, "applied": False,
        "scene": None}
    return ScaleSolution(sim, frame, report)


def origin_of(root_transform: FloatArray) -> FloatArray:
    """The ECEF origin (3,) of a scene's root frame (the root transform's translation)."""
    return np.asarray(root_transform, dtype=np.float64)[:3, 3].copy()
