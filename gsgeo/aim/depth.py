"""Where along a ray the splats are: the depth hint of a click and the near/far bounds of the
segment the clicked feature can lie on.

Each splat near the ray is evaluated where its Gaussian is densest along the ray (exactly:
the minimum Mahalanobis distance of a 3-D Gaussian along a line), dilated by a fraction of
the pixel footprint as 3DGS rasterisers low-pass each splat; the splats are then composited
front to back like the renderer does (alpha = opacity x exp(-m^2 / 2), transmittance the
product of 1 - alpha in front). The depth hint is where the accumulated opacity passes 1/2
(the surface the pixel shows); near and far bracket where it rises from 2 % to 98 % of its
final value, widened by two standard deviations of the splats there along the ray.

Everything is vectorised over the splats (numpy); no Python loop over splats.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.aim.splatindex import SplatIndex
from gsgeo.crs.modelmatrix import apply_directions, apply_points, invert_affine
from gsgeo.solve.linalg import FloatArray

#: Accumulated opacity at which a ray counts as hitting the scene (the median of what the
#: pixel shows then lies on splats).
HIT_OPACITY = 0.5
#: Alpha below which a splat does not count (one 8-bit grey level, as renderers skip it).
MIN_ALPHA = 1.0 / 255.0
#: 3DGS rasterisers clip a splat's alpha here.
MAX_ALPHA = 0.99
#: Standard deviation of the pixel's low-pass filter, in pixels (3DGS adds 0.3 px^2).
PIXEL_FILTER_PX = 0.55
#: The near/far bounds span accumulated opacity from LOW to HIGH of its final value.
BOUND_LOW, BOUND_HIGH = 0.02, 0.98
#: Widening of near and far in splat standard deviations along the ray, and relatively.
BOUND_SIGMAS = 2.0
BOUND_RELATIVE = 0.01
SKY = "no splat along this ray (sky?)"
#: A surface normal is given when the splats making the pixel are this flat on average and
#: their normals' weighted resultant is at least this long (1: all alike).
NORMAL_FLATNESS = 0.5
NORMAL_AGREEMENT = 0.7


@dataclass(frozen=True)
class RayProfile:
    """The splats along one ray, front to back (tileset frame, metres along the unit ray).

    t : (K,) depth of each splat's densest point; sigma_t : (K,) its standard deviation
    along the ray; alpha : (K,) its alpha there; weight : (K,) its share of the pixel
    (alpha x transmittance in front of it); normals : (K, 3) unit, the splat's thinnest axis
    turned towards the ray's origin; flatness : (K,) 1 - thinnest / widest sigma (0 a ball,
    1 a disc)."""

    t: FloatArray
    sigma_t: FloatArray
    alpha: FloatArray
    weight: FloatArray
    normals: FloatArray
    flatness: FloatArray

    @property
    def opacity(self) -> float:
        """Accumulated opacity of the whole ray, 0..1."""
        return float(self.weight.sum())


@dataclass(frozen=True)
class DepthHint:
    """The answer of :func:`depth_hint`; lengths along the ray (rendered frame, metres),
    ``point`` in rendered ECEF. ``reason`` says why ``hit`` is False."""

    hit: bool
    depth_m: float | None
    point: FloatArray | None
    near_m: float | None
    far_m: float | None
    n_splats: int
    reason: str | None
    normal: FloatArray | None = None

    def to_json(self) -> dict[str, object]:
        return {"hit": self.hit, "depth_m": self.depth_m,
                "point_ecef": None if self.point is None else self.point.tolist(),
                "near_m": self.near_m, "far_m": self.far_m, "n_splats": self.n_splats,
                "reason": self.reason,
                "normal_ecef": None if self.normal is None else self.normal.tolist()}


def near_ray(index: SplatIndex, origin: FloatArray, direction: FloatArray,
             ifov: float | None, t_max: float | None = None) -> np.ndarray:
    """Indices of the splats whose reach (EXTENT_SIGMAS, plus the pixel filter) touches the
    ray from ``origin`` along unit ``direction`` (tileset ECEF), in front of the origin and,
    with ``t_max``, before that distance. The index's blocks the ray misses are skipped."""
    o64 = np.asarray(origin, dtype=np.float64) - index.centre
    spread = 3.0 * PIXEL_FILTER_PX * ifov if ifov else 0.0
    cand = index.gather(index.blocks_near_ray(o64, direction, spread, t_max))
    o = o64.astype(np.float32)
    d = np.asarray(direction, dtype=np.float32)
    x, y, z = index.offsets[:, cand]
    vx, vy, vz = x - o[0], y - o[1], z - o[2]
    t = vx * d[0] + vy * d[1] + vz * d[2]
    d2 = vx * vx + vy * vy + vz * vz - t * t
    reach = index.reach[cand]
    if ifov:
        reach = reach + np.float32(spread) * np.maximum(t, 0)
    keep = (d2 < reach * reach) & (t > -reach)
    if t_max is not None:
        keep &= t < t_max + reach
    return cand[keep]


def ray_profile(index: SplatIndex, origin: FloatArray, direction: FloatArray,
                ifov: float | None, t_max: float | None = None) -> RayProfile:
    """The splats along a ray (tileset ECEF origin, unit direction), composited front to back;
    with ``t_max`` only the part of the ray before that distance (metres)."""
    idx = near_ray(index, origin, direction, ifov, t_max)
    d = np.asarray(direction, dtype=np.float64)
    rel = np.asarray(origin, dtype=np.float64) - index.centre - index.offsets[:, idx].T
    rot = index.rotations[idx].astype(np.float64)                      # splat axes -> ECEF
    a = np.einsum("nji,nj->ni", rot, rel)                              # origin, splat axes
    b = np.einsum("nji,j->ni", rot, d)                                 # direction, splat axes
    s2 = index.sigmas[idx].astype(np.float64) ** 2
    if ifov:
        tc = -(rel @ d)                                                # centre's depth
        s2 = s2 + ((PIXEL_FILTER_PX * ifov) * np.maximum(tc, 0.0))[:, None] ** 2
    bb = np.einsum("ni,ni->n", b, b / s2)
    ab = np.einsum("ni,ni->n", a, b / s2)
    aa = np.einsum("ni,ni->n", a, a / s2)
    t = -ab / bb
    m2 = np.maximum(aa - ab * ab / bb, 0.0)   # Mahalanobis distance^2 at t
    alpha = np.minimum(index.alpha[idx].astype(np.float64) * np.exp(-0.5 * m2), MAX_ALPHA)
    keep = (alpha >= MIN_ALPHA) & (t > 0)
    if t_max is not None:
        keep &= t < t_max
    t, alpha, sigma_t = t[keep], alpha[keep], 1.0 / np.sqrt(bb[keep])
    order = np.argsort(t, kind="stable")
    t, alpha, sigma_t = t[order], alpha[order], sigma_t[order]
    trans = np.cumprod(np.concatenate([[1.0], 1.0 - alpha]))[:-1]
    sig = index.sigmas[idx][keep][order]
    thin = sig.argmin(axis=1)
    normals = np.take_along_axis(rot[keep][order], thin[:, None, None], axis=2)[:, :, 0]
    normals = normals * -np.sign(normals @ d + 1e-300)[:, None]      # facing the origin
    flatness = 1.0 - sig.min(axis=1) / sig.max(axis=1)
    return RayProfile(t, sigma_t, alpha, alpha * trans, normals, flatness.astype(np.float64))


def surface_normal(profile: RayProfile) -> FloatArray | None:
    """The surface's unit normal where the ray meets it (facing the ray's origin): the mean of
    the thinnest axes of the splats making the pixel, each weighted by its share and its
    flatness; None when they do not agree (resultant below NORMAL_AGREEMENT) or are not flat
    (round splats have no normal)."""
    w = profile.weight * profile.flatness
    total = float(w.sum())
    if total <= 0 or float(profile.weight @ profile.flatness) < NORMAL_FLATNESS * \
            float(profile.weight.sum()):
        return None
    n = w @ profile.normals
    length = float(np.linalg.norm(n))
    if length < NORMAL_AGREEMENT * total:
        return None
    return np.asarray(n / length, dtype=np.float64)


def depth_along(profile: RayProfile) -> tuple[float, float, float] | None:
    """(depth, near, far) along the ray (metres) of a profile, None when the ray does not
    accumulate HIT_OPACITY."""
    total = profile.opacity
    if total < HIT_OPACITY or profile.t.size == 0:
        return None
    cum = np.cumsum(profile.weight)
    i = int(np.searchsorted(cum, 0.5))
    if i == 0:   # the first splat alone makes the pixel: its densest point
        depth = float(profile.t[0])
    else:        # between the splats before and at which the opacity passes 1/2
        frac = (0.5 - cum[i - 1]) / max(cum[i] - cum[i - 1], 1e-12)
        depth = float(profile.t[i - 1] + frac * (profile.t[i] - profile.t[i - 1]))
    lo = int(np.searchsorted(cum, BOUND_LOW * total))
    hi = min(int(np.searchsorted(cum, BOUND_HIGH * total)), cum.size - 1)
    pad = BOUND_RELATIVE * depth
    near = float(profile.t[lo] - BOUND_SIGMAS * profile.sigma_t[lo]) - pad
    far = float(profile.t[hi] + BOUND_SIGMAS * profile.sigma_t[hi]) + pad
    return depth, max(min(near, depth), 0.0), max(far, depth)


def depth_hint(index: SplatIndex, origin: FloatArray, direction: FloatArray,
               ifov: float | None = None, model_matrix: FloatArray | None = None) -> DepthHint:
    """The depth hint of a ray given in rendered ECEF (origin, any-length direction, the
    modelMatrix (4, 4) it was taken under or None for identity; ifov radians per pixel or
    None): the ray is carried into the tileset's ECEF by the matrix's inverse, queried, and
    the answer carried back (lengths along the rendered ray, metres)."""
    o_r = np.asarray(origin, dtype=np.float64)
    d_r = np.asarray(direction, dtype=np.float64)
    d_r = d_r / np.linalg.norm(d_r)
    if model_matrix is None:
        m = None
        o_t, d_t = o_r, d_r
    else:
        m = np.asarray(model_matrix, dtype=np.float64)
        inv = invert_affine(m)
        o_t, d_t = apply_points(inv, o_r), apply_directions(inv, d_r)
    prof = ray_profile(index, o_t, d_t, ifov)
    found = depth_along(prof)
    if found is None:
        reason = SKY if prof.t.size == 0 else \
            f"{SKY}: the splats along it add up to opacity {prof.opacity:.2f} only"
        return DepthHint(False, None, None, None, None, int(prof.t.size), reason)

    def rendered(t: float) -> float:
        p = o_t + t * d_t
        return float((apply_points(m, p) - o_r) @ d_r) if m is not None else t

    depth, near, far = (rendered(v) for v in found)
    point = o_r + depth * d_r
    normal = surface_normal(prof)
    if normal is not None and m is not None:
        normal = apply_directions(np.linalg.inv(m[:3, :3]).T, normal)   # normals: inverse transpose
    return DepthHint(True, depth, point, near, far, int(prof.t.size), None, normal)
