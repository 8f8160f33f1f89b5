"""The covariance of a point whose rays share one aiming error: auto-aimed rays.

Auto-aim finds the feature clicked for a reference ray (the point's first clicked ray) in
other views by image matching. A person's click is off the feature by a pixel or two; every
matched ray then finds *the clicked spot*, not the feature. The reference ray and its matched
rays therefore meet at the same wrong place, agree with each other to a fraction of a pixel,
and the least-squares covariance (which takes every ray's error as independent) is far too
small: the reference click's aiming error is common to the whole group.

Model (the angular model of :mod:`gsgeo.solve.intersection`; frame any Cartesian, metres).
Ray i has unit direction u_i, range r_i to the solved point, a-priori precision
sigma_i = s_i f_i r_i (f_i = ifov_i; s_i = sigma_px for a click, MATCH_SIGMA_PX for an auto
ray: a match against its reference is sub-pixel), weight w_i = 1 / sigma_i^2 and projector
P_i = I - u_i u_i^T; N = sum over kept rays of w_i P_i, so the independent-ray covariance is
N^-1. The reference ray (index ``ref``, the point's first clicked ray) is off the feature by
an aiming error of sigma_px pixels in each image direction, and the spot it hits lies on the
surface there, nearer or deeper along the ray by as much again on a surface seen at
45 degrees: the group aims at feature + Delta, Delta with covariance
S = sigma_ref^2 I (sigma_ref = sigma_px f_ref r_ref: across the ray the click's error, along it
the surface's unknown slope). Every member of the group (the reference and each auto ray
matched to it) aims at feature + Delta with its own independent error as well, except the
reference, whose whole error *is* Delta. The solution moves by N^-1 G Delta with
G = sum over the kept group of w_i P_i, so

    C = N^-1 (A + G S G^T) N^-1,   A = sum over kept rays but the reference of w_i P_i.

Without auto rays, or with the reference alone in its group, C = N^-1 exactly
(w_ref^2 P_ref S P_ref = w_ref P_ref: a lone ray does not see the along-ray share).
The along-ray term is a middle way: a surface seen square-on makes the stated ellipsoid
a little large, one seen at 60 degrees or more a little small (tests/test_autoaim_honesty.py
measures the coverage over reference views 0-60 degrees from the surface normal).
"""

from __future__ import annotations

import numpy as np

from gsgeo.solve.linalg import FloatArray

#: A-priori precision of an auto ray (pixels of its view): the match of the reference patch,
#: refined to sub-pixel (gsgeo.aim.match). The demo's 20-marker sweep measured the auto rays'
#: scatter about their reference at 0.06-0.14 px (sigma0 at 1 px); this allows for views that
#: render the feature a little differently. Used only with the angular model.
MATCH_SIGMA_PX = 0.3
#: The warning of a point with auto rays measured by the unweighted model (no ifov).
AUTO_UNWEIGHTED = ("auto rays without ifov (unweighted model): the aiming error they share with "
                   "their reference ray is not in the covariance")


def reference_rays(auto: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The reference of each point's auto rays: (M,) index of the first ray not marked auto,
    and (M,) whether the point has a group at all (an auto ray and a ray it was matched to).

    ``auto`` : (M, N) bool, True where a ray was matched automatically."""
    auto = np.asarray(auto, dtype=bool)
    clicked = ~auto
    ref = np.argmax(clicked, axis=1)
    grouped = np.logical_and(np.any(auto, axis=1), np.any(clicked, axis=1))
    return ref, np.asarray(grouped, dtype=bool)


def aim_scales(auto: np.ndarray | None, shape: tuple[int, ...], sigma_px: float
               ) -> FloatArray | None:
    """Per-ray factors (shape) on sigma_px: MATCH_SIGMA_PX / sigma_px for auto rays, 1 for
    clicks; None when no ray is auto. The solver weights ray i by 1 / (sigma_px x factor x
    ifov_i x range_i)^2, which is how it is given here: ifov times the factor."""
    if auto is None:
        return None
    a = np.broadcast_to(np.asarray(auto, dtype=bool), shape)
    if not a.any():
        return None
    return np.where(a, MATCH_SIGMA_PX / sigma_px, 1.0)


def shared_aim_covariance(points: FloatArray, origins: FloatArray, directions_unit: FloatArray,
                          ifov: FloatArray, sigma_px: float, kept: np.ndarray, auto: np.ndarray,
                          normal_inverse: FloatArray) -> FloatArray:
    """The a-priori covariance (M, 3, 3), m^2, of M points whose auto rays share their
    reference ray's aiming error (module docstring), in the frame of the inputs.

    points : (M, 3) solved points. origins, directions_unit : (M, N, 3) every ray of each point,
    excluded ones too (an excluded reference still passes its error to its auto rays).
    ifov : (M, N) radians per pixel times each ray's aim_scales factor (the solver's weights).
    sigma_px : a-priori aiming precision of a click, pixels.
    kept : (M, N) rays in the solution. auto : (M, N) rays matched automatically.
    normal_inverse : (M, 3, 3) N^-1 of the kept rays with weights 1 / (sigma_px ifov range)^2
    (ifov as given here).
    Points without a group get ``normal_inverse`` unchanged.
    """
    ninv = np.asarray(normal_inverse, dtype=np.float64)
    out = ninv.copy()
    ref, grouped = reference_rays(auto)
    if not grouped.any():
        return out
    rows = np.flatnonzero(grouped)
    x, o, u = points[rows], origins[rows], directions_unit[rows]
    f, keep, au, r0 = ifov[rows], kept[rows], auto[rows], ref[rows]
    m, n = keep.shape
    ranges = np.einsum("mki,mki->mk", x[:, None, :] - o, u)
    sigma_m = sigma_px * f * ranges
    with np.errstate(divide="ignore"):
        w = np.where(keep, 1.0 / sigma_m**2, 0.0)
    proj = np.eye(3) - u[..., :, None] * u[..., None, :]  # (m, n, 3, 3)
    is_ref = np.zeros((m, n), dtype=bool)
    is_ref[np.arange(m), r0] = True
    group = (au | is_ref) & keep
    g = np.einsum("mk,mkij->mij", np.where(group, w, 0.0), proj)
    a = np.einsum("mk,mkij->mij", np.where(is_ref, 0.0, w), proj)
    at = np.arange(m)
    s = (sigma_m[at, r0] ** 2)[:, None, None] * np.eye(3)
    middle = a + g @ s @ np.swapaxes(g, 1, 2)
    ni = ninv[rows]
    c = ni @ middle @ ni
    out[rows] = 0.5 * (c + np.swapaxes(c, 1, 2))
    return out
