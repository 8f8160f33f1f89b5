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
from numpy.typing import ArrayLike

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


# ASPRS Positional Accuracy Standards for Digital Geospatial Data, Edition 2 (2023) -----------

#: The standard the statistics of :func:`asprs_accuracy` follow.
ASPRS_STANDARD = "ASPRS Positional Accuracy Standards for Digital Geospatial Data, Edition 2 (2023)"
#: Edition 2's minimum number of checkpoints for a product accuracy assessment (it was 20 in
#: Edition 1); large projects need no more than 120.
ASPRS_MIN_CHECKPOINTS = 30
#: NSSDA 95 % factors: horizontal radial error in the circular case (RMSE_E = RMSE_N),
#: 2.4477 / sqrt(2); vertical, the normal distribution's two-sided 95 % quantile.
NSSDA_H95 = 1.7308
NSSDA_V95 = 1.9600
#: Below this ratio of the smaller to the larger of RMSE_E, RMSE_N the NSSDA circular
#: approximation behind NSSDA_H95 does not hold.
NSSDA_CIRCULAR_RATIO = 0.6


def _survey_rmse(sigma: FloatArray, mask: np.ndarray, per_point: float) -> tuple[float, int]:
    """(RMSE over the points of ``mask`` whose sigma is stated, how many stated); ``per_point``
    turns a 1-sigma per axis into that point's expected squared error factor."""
    s = sigma[mask]
    s = s[np.isfinite(s) & (s > 0)]
    if not s.size:
        return math.nan, 0
    return float(np.sqrt(np.mean(per_point * s * s))), int(s.size)


def asprs_accuracy(differences: ArrayLike, survey_sigma_h: ArrayLike | None = None,
                   survey_sigma_v: ArrayLike | None = None) -> JSONObject:
    """Product accuracy against independent checkpoints per ASPRS Edition 2 (2023).

    differences : (M, 3) measured minus checkpoint dE, dN, dH (metres, grid axes); a NaN dH
        leaves that point out of the vertical statistics only.
    survey_sigma_h, survey_sigma_v : (M,) the checkpoints' own stated 1-sigma survey
        precision (metres; horizontal per axis, vertical), NaN or None where not stated.

    Edition 2 counts the checkpoints' survey error into the product accuracy:
    RMSE_H = sqrt(RMSE_H1^2 + RMSE_H2^2) and RMSE_V = sqrt(RMSE_V1^2 + RMSE_V2^2), where
    RMSE_H1 = sqrt(RMSE_E^2 + RMSE_N^2) and RMSE_V1 are the fit of the product to the
    checkpoints and RMSE_H2, RMSE_V2 the checkpoints' survey accuracy (a per-axis sigma s
    has radial RMSE sqrt(2) s). RMSE_3D = sqrt(RMSE_H^2 + RMSE_V^2). Mean errors and
    standard deviations (n - 1) are of the differences. The 95 % figures are NSSDA's
    (Edition 2 itself reports RMSE only): 1.7308 RMSE_H (circular case), 1.96 RMSE_V.

    Returns a JSON object: ``statistics`` (numbers, None where undefined), ``formulas``
    (the formulas used, as text) and ``remarks`` (what the reader must know: too few
    checkpoints, survey accuracy not stated, a non-circular horizontal error).
    """
    d = np.asarray(differences, dtype=float).reshape(-1, 3)
    n = d.shape[0]
    has_v = np.isfinite(d[:, 2])
    de, dn, dv = d[:, 0], d[:, 1], d[:, 2][has_v]
    rmse_e, rmse_n, rmse_v1 = _rmse(de), _rmse(dn), _rmse(dv)
    rmse_h1 = math.hypot(rmse_e, rmse_n)
    sh = np.full(n, np.nan) if survey_sigma_h is None else \
        np.asarray(survey_sigma_h, dtype=float).reshape(n)
    sv = np.full(n, np.nan) if survey_sigma_v is None else \
        np.asarray(survey_sigma_v, dtype=float).reshape(n)
    rmse_h2, n_h2 = _survey_rmse(sh, np.ones(n, dtype=bool), 2.0)
    rmse_v2, n_v2 = _survey_rmse(sv, has_v, 1.0)
    rmse_h = math.hypot(rmse_h1, rmse_h2) if n_h2 else rmse_h1
    rmse_v = math.hypot(rmse_v1, rmse_v2) if n_v2 else rmse_v1
    rmse_3d = math.hypot(rmse_h, rmse_v)
    n_v = int(has_v.sum())
    ratio = (min(rmse_e, rmse_n) / max(rmse_e, rmse_n)
             if n and max(rmse_e, rmse_n) > 0 else math.nan)
    stats = {
        "n_horizontal": n, "n_vertical": n_v,
        "RMSE_E": _f(rmse_e), "RMSE_N": _f(rmse_n), "RMSE_H1": _f(rmse_h1),
        "RMSE_H2": _f(rmse_h2), "n_survey_horizontal": n_h2, "RMSE_H": _f(rmse_h),
        "RMSE_V1": _f(rmse_v1), "RMSE_V2": _f(rmse_v2), "n_survey_vertical": n_v2,
        "RMSE_V": _f(rmse_v), "RMSE_3D": _f(rmse_3d),
        "ME_E": _f(float(de.mean()) if n else math.nan),
        "ME_N": _f(float(dn.mean()) if n else math.nan),
        "ME_V": _f(float(dv.mean()) if n_v else math.nan),
        "SD_E": _f(_sd(de)), "SD_N": _f(_sd(dn)), "SD_V": _f(_sd(dv)),
        "rmse_ratio_EN": _f(ratio),
        "ACC_H95": _f(NSSDA_H95 * rmse_h), "ACC_V95": _f(NSSDA_V95 * rmse_v),
    }
    formulas = [
        "RMSE_H1 = sqrt(RMSE_E² + RMSE_N²) (radial; product against checkpoints)",
        "RMSE_H2 = sqrt(mean(2 σ_h²)) of the checkpoints' stated per-axis survey σ_h",
        "RMSE_H = sqrt(RMSE_H1² + RMSE_H2²); RMSE_V = sqrt(RMSE_V1² + RMSE_V2²)",
        "RMSE_3D = sqrt(RMSE_H² + RMSE_V²)",
        "ME = mean difference; SD = sample standard deviation (n − 1)",
        f"horizontal 95 % = {NSSDA_H95} × RMSE_H (NSSDA, circular case RMSE_E = RMSE_N)",
        f"vertical 95 % = {NSSDA_V95:.2f} × RMSE_V (NSSDA)",
    ]
    remarks: list[str] = []
    if n < ASPRS_MIN_CHECKPOINTS:
        remarks.append(f"{n} checkpoint{'' if n == 1 else 's'} horizontally and {n_v} "
                       f"vertically: Edition 2 recommends at least {ASPRS_MIN_CHECKPOINTS} "
                       "checkpoints for a product accuracy assessment.")
    if n and n_h2 < n:
        remarks.append("checkpoint survey accuracy (σ_h) not stated for "
                       f"{n - n_h2} of {n} checkpoints: RMSE_H2 "
                       + ("from the others." if n_h2 else "is not included (taken as zero)."))
    if n_v and n_v2 < n_v:
        remarks.append("checkpoint survey accuracy (σ_v) not stated for "
                       f"{n_v - n_v2} of {n_v} checkpoints: RMSE_V2 "
                       + ("from the others." if n_v2 else "is not included (taken as zero)."))
    if math.isfinite(ratio) and ratio < NSSDA_CIRCULAR_RATIO:
        remarks.append(f"RMSE_E and RMSE_N differ (ratio {ratio:.2f} < "
                       f"{NSSDA_CIRCULAR_RATIO}): the circular-case horizontal 95 % figure is "
                       "only indicative.")
    remarks.append("Edition 2 states accuracy as RMSE; the 95 % figures follow the NSSDA "
                   "and are given for reference.")
    return {"standard": ASPRS_STANDARD, "statistics": stats, "formulas": formulas,
            "remarks": remarks}
