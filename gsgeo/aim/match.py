"""Finding a clicked feature in another rendered view: patch matching along the epipolar
segment (OpenCV).

1. The reference ray through the click, and its segment near..far (from the depth hint),
   projected into the target view: the epipolar segment, cut to the part in front of the
   target camera and to the target image (less the template's reach).
2. The patch around the click is warped into the target view by the homography of a plane
   through the depth-hint point. Which plane: the surface's own when the depth hint gives
   its normal (the flat splats there); else, and in any case as alternatives, the level
   plane (normal = the local up: ground, roofs, the tops of things, whose splats' normal a
   client may not pass), the plane parallel to the reference image (normal = its viewing
   direction, as plane-sweep stereo assumes: exact for a surface seen square-on, which is
   what an operator picks a view for)
   and the plane facing both cameras alike (normal along the bisector of the two lines of
   sight: the least distortion for a wide baseline whose surface is unknown, where the
   first one is seen nearly edge-on by the target). Each is tried and the one whose warp
   matches best is kept. The warp carries the view change's rotation, scale and
   foreshortening into the patch, which is what makes oblique views match (a plain patch at
   60 degrees scores far lower, see the tests). When near..far is wide (a click on a thin
   object's edge, its background behind) the hint may be far from the feature, so the patch
   is warped for a sweep of depths from near to far and each warp scores the part of the
   segment its depth projects to.
   With the scene's splats about the click (a ``Foreground``, gsgeo.aim.foreground: what
   POST /api/scenes/{scene}/match passes), two more things: each patch pixel is weighted by
   the opacity of those splats there (masked NCC and ECC), so the background around an
   object's outline (sky, the ground metres behind a pole top or an eaves corner) does not
   enter the match; and the patch is also warped by the splats' own shape, their depth per
   half-pixel sample about the click moved along the reference ray, projected into the
   target (hidden samples left out) and splatted into the template: a corner's faces each
   turned as the target sees them, which no single plane does.
3. The target image is resampled into a strip along the segment (``cv2.warpAffine``), the
   warped patch in the same frame (``cv2.warpPerspective``), so the search is the band of
   BAND_PX either side of the line, and ``cv2.matchTemplate`` (normalised cross-correlation,
   TM_CCOEFF_NORMED) scores every position at once.
4. The peak is refined to sub-pixel (a parabola through it and its neighbours, then the
   translation that best aligns patch and strip, ``cv2.findTransformECC``) and mapped back
   to window coordinates; its depth along the reference ray is where the target's pick ray
   through it comes closest.

A match is declined (``ok`` False, ``reason`` says why) when the patch has no texture or the
peak is weak, when another peak away from the main one is nearly as high (ambiguous) or
several are (repeated texture along the line), when the segment is not in the target view
or the patch leaves the reference image, when the refined peak falls off the segment, or
when matching back from the target view does not lead to the click (inconsistent).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import cv2
import numpy as np

from gsgeo.aim.camera import Camera, closest_on_first
from gsgeo.aim.foreground import Foreground
from gsgeo.aim.views import local_axes
from gsgeo.solve.linalg import FloatArray

#: Half size of the matched patch (the template is 2 HALF_PX + 1 pixels square).
HALF_PX = 12
#: Half width of the band around the epipolar line searched, pixels.
BAND_PX = 2
#: Lowest peak NCC accepted.
MIN_SCORE = 0.7
#: A second peak (outside the main peak's neighbourhood) at this fraction of the main peak
#: or more makes the match ambiguous; several make it repeated texture.
AMBIGUOUS_RATIO = 0.85
REPEATS = 2
#: The main peak's neighbourhood along the line, pixels (its correlation lobe).
NEIGHBOURHOOD_PX = max(3, HALF_PX // 2)
#: Grey-level standard deviation below which a patch counts as untextured (0..255 scale).
MIN_TEXTURE = 2.0
#: Fraction of the near..far length the matched depth may lie beyond the segment (sub-pixel).
DEPTH_SLACK = 0.02
#: The plane sweep: a new warp of the patch each time the depth grows by this factor, and
#: at most this many warps per match.
SWEEP_RATIO = 1.1
MAX_TEMPLATES = 16
#: A known surface normal is used unless a camera sees the plane this edge-on (cosine), and
#: plane orientations closer than this (cosine) count as one.
EDGE_ON = 0.2
SAME_PLANE = 0.985
#: Matching back from the target view must land this close to the click (px); when the
#: splats' shape warp matched, BACK_MATCH_SHAPE_PX: two matches' sub-pixel errors (0.5-1 px
#: each for a corner's or a pole's shape warp) add up.
BACK_MATCH_PX = 1.0
BACK_MATCH_SHAPE_PX = 1.5
#: With the splats known (a Foreground), the reference patch's pixels are weighted by the
#: foreground's opacity, computed this far (px) about the click; a patch whose weight is
#: FULL_COVER or more of its pixels is matched whole (a surface: nothing to leave out), one
#: with less than MIN_COVER_PX pixels' worth declines (too little of the feature to match).
MASK_REACH_PX = 2 * HALF_PX
FULL_COVER = 0.97
MIN_COVER_PX = 40.0
#: Samples' weight per template pixel that counts as covering it whole (the shape's samples
#: are at half-pixel steps: 4 a pixel where the target view keeps the reference's scale;
#: 2 still covers a view that magnifies by 1.4).
SHAPE_DENSITY = 2.0
#: A shape sample is hidden in the target view when it lies farther than this many pixels'
#: footprints behind the nearest sample at its pixel.
SHAPE_DEPTH_PX = 4.0
#: Iterations and step (px) at which the sub-pixel alignment stops.
ECC_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 30, 1e-4)


@dataclass(frozen=True)
class View:
    """A rendered view: grey image (H, W) float32, window coordinates of its top-left
    corner, and the camera it was rendered with."""

    image: np.ndarray
    origin: FloatArray
    camera: Camera


@dataclass(frozen=True)
class MatchResult:
    """``pixel``: window coordinates in the target view; ``depth_m`` along the reference
    ray (metres); ``score`` the peak NCC, ``second`` the best peak elsewhere on the line."""

    ok: bool
    pixel: FloatArray | None = None
    score: float | None = None
    second: float | None = None
    depth_m: float | None = None
    reason: str | None = None
    plane: FloatArray | None = None     # the plane whose warp matched best; None: the shape

    def to_json(self) -> dict[str, object]:
        return {"ok": self.ok, "pixel": None if self.pixel is None else self.pixel.tolist(),
                "score": self.score, "second": self.second, "depth_m": self.depth_m,
                "reason": self.reason}


def declined(reason: str, score: float | None = None, second: float | None = None
             ) -> MatchResult:
    return MatchResult(False, score=score, second=second, reason=reason)


def clip_segment(p0: FloatArray, p1: FloatArray, lo: FloatArray, hi: FloatArray
                 ) -> tuple[FloatArray, FloatArray] | None:
    """The part of segment p0-p1 inside the box lo..hi (Liang-Barsky); None if none."""
    d = p1 - p0
    t0, t1 = 0.0, 1.0
    for k in range(2):
        for p, q in ((-d[k], p0[k] - lo[k]), (d[k], hi[k] - p0[k])):
            if abs(p) < 1e-12:
                if q < 0:
                    return None
                continue
            r = q / p
            if p < 0:
                t0 = max(t0, r)
            else:
                t1 = min(t1, r)
    if t0 > t1:
        return None
    return p0 + t0 * d, p0 + t1 * d


def plane_homography(ref: Camera, tgt: Camera, point: FloatArray, normal: FloatArray,
                     ref_origin: FloatArray, tgt_origin: FloatArray, at: FloatArray,
                     size: float) -> np.ndarray | None:
    """3 x 3 homography from reference image pixel indices to target image pixel indices
    induced by the plane through ``point`` with ``normal`` (rendered ECEF), fitted on four
    points ``size`` px around ``at`` (reference window coordinates); None when the plane is
    seen edge-on or behind either camera."""
    corners = at + size * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    rays = ref.pick_ray(corners)
    den = rays @ normal
    if np.any(np.abs(den) < 1e-9):
        return None
    t = ((point - ref.position) @ normal) / den
    if np.any(t <= 0):
        return None
    xy, _ = tgt.project(ref.position + t[:, None] * rays)
    if not np.all(np.isfinite(xy)):
        return None
    src = (corners - ref_origin - 0.5).astype(np.float32)
    dst = (xy - tgt_origin - 0.5).astype(np.float32)
    return cv2.getPerspectiveTransform(src, dst).astype(np.float64)


def parabola_offset(a: float, b: float, c: float) -> float:
    """The vertex of the parabola through (-1, a), (0, b), (1, c), within +-0.5."""
    den = a - 2.0 * b + c
    if den >= 0 or not math.isfinite(den):
        return 0.0
    return float(np.clip(0.5 * (a - c) / den, -0.5, 0.5))


def refine(templ: np.ndarray, strip: np.ndarray, col: int, row: int, ds: float, dw: float,
           weights: np.ndarray | None = None) -> tuple[float, float]:
    """Sub-pixel offsets of the template placed at integer (col, row) of the strip, starting
    from the parabola's (ds, dw): the translation that best aligns the two images
    (``cv2.findTransformECC``, enhanced correlation coefficient). The parabola through the
    NCC samples is biased by up to ~0.15 px towards the sample; the alignment is not. Keeps
    the parabola's answer when the alignment fails or leaves the peak's pixel. With
    ``weights`` (the template's foreground) only the template's pixels weighing 1/2 or more
    are aligned."""
    warp = np.array([[1.0, 0.0, col + ds], [0.0, 1.0, row + dw]], dtype=np.float32)
    try:
        everywhere = np.full(strip.shape, 255, dtype=np.uint8)
        if weights is None:
            _, found = cv2.findTransformECC(templ, strip, warp, cv2.MOTION_TRANSLATION,
                                            ECC_CRITERIA, everywhere, 1)
        else:
            used = np.where(weights >= 0.5, 255, 0).astype(np.uint8)
            _, found = cv2.findTransformECCWithMask(templ, strip, used, everywhere, warp,
                                                    cv2.MOTION_TRANSLATION, ECC_CRITERIA, 1)
    except cv2.error:          # not converged (e.g. too little texture): keep the parabola
        return ds, dw
    shift = np.asarray(found, dtype=np.float64)[:, 2]
    ex, ey = float(shift[0]) - col, float(shift[1]) - row
    if abs(ex) <= 1.0 and abs(ey) <= 1.0:
        return ex, ey
    return ds, dw


def depth_samples(near: float, far: float, depth: float) -> FloatArray:
    """Depths (metres along the reference ray) at which the patch is warped: the depth hint
    alone when near..far changes the view's scale by less than SWEEP_RATIO, else a
    geometric series from near to far (a plane sweep; at most MAX_TEMPLATES) with the hint
    in place of its nearest member."""
    lo = max(near, far / 50.0, 1e-3)
    if far <= lo * SWEEP_RATIO:
        return np.array([depth])
    n = int(min(MAX_TEMPLATES, math.ceil(math.log(far / lo) / math.log(SWEEP_RATIO)) + 1))
    out = np.asarray(np.geomspace(lo, far, n), dtype=np.float64)
    out[int(np.argmin(np.abs(np.log(out / max(depth, 1e-3)))))] = depth
    return out


def weighted_std(img: np.ndarray, weights: np.ndarray | None) -> float:
    """The standard deviation of an image's grey levels, each pixel weighted (None: alike)."""
    if weights is None:
        return float(img.std())
    total = float(weights.sum())
    if total <= 0:
        return 0.0
    mean = float((img * weights).sum()) / total
    return math.sqrt(max(float((weights * (img - mean) ** 2).sum()) / total, 0.0))


def reference_weights(ref: View, click: FloatArray, foreground: Foreground) -> np.ndarray:
    """The foreground's opacity (gsgeo.aim.foreground) at each pixel of the reference image
    within MASK_REACH_PX of the click, 0 elsewhere: (H, W) float32 like ``ref.image``."""
    ih, iw = ref.image.shape
    out = np.zeros((ih, iw), dtype=np.float32)
    cx, cy = np.asarray(click, dtype=np.float64) - ref.origin - 0.5
    i0, i1 = max(int(round(cx)) - MASK_REACH_PX, 0), min(int(round(cx)) + MASK_REACH_PX, iw - 1)
    j0, j1 = max(int(round(cy)) - MASK_REACH_PX, 0), min(int(round(cy)) + MASK_REACH_PX, ih - 1)
    if i1 < i0 or j1 < j0:
        return out
    xs = ref.origin[0] + np.arange(i0, i1 + 1) + 0.5
    ys = ref.origin[1] + np.arange(j0, j1 + 1) + 0.5
    out[j0:j1 + 1, i0:i1 + 1] = foreground.opacity(ref.camera, xs, ys)
    return out


@dataclass(frozen=True)
class Shape:
    """The foreground about the click as 3-D samples: ``offsets`` (K, 3) from the click's
    own surface point (rendered ECEF, metres), the reference image's grey ``values`` (K,)
    and their ``weights`` (K,, the foreground's opacity) at half-pixel steps about the
    click; a patch warped by it follows the splats' shape (a corner's faces, a pole's end)
    instead of one plane's."""

    offsets: FloatArray
    values: np.ndarray
    weights: np.ndarray


def reference_shape(ref: View, click: FloatArray, foreground: Foreground) -> Shape | None:
    """The foreground's samples about the click (:class:`Shape`) from its depth per sample
    (gsgeo.aim.foreground's surface), half-pixel steps within MASK_REACH_PX; None when the
    click's own sample has no depth."""
    click = np.asarray(click, dtype=np.float64)
    steps = np.arange(-2 * MASK_REACH_PX, 2 * MASK_REACH_PX + 1) / 2.0
    xs, ys = click[0] + steps, click[1] + steps
    op, z = foreground.surface(ref.camera, xs, ys)
    c = steps.size // 2
    z_click = z[c, c]
    if not math.isfinite(z_click):
        return None
    gx, gy = np.meshgrid(xs, ys)
    use = (op >= 0.5) & np.isfinite(z)
    px = np.stack([gx[use], gy[use]], axis=1)
    rays = ref.camera.pick_ray(px)
    pts = ref.camera.position + (z[use] / (rays @ ref.camera.direction))[:, None] * rays
    ray_c = ref.camera.pick_ray(click)[0]
    at_click = ref.camera.position + z_click / float(ray_c @ ref.camera.direction) * ray_c
    img = ref.image
    sx = (px[:, 0] - ref.origin[0] - 0.5).astype(np.float32)
    sy = (px[:, 1] - ref.origin[1] - 0.5).astype(np.float32)
    values = cv2.remap(img, sx[None, :], sy[None, :], cv2.INTER_LINEAR,
                       borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)[0]
    inside = values >= 0
    return Shape(pts[inside] - at_click, values[inside].astype(np.float64),
                 op[use][inside].astype(np.float64))


def shape_patch(tgt: View, strip_from_target: np.ndarray, origin: FloatArray,
                ray: FloatArray, t: float, shape: Shape
                ) -> tuple[np.ndarray, np.ndarray, float] | str:
    """The reference patch as the target view would show it in the strip frame if the
    click's surface point lay at depth ``t`` on the reference ray and the foreground about it
    had the splats' shape: the samples of ``shape`` moved there, projected into the target
    and splatted bilinearly into a 2 HALF_PX + 1 square about the click's projection; the
    template, its weights (how much of each pixel the samples cover, 0..1) and the strip
    column of its centre. A decline reason when the point does not project."""
    h = HALF_PX
    at = origin + t * ray
    xy, zt = tgt.camera.project(np.vstack([at[None], at + shape.offsets]))
    if not np.all(np.isfinite(xy[0])):
        return "outside the view: the click does not map into the target view"
    ok = np.all(np.isfinite(xy), axis=1)
    ij = np.c_[xy - tgt.origin - 0.5, np.ones(len(xy))] @ strip_from_target.T
    ij = ij[:, :2] / ij[:, 2:]
    c = ij[0]
    q = ij[1:] - c + h
    ok = ok[1:] & (q[:, 0] > -1) & (q[:, 0] < 2 * h + 1) & (q[:, 1] > -1) & (q[:, 1] < 2 * h + 1)
    q, val, w, zt = q[ok], shape.values[ok], shape.weights[ok], zt[1:][ok]
    n = 2 * h + 1
    # what the target sees: per template pixel only the samples near the nearest one (a
    # face turned away from the target lies behind the others there)
    near = np.clip(np.rint(q).astype(np.int64), 0, n - 1)
    cell = near[:, 1] * n + near[:, 0]
    front = np.full(n * n, np.inf)
    np.minimum.at(front, cell, zt)
    seen = zt <= front[cell] + SHAPE_DEPTH_PX * tgt.camera.ifov * zt
    q, val, w = q[seen], val[seen], w[seen]
    acc_w = np.zeros(n * n)
    acc_v = np.zeros(n * n)
    base = np.floor(q).astype(np.int64)
    frac = q - base
    for dx, dy in ((0, 0), (1, 0), (0, 1), (1, 1)):
        bx, by = base[:, 0] + dx, base[:, 1] + dy
        k = (np.abs(1 - dx - frac[:, 0])) * (np.abs(1 - dy - frac[:, 1])) * w
        inside = (bx >= 0) & (bx < n) & (by >= 0) & (by < n)
        flat = by[inside] * n + bx[inside]
        acc_w += np.bincount(flat, weights=k[inside], minlength=n * n)
        acc_v += np.bincount(flat, weights=k[inside] * val[inside], minlength=n * n)
    weight = acc_w.reshape(n, n)
    with np.errstate(invalid="ignore", divide="ignore"):
        templ = np.where(weight > 1e-6, acc_v.reshape(n, n) / weight, 0.0).astype(np.float32)
    # half-pixel samples: about 4 per covered pixel when the view keeps the scale
    tmask = np.clip(weight / SHAPE_DENSITY, 0.0, 1.0).astype(np.float32)
    tmask[tmask < 0.25] = 0.0
    weak = patch_too_weak(templ, tmask)
    return weak if weak is not None else (templ, tmask, float(c[0]))


def patch_too_weak(templ: np.ndarray, tmask: np.ndarray | None) -> str | None:
    """Why a warped patch (and its weights, None: all 1) cannot be matched: too few weighted
    pixels or no texture under them; None when it can."""
    if tmask is not None and float(tmask.sum()) < MIN_COVER_PX:
        return (f"weak: the feature covers {float(tmask.sum()):.0f} px of the patch around "
                f"the click, below {MIN_COVER_PX:.0f}")
    if weighted_std(templ, tmask) < MIN_TEXTURE:
        return "weak: no texture around the click to match"
    return None


def warped_patch(ref: View, tgt: View, strip_from_target: np.ndarray, origin: FloatArray,
                 ray: FloatArray, t: float, normal: FloatArray, click: FloatArray,
                 weights: np.ndarray | None = None
                 ) -> tuple[np.ndarray, np.ndarray | None, float] | str:
    """The reference patch around the click as the target view would show it in the strip
    frame if the feature lay at depth ``t`` on the plane with ``normal`` (2 HALF_PX + 1
    square, the click at its centre), its pixels' weights (``weights``, the reference
    image's, warped alike; None without) and the strip column of that centre; a decline
    reason instead when the plane or patch does not map or too little of it weighs."""
    h = HALF_PX
    hom = plane_homography(ref.camera, tgt.camera, origin + t * ray, normal,
                           ref.origin, tgt.origin, click, 2.0 * h)
    if hom is None:
        return "outside the view: the depth hint's plane is not seen by both views"
    strip_from_ref = strip_from_target @ hom
    cx, cy = click - ref.origin - 0.5
    c = strip_from_ref @ np.array([cx, cy, 1.0])
    if abs(c[2]) < 1e-12:
        return "outside the view: the click does not map into the target view"
    c = c[:2] / c[2]
    shift = np.array([[1.0, 0.0, c[0] - h], [0.0, 1.0, c[1] - h], [0.0, 0.0, 1.0]])
    back = np.linalg.inv(strip_from_ref) @ shift
    templ = cv2.warpPerspective(ref.image, back, (2 * h + 1, 2 * h + 1),
                                flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                borderMode=cv2.BORDER_CONSTANT, borderValue=-1.0)
    if float(templ.min()) < 0.0:
        return "outside the view: the warped patch reaches beyond the reference image"
    tmask = None
    if weights is not None:
        tmask = cv2.warpPerspective(weights, back, (2 * h + 1, 2 * h + 1),
                                    flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                                    borderMode=cv2.BORDER_CONSTANT, borderValue=0.0)
    weak = patch_too_weak(templ, tmask)
    return weak if weak is not None else (templ, tmask, float(c[0]))


@dataclass(frozen=True)
class Sweep:
    """The NCC of the strip against the patch warped for each depth of the sweep on one plane
    orientation: ``score`` (rows: offsets from the line, columns along it), the warped
    patches and their weights (None: alike) and, per column, the patch that scored it."""

    score: np.ndarray
    templates: list[np.ndarray]
    owner: np.ndarray
    masks: list[np.ndarray | None]

    @property
    def peak(self) -> float:
        return float(self.score.max())


def sweep(ref: View, tgt: View, strip: np.ndarray, strip_from_target: np.ndarray,
          origin: FloatArray, ray: FloatArray, normal: FloatArray | None, click: FloatArray,
          depths: FloatArray, weights: np.ndarray | None = None, shape: Shape | None = None
          ) -> Sweep | str:
    """NCC along the strip of the patch warped for each depth on planes with ``normal``
    (each warp scores the columns nearest its depth's own); a reason when no warp maps (a
    depth whose plane maps the patch beyond the reference image, e.g. one very close to the
    target camera, is left out and its columns go to the nearest depth that maps)."""
    h = HALF_PX
    templates, masks, columns, reasons = [], [], [], []
    for t in depths.tolist():
        got = (shape_patch(tgt, strip_from_target, origin, ray, t, shape)
               if normal is None and shape is not None else
               warped_patch(ref, tgt, strip_from_target, origin, ray, t,
                            normal if normal is not None else -ref.camera.direction, click,
                            weights))
        if isinstance(got, str):
            reasons.append(got)
            continue
        templates.append(got[0])
        masks.append(got[1])
        columns.append(got[2] - h)                      # score column of that depth
    if not templates:
        return reasons[0]
    n_cols = strip.shape[1] - 2 * h
    owner = np.abs(np.arange(n_cols)[:, None] - np.array(columns)[None, :]).argmin(axis=1)
    score = np.full((strip.shape[0] - 2 * h, n_cols), -1.0, dtype=np.float32)
    for j in np.unique(owner).tolist():
        cols = np.flatnonzero(owner == j)
        c0, c1 = int(cols[0]), int(cols[-1])
        if masks[j] is None:
            part = cv2.matchTemplate(strip[:, c0:c1 + 2 * h + 1], templates[j],
                                     cv2.TM_CCOEFF_NORMED)
        else:
            part = cv2.matchTemplate(strip[:, c0:c1 + 2 * h + 1], templates[j],
                                     cv2.TM_CCOEFF_NORMED, mask=masks[j])
        score[:, c0:c1 + 1] = np.where(owner[c0:c1 + 1] == j, part, score[:, c0:c1 + 1])
    return Sweep(np.nan_to_num(np.clip(score, -1.0, 1.0), nan=-1.0), templates, owner, masks)


def plane_normals(ref: Camera, tgt: Camera, point: FloatArray, normal: FloatArray | None
                  ) -> list[FloatArray]:
    """The plane orientations tried: the surface normal when known (and not seen edge-on by
    either camera), the level plane (the local up at ``point``, unless seen edge-on), the
    plane parallel to the reference image, and the plane facing both
    cameras alike (normal along the bisector of the two lines of sight, the least distortion
    for a wide baseline whose surface is unknown); near-duplicates dropped."""
    to_ref = ref.position - point
    to_tgt = tgt.position - point
    to_ref, to_tgt = to_ref / np.linalg.norm(to_ref), to_tgt / np.linalg.norm(to_tgt)
    out: list[FloatArray] = []
    if normal is not None:
        n = np.asarray(normal, dtype=np.float64)
        n = n / np.linalg.norm(n)
        n = n if n @ to_ref >= 0 else -n
        if n @ to_ref > EDGE_ON and n @ to_tgt > EDGE_ON:
            out.append(n)
    bisector = to_ref + to_tgt
    level = local_axes(point)[2]
    for n in (level, -ref.direction, bisector / max(float(np.linalg.norm(bisector)), 1e-12)):
        if n is level and not (n @ to_ref > EDGE_ON and n @ to_tgt > EDGE_ON):
            continue
        if all(float(n @ m) < SAME_PLANE for m in out):
            out.append(np.asarray(n, dtype=np.float64))
    return out


def match_feature(ref: View, click: FloatArray, tgt: View, near: float, far: float,
                  depth: float, normal: FloatArray | None = None,
                  foreground: Foreground | None = None) -> MatchResult:
    """The click of the reference view found in the target view (module docstring), and
    confirmed by matching back: the patch around the match, searched for in the reference
    view along the target ray's segment over the same stretch of space, must lead back to
    within BACK_MATCH_PX (BACK_MATCH_SHAPE_PX when the splats' shape warp won) of the click (a wrong
    match on repetitive or confusing structure seldom does); otherwise declined as
    inconsistent.

    ``click``: reference window coordinates; ``near``, ``far``, ``depth``: metres along the
    reference ray (near <= depth <= far); ``normal``: the surface's normal there (rendered
    ECEF, any length; either sign) when known; ``foreground``: the splats about the
    feature (gsgeo.aim.foreground), when known: each patch's pixels are weighted by their
    opacity, so the background around an object's outline does not enter the match."""
    there = match_one_way(ref, click, tgt, near, far, depth, normal, foreground=foreground)
    if not there.ok or there.pixel is None or there.depth_m is None:
        return there
    o, d = ref.camera.position, ref.camera.pick_ray(click)[0]
    c = tgt.camera.position
    d_back = tgt.camera.pick_ray(there.pixel)[0]
    t_back = closest_on_first(c, d_back, o, d)
    if not (math.isfinite(t_back) and t_back > 0):
        t_back = float(np.linalg.norm(o + there.depth_m * d - c))
    # the target ray's segment as long each side of the match as the reference one is (the
    # distances from the target camera to the ends of the reference segment would collapse
    # to a few millimetres when the two rays are perpendicular, and matching back declined)
    back = match_one_way(tgt, there.pixel, ref,
                         max(t_back - (there.depth_m - near), 1e-3),
                         t_back + (far - there.depth_m), t_back, there.plane, only_normal=True,
                         foreground=foreground)
    if not back.ok or back.pixel is None:
        return declined(f"inconsistent: matching back from the target view fails "
                        f"({back.reason})", there.score, there.second)
    miss = float(np.linalg.norm(back.pixel - click))
    if miss > (BACK_MATCH_SHAPE_PX if there.plane is None else BACK_MATCH_PX):
        return declined(f"inconsistent: matching back lands {miss:.1f} px from the click",
                        there.score, there.second)
    return there


def match_one_way(ref: View, click: FloatArray, tgt: View, near: float, far: float,
                  depth: float, normal: FloatArray | None = None, only_normal: bool = False,
                  foreground: Foreground | None = None) -> MatchResult:
    """The click of the reference view found in the target view, one way (module docstring);
    with ``only_normal`` the patch is warped by the plane of ``normal`` alone (matching
    back, on the plane the way there found); with ``foreground`` the patch's pixels are
    weighted by its opacity (unless it covers FULL_COVER of the patch or more).

    ``click``: reference window coordinates; ``near``, ``far``, ``depth``: metres along the
    reference ray (near <= depth <= far); ``normal``: the surface's normal there (rendered
    ECEF, any length; either sign) when known."""
    h, b = HALF_PX, BAND_PX
    click = np.asarray(click, dtype=np.float64)
    o = ref.camera.position
    d = ref.camera.pick_ray(click)[0]
    # the patch around the click, as the reference view shows it
    cx, cy = click - ref.origin - 0.5
    ih, iw = ref.image.shape
    i0, j0 = int(round(cx)) - h, int(round(cy)) - h
    if i0 < 0 or j0 < 0 or i0 + 2 * h >= iw or j0 + 2 * h >= ih:
        return declined("outside the view: the patch around the click reaches beyond the "
                        "reference image")
    # the splats about the click: their shape, and the weights of the patch's pixels; none
    # when the click's own sample shows none of them (the weights alone, with the planes'
    # warps only, matched the ground beside corners: points 10 cm off on the demo)
    weights, shape = None, None
    if foreground is not None and foreground.count > 0:
        shape = reference_shape(ref, click, foreground)
    if shape is not None and foreground is not None:
        weights = reference_weights(ref, click, foreground)
        if float(weights[j0:j0 + 2 * h + 1, i0:i0 + 2 * h + 1].mean()) >= FULL_COVER:
            weights = None
    if weighted_std(ref.image[j0:j0 + 2 * h + 1, i0:i0 + 2 * h + 1],
                    None if weights is None else weights[j0:j0 + 2 * h + 1, i0:i0 + 2 * h + 1]
                    ) < MIN_TEXTURE:
        return declined("weak: no texture around the click to match")
    # the epipolar segment in the target image, where the whole template fits
    seg = tgt.camera.epipolar_segment(o, d, near, far)
    if seg is None:
        return declined("outside the view: the segment where the feature can lie is behind "
                        "the target camera")
    th, tw = tgt.image.shape
    reach = h * math.sqrt(2.0) + b + 2.0
    lo = np.array([reach, reach]) - 0.5
    hi = np.array([tw - 1 - reach, th - 1 - reach]) + 0.5
    clipped = clip_segment(seg[0] - tgt.origin - 0.5, seg[1] - tgt.origin - 0.5, lo, hi)
    if clipped is None:
        return declined("outside the view: the segment where the feature can lie is not in "
                        "the target image")
    p0, p1 = clipped
    length = float(np.linalg.norm(p1 - p0))
    u = (p1 - p0) / length if length > 1e-6 else np.array([1.0, 0.0])
    v = np.array([-u[1], u[0]])
    # strip frame: (x, y) -> image p0 + (x - h - ext) u + (y - h - b - ext) v
    ext = 1                                             # one more pixel all round for the fit
    a = np.array([[u[0], v[0], p0[0] - (h + ext) * u[0] - (h + b + ext) * v[0]],
                  [u[1], v[1], p0[1] - (h + ext) * u[1] - (h + b + ext) * v[1]],
                  [0.0, 0.0, 1.0]])
    n_s = int(math.floor(length)) + 1
    strip_w, strip_h = n_s + 2 * (h + ext), 2 * (h + b + ext) + 1
    strip = cv2.warpAffine(tgt.image, a[:2], (strip_w, strip_h),
                           flags=cv2.INTER_LINEAR | cv2.WARP_INVERSE_MAP,
                           borderMode=cv2.BORDER_REPLICATE)
    # the patch warped for each depth of the sweep and each plane orientation tried; the
    # orientation whose warp matches best is kept
    strip_from_target = np.linalg.inv(a)
    depths = depth_samples(near, far, depth)
    planes: list[FloatArray | None] = list(
        plane_normals(ref.camera, tgt.camera, o + depth * d, normal))
    if shape is not None:
        planes.append(None)                    # the splats' own shape about the click
    if only_normal:
        planes = ([None] if shape is not None else planes[:1]) if normal is None \
            else planes[:1]
    tried = [(n, sweep(ref, tgt, strip, strip_from_target, o, d, n, click, depths, weights,
                       shape)) for n in planes]
    found = [(n, sw) for n, sw in tried if isinstance(sw, Sweep)]
    if not found:
        return declined(next(sw for _, sw in tried if isinstance(sw, str)))
    normal_used, best = max(found, key=lambda item: item[1].peak)
    score, templates, owner, masks = best.score, best.templates, best.owner, best.masks
    # rows: offsets -(b+ext)..(b+ext) from the line; columns: -ext..n_s-1+ext along it
    inner = score[ext:ext + 2 * b + 1, ext:ext + n_s]
    w_pk, s_pk = (int(v) for v in np.unravel_index(int(np.argmax(inner)), inner.shape))
    peak = float(inner[w_pk, s_pk])
    along = inner.max(axis=0)
    far_off = np.abs(np.arange(n_s) - s_pk) > NEIGHBOURHOOD_PX
    second = float(along[far_off].max()) if far_off.any() else -1.0
    if peak < MIN_SCORE:
        return declined(f"weak: the best match scores {peak:.2f} (NCC), below {MIN_SCORE}",
                        peak, second)
    # other local maxima along the line that are nearly as high
    left = np.concatenate([[-2.0], along[:-1]])
    right = np.concatenate([along[1:], [-2.0]])
    rivals = far_off & (along >= left) & (along > right) & (along >= AMBIGUOUS_RATIO * peak)
    if int(rivals.sum()) >= REPEATS:
        return declined(f"repeated texture along the epipolar line: {int(rivals.sum()) + 1} "
                        f"peaks of NCC {AMBIGUOUS_RATIO * peak:.2f} or more", peak, second)
    if second >= AMBIGUOUS_RATIO * peak:
        return declined(f"ambiguous: a second peak of {second:.2f} against {peak:.2f}",
                        peak, second)
    rw, rs = w_pk + ext, s_pk + ext
    ds = parabola_offset(score[rw, rs - 1], score[rw, rs], score[rw, rs + 1])
    dw = parabola_offset(score[rw - 1, rs], score[rw, rs], score[rw + 1, rs])
    # the sub-pixel alignment with the patch warped for the depth the peak itself lies at
    templ, tmask = templates[int(owner[rs])], masks[int(owner[rs])]
    coarse = p0 + (s_pk + ds) * u + (w_pk - b + dw) * v + tgt.origin + 0.5
    t_pk = closest_on_first(o, d, tgt.camera.position, tgt.camera.pick_ray(coarse)[0])
    if math.isfinite(t_pk) and t_pk > 0:
        got = (shape_patch(tgt, strip_from_target, o, d, t_pk, shape)
               if normal_used is None and shape is not None else
               warped_patch(ref, tgt, strip_from_target, o, d, t_pk,
                            normal_used if normal_used is not None else -ref.camera.direction,
                            click, weights))
        templ, tmask = (templ, tmask) if isinstance(got, str) else (got[0], got[1])
    ds, dw = refine(templ, strip, rs, rw, ds, dw, tmask)
    s, w = s_pk + ds, w_pk - b + dw
    img_pt = p0 + s * u + w * v
    pixel = img_pt + tgt.origin + 0.5
    t = closest_on_first(o, d, tgt.camera.position, tgt.camera.pick_ray(pixel)[0])
    slack = DEPTH_SLACK * (far - near)
    if not (math.isfinite(t) and near - slack <= t <= far + slack) or abs(w) > b:
        return declined("off the segment: the best match does not lie on the segment where "
                        "the feature can be", peak, second)
    return MatchResult(True, pixel, peak, second, float(t), None, normal_used)
