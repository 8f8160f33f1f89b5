"""Accuracy of measured points against check points (docs/architecture.md, "Quality statistics").

Differences are measured minus check, in the grid CRS (metres). Horizontal:
RMSE_H = sqrt(RMSE_E^2 + RMSE_N^2); vertical RMSE_V from the height differences dH;
RMSE_3D = sqrt(RMSE_H^2 + RMSE_V^2). ME is the mean difference per component and SD its
sample standard deviation (n - 1), as the ASPRS Positional Accuracy Standards (ed. 2, 2023)
report them.
"""

from __future__ import annotations

import math

import numpy as np

from gsgeo.jsontypes import JSONObject
from gsgeo.solve.linalg import FloatArray


def _f(x: float) -> float | None:
    return None if x is None or not math.isfinite(x) else float(x)


def _rmse(d: np.ndarray) -> float:
    return float(np.sqrt(np.mean(d * d))) if d.size else math.nan


def _sd(d: np.ndarray) -> float:
    return float(np.std(d, ddof=1)) if d.size >= 2 else math.nan


def accuracy_report(ids: list[str], measured: FloatArray, check: FloatArray) -> JSONObject:
    """Per-point differences and summary statistics.

    ids : point ids matched between measured and check points (M,).
    measured, check : (M, 3) easting, northing, height in one grid CRS, metres; a height may
        be NaN (not measured / not given), which leaves that point out of the vertical
        statistics only.
    """
    m = np.asarray(measured, dtype=float).reshape(-1, 3)
    c = np.asarray(check, dtype=float).reshape(-1, 3)
    d = m - c
    has_v = np.isfinite(d[:, 2])
    d2 = np.hypot(d[:, 0], d[:, 1])
    points = [
        {"id": pid, "dE": _f(d[i, 0]), "dN": _f(d[i, 1]), "dH": _f(d[i, 2]),
         "d2D": _f(d2[i]), "d3D": _f(math.hypot(d2[i], d[i, 2])) if has_v[i] else None}
        for i, pid in enumerate(ids)
    ]
    de, dn, dv = d[:, 0], d[:, 1], d[:, 2][has_v]
    rmse_e, rmse_n, rmse_v = _rmse(de), _rmse(dn), _rmse(dv)
    rmse_h = math.hypot(rmse_e, rmse_n)
    rmse_3d = math.hypot(rmse_h, rmse_v)
    stats = {
        "RMSE_E": _f(rmse_e), "RMSE_N": _f(rmse_n), "RMSE_H": _f(rmse_h),
        "RMSE_V": _f(rmse_v), "RMSE_3D": _f(rmse_3d),
        "ME_E": _f(float(de.mean()) if de.size else math.nan),
        "ME_N": _f(float(dn.mean()) if dn.size else math.nan),
        "ME_V": _f(float(dv.mean()) if dv.size else math.nan),
        "SD_E": _f(_sd(de)), "SD_N": _f(_sd(dn)), "SD_V": _f(_sd(dv)),
        "n_horizontal": int(d.shape[0]), "n_vertical": int(has_v.sum()),
    }
    return {"points": points, "statistics": stats}
