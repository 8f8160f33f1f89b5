"""A scene's georeference from its measured control: the fit, its blunder tests, its report.

:func:`georeference` takes the measured points of a scene (ECEF in the scene's current frame,
with covariances) and the reference points (control and check, in their own CRSs), fits the
similarity of :mod:`gsgeo.georef.helmert` to the measured control, runs iterated data
snooping, and gives a :class:`GeorefSolution`: the similarity, its frame covariance (what it
adds to every point measured in the scene) and the JSON a user reads (``to_json``).

Residuals are always *measured minus reference*: the measured point mapped by the fit minus
the control (or check) coordinates, in the project's grid (E, N, H in metres, through the
grid's Jacobian, so scale factor and convergence are those of the grid) or, without a grid,
in the local east-north-up frame at each point.

Blunders are never absorbed: a control point whose residual fails the test (alpha 0.1 %,
chi-square with 3 degrees of freedom) is flagged; the worst is set aside and the test
repeated until none fails or only 3 points remain. The fit reported is the one with every
control point the user did not exclude; the fit without the flagged points is reported
beside it, and the user decides (exclude them, or accept them).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form, enu_rotation
from gsgeo.crs.grid import to_grid_many
from gsgeo.errors import GeometryError, InputError
from gsgeo.georef.control import control_ecef, enu_covariances
from gsgeo.georef.helmert import Similarity, SimilarityFit, fit_similarity
from gsgeo.jsontypes import JSONObject
from gsgeo.measure.framecov import FrameCovariance
from gsgeo.measure.rays import SolveSettings
from gsgeo.solve.linalg import FloatArray

#: Level of the per-point blunder test (Baarda's customary 0.1 %).
SNOOPING_ALPHA = 0.001
#: Precision assumed for control whose file states none (metres), with a warning.
DEFAULT_SIGMA_H = 0.01
DEFAULT_SIGMA_V = 0.02


@dataclass
class Reference:
    """Control or check points as given: ids, (M, 3) coordinates in ``crss[i]`` (NaN height
    when unknown), stated sigmas (m, NaN when not stated) and roles ('control' | 'check')."""

    ids: list[str]
    xyz: FloatArray
    crss: list[str]
    sigma_h: FloatArray
    sigma_v: FloatArray
    roles: list[str]


@dataclass
class Measured:
    """Measured points of the scene: ids, ECEF (K, 3) in its current frame, covariances
    (K, 3, 3) m² (the aiming alone)."""

    ids: list[str]
    ecef: FloatArray
    cov: FloatArray

    def index(self) -> dict[str, int]:
        return {pid: i for i, pid in enumerate(self.ids)}


@dataclass
class GeorefSolution:
    """The chosen fit (every control point not excluded), its frame covariance and the JSON
    report (flagged outliers, the fit without them, warnings)."""

    similarity: Similarity
    frame: FrameCovariance
    fit: SimilarityFit
    report: JSONObject


def _rmse(d: FloatArray) -> JSONObject | None:
    """RMSE of (M, 3) dE, dN, dH (NaN heights left out of H and 3-D)."""
    if d.shape[0] == 0:
        return None
    hv = np.isfinite(d[:, 2])
    h2 = d[:, 0] ** 2 + d[:, 1] ** 2

    def rms(x: FloatArray) -> float | None:
        return float(math.sqrt(np.mean(x))) if x.size else None

    return {"e": rms(d[:, 0] ** 2), "n": rms(d[:, 1] ** 2), "h": rms(d[hv, 2] ** 2),
            "horizontal": rms(h2), "3d": rms(h2[hv] + d[hv, 2] ** 2), "count": int(d.shape[0]),
            "count_vertical": int(hv.sum())}


class _Local:
    """Differences and coordinates of ECEF points in the grid (or local ENU without one)."""

    def __init__(self, ref_ecef: FloatArray, settings: SolveSettings) -> None:
        self.settings = settings
        if settings.crs:
            g = to_grid_many(ref_ecef, None, settings.crs, vertical=settings.vertical,
                             geoid=settings.geoid, source_crs=settings.source_crs)
            self.jac = g.jacobian
            self.coords = np.column_stack([g.easting, g.northing, g.height])
        else:
            lon, lat, _ = ecef_to_geodetic_closed_form(ref_ecef)
            self.jac = enu_rotation(lon, lat).reshape(-1, 3, 3)
            c = ref_ecef.mean(axis=0)
            self.coords = np.einsum("nij,nj->ni", self.jac, ref_ecef - c)

    def diff(self, idx: Sequence[int], d_ecef: FloatArray) -> FloatArray:
        return np.einsum("nij,nj->ni", self.jac[list(idx)], d_ecef)


def georeference(measured: Measured, reference: Reference, settings: SolveSettings, *,
                 exclude: Sequence[str] = (), alpha: float = SNOOPING_ALPHA) -> GeorefSolution:
    """Fit the similarity scene frame -> Earth from the measured control (see module docstring).

    ``settings`` are the project's (grid CRS, vertical datum or geoid, source CRS): the control
    goes to ECEF along their path. Raises InputError (unknown excluded ids, control without
    heights), GeometryError (fewer than 3 measured control points, a collinear layout) or
    CRSError.
    """
    ctl = [i for i, r in enumerate(reference.roles) if r == "control"]
    ctl_ids = [reference.ids[i] for i in ctl]
    unknown = sorted(set(exclude) - set(ctl_ids))
    if unknown:
        raise InputError(f"not a control point: {', '.join(unknown[:5])}", field="exclude")
    at = measured.index()
    used = [i for i in ctl if reference.ids[i] in at and reference.ids[i] not in exclude]
    not_measured = [reference.ids[i] for i in ctl if reference.ids[i] not in at]
    if len(used) < 3:
        raise GeometryError(
            f"georeferencing needs at least 3 measured control points; {len(used)} usable "
            f"({len(ctl)} control point(s) in the project"
            + (f", not measured: {', '.join(not_measured[:8])}" if not_measured else "")
            + (f", excluded: {', '.join(sorted(exclude))}" if exclude else "") + ")")
    warnings: list[str] = []
    sh = reference.sigma_h.astype(np.float64).copy()
    sv = reference.sigma_v.astype(np.float64).copy()
    unstated = [reference.ids[i] for i in ctl if not (np.isfinite(sh[i]) and np.isfinite(sv[i]))]
    if unstated:
        warnings.append(f"no stated precision for control {', '.join(unstated[:5])}"
                        f"{'...' if len(unstated) > 5 else ''}: taken as sigma_h "
                        f"{DEFAULT_SIGMA_H} m, sigma_v {DEFAULT_SIGMA_V} m")
    sh = np.where(np.isfinite(sh), sh, DEFAULT_SIGMA_H)
    sv = np.where(np.isfinite(sv), sv, DEFAULT_SIGMA_V)

    chk = [i for i, r in enumerate(reference.roles)
           if r == "check" and reference.ids[i] in at]
    no_h = [i for i in chk if not np.isfinite(reference.xyz[i, 2])]
    if no_h:
        warnings.append(f"check point(s) {', '.join(reference.ids[i] for i in no_h[:5])} "
                        "have no height and are left out")
    chk = [i for i in chk if i not in no_h]
    both = [i for i in ctl if reference.ids[i] in at] + chk
    ecef = np.full((len(reference.ids), 3), np.nan)
    ecef[both] = control_ecef(reference.xyz[both], [reference.crss[i] for i in both], settings,
                              [reference.ids[i] for i in both])
    cov_ref = enu_covariances(np.nan_to_num(ecef), sh, sv)
    local = _Local(np.where(np.isfinite(ecef), ecef, ecef[both[0]]), settings)

    def fit_of(idx: list[int]) -> SimilarityFit:
        m = [at[reference.ids[i]] for i in idx]
        return fit_similarity(measured.ecef[m], ecef[idx], measured.cov[m], cov_ref[idx])

    fit = fit_of(used)
    flagged: list[str] = []
    cur, last = list(used), fit
    while len(cur) > 3:
        p = np.where(np.isfinite(last.p), last.p, 1.0)
        k = int(np.argmin(p))
        if not p[k] < alpha:
            break
        flagged.append(reference.ids[cur[k]])
        cur.pop(k)
        last = fit_of(cur)
    tests = {reference.ids[i]: (float(fit.test[n]), float(fit.p[n])) for n, i in enumerate(used)}

    def residual_rows(f: SimilarityFit, idx: list[int]) -> tuple[list[JSONObject], FloatArray]:
        m = [at[reference.ids[i]] for i in idx]
        d = local.diff(idx, f.similarity.apply(measured.ecef[m]) - ecef[idx])
        rows: list[JSONObject] = []
        for n, i in enumerate(idx):
            rows.append({"id": reference.ids[i], "dE": float(d[n, 0]), "dN": float(d[n, 1]),
                         "dH": float(d[n, 2]), "easting": float(local.coords[i, 0]),
                         "northing": float(local.coords[i, 1]),
                         "height": float(local.coords[i, 2])})
        return rows, d

    measured_ctl = [i for i in ctl if reference.ids[i] in at]
    ctl_rows, _ = residual_rows(fit, measured_ctl)
    for row, i in zip(ctl_rows, measured_ctl, strict=True):
        t, pv = tests.get(reference.ids[i], (math.nan, math.nan))
        row.update(used=i in used, excluded=reference.ids[i] in exclude,
                   outlier=reference.ids[i] in flagged,
                   w=None if not math.isfinite(t) else math.sqrt(t),
                   p=None if not math.isfinite(pv) else pv,
                   sigma_h=float(sh[i]), sigma_v=float(sv[i]))
    used_d = np.array([[r["dE"], r["dN"], r["dH"]] for r in ctl_rows if r["used"]], dtype=float)
    chk_rows, chk_d = residual_rows(fit, chk)
    report = _summary(fit, "similarity")
    report.update(
        control=ctl_rows, check=chk_rows, rmse_control=_rmse(used_d.reshape(-1, 3)),
        rmse_check=_rmse(chk_d.reshape(-1, 3)), outliers=flagged,
        not_measured=not_measured, grid_crs=settings.crs,
        residuals="measured (mapped by the fit) minus reference, metres, "
                  + ("in the grid" if settings.crs else "in local east, north, up"),
        without_outliers=None, warnings=list(warnings), applied=False, scene=None)
    if flagged:
        keep = [i for i in used if reference.ids[i] not in flagged]
        rows_wo, d_wo = residual_rows(last, keep)
        _, chk_wo = residual_rows(last, chk)
        alt = _summary(last, "similarity")
        alt.update(excluded=flagged, rmse_control=_rmse(d_wo), rmse_check=_rmse(chk_wo))
        report["without_outliers"] = alt
        report["warnings"] = list(warnings) + [
            f"control point(s) {', '.join(flagged)} fail the blunder test (alpha "
            f"{alpha:g}): check them; exclude them or accept them explicitly"]
    frame = FrameCovariance(fit.centre, fit.covariance)
    report["frame_covariance"] = frame.to_json()
    return GeorefSolution(fit.similarity, frame, fit, report)


def _summary(f: SimilarityFit, kind: str) -> JSONObject:
    """Parameters with sigmas of one fit (JSON)."""
    s = f.similarity
    return {"kind": kind, "scale": s.scale, "scale_sigma": f.scale_sigma(),
            "scale_ppm": (s.scale - 1.0) * 1e6,
            "rotation": s.rotation.tolist(),
            "rotation_sigma_deg": np.degrees(f.rotation_sigma_rad()).tolist(),
            "translation": s.translation.tolist(),
            # the shift's 1-sigma at the control's centre (t itself, the image of the Earth's
            # centre, is kilometres uncertain through its correlation with the rotation)
            "translation_sigma": np.sqrt(np.clip(np.diag(f.covariance)[:3], 0, None)).tolist(),
            "centre_ecef": f.centre.tolist(),
            "matrix": [float(v) for v in s.matrix().T.reshape(-1)],
            "sigma0": f.sigma0, "dof": f.dof, "global_test_p": f.global_p,
            "iterations": f.iterations}
