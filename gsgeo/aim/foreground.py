"""Which pixels of a view show the clicked feature itself, and which its background: the
splats near the feature's provisional 3-D point, projected into the view.

A feature on an object's outline (an eaves corner, a pole top) has, in a patch around it,
as much background as object: sky, a roof, the ground metres behind. The background moves
against the feature from view to view (parallax) and is a different thing in a view far
from the click, so a patch matcher that compares it too declines or errs. The server holds
the splats, so it knows which pixels show the feature's surroundings: those covered by the
splats within a ball about the provisional point (gsgeo.aim.depth's hint). The opacity of
those splats alone, per pixel, is the weight of that pixel in the match (gsgeo.aim.match).

Each splat is projected like a 3DGS rasteriser does (EWA: the 3-D covariance through the
projection's Jacobian at its centre, plus the pixel's low-pass filter of 0.3 px^2), its
alpha at a pixel a x exp(-q / 2), and the foreground opacity of the pixel
1 - prod(1 - alpha) over the ball's splats (order-independent: splats in front of the point
but outside the ball, which the view would show instead, are not counted; the reference
view sees the point, so there are none worth counting near the click).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.aim.camera import Camera
from gsgeo.aim.splatindex import SplatIndex
from gsgeo.crs.modelmatrix import apply_points, invert_affine
from gsgeo.solve.linalg import FloatArray

#: The ball's radius in pixels of the reference view at the point (a patch of the matcher
#: is 2 x 12 + 1 px across, so this reaches a little beyond its corners).
BALL_PX = 25.0
#: 3DGS rasterisers' low-pass filter added to every projected covariance, px^2.
PIXEL_FILTER_PX2 = 0.3
#: Alpha below which a splat leaves a pixel alone, and the most a splat covers.
MIN_ALPHA = 1.0 / 255.0
MAX_ALPHA = 0.99
#: A splat is evaluated on the pixels within this many standard deviations of its centre.
STAMP_SIGMAS = 3.5
#: Splats per chunk, composited front to back chunk by chunk.
CHUNK_SPLATS = 64


@dataclass(frozen=True)
class Foreground:
    """The splats within ``radius_m`` of ``point`` (both rendered ECEF, metres): centres
    (N, 3) rendered ECEF, covariances (N, 3, 3) m^2 in rendered ECEF, alpha (N,) 0..1."""

    point: FloatArray
    radius_m: float
    centres: FloatArray
    covariances: FloatArray
    alpha: FloatArray

    @property
    def count(self) -> int:
        return int(self.alpha.shape[0])

    @classmethod
    def near(cls, index: SplatIndex, point: FloatArray, radius_m: float,
             model_matrix: FloatArray | None = None) -> Foreground:
        """The splats of ``index`` whose centre lies within ``radius_m`` (metres) of
        ``point`` (rendered ECEF); ``model_matrix`` (4, 4) carries the tileset's ECEF into
        the rendered one (None: identity)."""
        p = np.asarray(point, dtype=np.float64).reshape(3)
        m = None if model_matrix is None else np.asarray(model_matrix, dtype=np.float64)
        p_t = p if m is None else apply_points(invert_affine(m), p)
        lin = np.eye(3) if m is None else m[:3, :3]
        # the radius in the tileset's frame (a scaled modelMatrix shrinks or grows it)
        r_t = float(radius_m) / max(float(np.cbrt(abs(np.linalg.det(lin)))), 1e-12)
        mid, rad = index.block_spheres
        rel = p_t - index.centre
        blocks = np.flatnonzero(np.linalg.norm(mid - rel, axis=1) <= rad + r_t)
        cand = index.gather(blocks)
        off = index.offsets[:, cand].T.astype(np.float64)
        keep = cand[np.linalg.norm(off - rel, axis=1) <= r_t]
        centres = index.centre + index.offsets[:, keep].T.astype(np.float64)
        rot = index.rotations[keep].astype(np.float64)
        s2 = index.sigmas[keep].astype(np.float64) ** 2
        cov = np.einsum("nij,nj,nkj->nik", rot, s2, rot)
        if m is not None:
            centres = apply_points(m, centres)
            cov = np.einsum("ij,njk,lk->nil", lin, cov, lin)
        return cls(p, float(radius_m), np.asarray(centres).reshape(-1, 3), cov,
                   index.alpha[keep].astype(np.float64))

    def opacity(self, camera: Camera, xs: FloatArray, ys: FloatArray) -> np.ndarray:
        """The foreground opacity (len(ys), len(xs)) float32, 0..1, at the pixels whose
        centres are at window coordinates (xs[i], ys[j]) (CSS px) in ``camera``'s view."""
        return self.surface(camera, xs, ys)[0]

    def surface(self, camera: Camera, xs: FloatArray, ys: FloatArray
                ) -> tuple[np.ndarray, np.ndarray]:
        """The foreground opacity (as :meth:`opacity`) and the depth of the foreground there
        (len(ys), len(xs)) float64: metres along the camera's axis, the mean of the splats'
        centre depths weighted by their share of the pixel (alpha times the transmittance of
        the splats in front, composited front to back as the renderer does: what the view
        shows, not the faces behind it); NaN where no splat reaches."""
        xs = np.asarray(xs, dtype=np.float64).reshape(-1)
        ys = np.asarray(ys, dtype=np.float64).reshape(-1)
        log_clear = np.zeros((ys.size, xs.size), dtype=np.float64)
        if self.count == 0 or xs.size == 0 or ys.size == 0:
            return log_clear.astype(np.float32), np.full(log_clear.shape, np.nan)
        rel = self.centres - camera.position
        z = rel @ camera.direction
        x = rel @ camera.right
        y = rel @ camera.up
        front = z > 1e-3
        f = camera.focal_px
        z, x, y = z[front], x[front], y[front]
        cov, alpha = self.covariances[front], self.alpha[front]
        u = camera.width / 2 + f * x / z
        v = camera.height / 2 - f * y / z
        # Jacobian of (u, v) with respect to the point, rendered ECEF
        ju = f * (camera.right[None, :] / z[:, None]
                  - (x / z**2)[:, None] * camera.direction[None, :])
        jv = -f * (camera.up[None, :] / z[:, None]
                   - (y / z**2)[:, None] * camera.direction[None, :])
        jac = np.stack([ju, jv], axis=1)                                   # (N, 2, 3)
        c2 = np.einsum("nij,njk,nlk->nil", jac, cov, jac)
        c2[:, 0, 0] += PIXEL_FILTER_PX2
        c2[:, 1, 1] += PIXEL_FILTER_PX2
        det = c2[:, 0, 0] * c2[:, 1, 1] - c2[:, 0, 1] ** 2
        # each splat is evaluated on a stamp of pixels about its centre, its half size the
        # reach of its widest axis (STAMP_SIGMAS) rounded up to a power of two, in groups
        reach = STAMP_SIGMAS * np.sqrt(0.5 * (c2[:, 0, 0] + c2[:, 1, 1])
                                       + np.sqrt(0.25 * (c2[:, 0, 0] - c2[:, 1, 1]) ** 2
                                                 + c2[:, 0, 1] ** 2))
        x0, y0 = xs[0], ys[0]
        sx = (xs[-1] - x0) / (xs.size - 1) if xs.size > 1 else 1.0
        sy = (ys[-1] - y0) / (ys.size - 1) if ys.size > 1 else 1.0
        ok = (det > 0) & (u + reach >= xs.min()) & (u - reach <= xs.max()) \
            & (v + reach >= ys.min()) & (v - reach <= ys.max())
        u, v, c2, det, alpha, reach = u[ok], v[ok], c2[ok], det[ok], alpha[ok], reach[ok]
        z = z[ok]
        a00, a01, a11 = c2[:, 1, 1] / det, -c2[:, 0, 1] / det, c2[:, 0, 0] / det
        # stamp half sizes in samples (the grid may be finer than a pixel)
        half = np.minimum(np.ceil(reach / min(sx, sy)), max(xs.size, ys.size)).astype(np.int64)
        order = np.argsort(z, kind="stable")                   # front to back
        acc = np.zeros(xs.size * ys.size, dtype=np.float64)    # log of the transmittance
        wsum = np.zeros(xs.size * ys.size, dtype=np.float64)
        zsum = np.zeros(xs.size * ys.size, dtype=np.float64)
        for s in range(0, order.size, CHUNK_SPLATS):
            k = order[s:s + CHUNK_SPLATS]
            r = int(half[k].max())
            off = np.arange(-r, r + 1)
            ci = np.rint((u[k] - x0) / sx).astype(np.int64)
            cj = np.rint((v[k] - y0) / sy).astype(np.int64)
            ii = ci[:, None, None] + off[None, None, :]                    # (n, 1, S)
            jj = cj[:, None, None] + off[None, :, None]                    # (n, S, 1)
            dx = x0 + ii * sx - u[k, None, None]
            dy = y0 + jj * sy - v[k, None, None]
            q = a00[k, None, None] * dx * dx + 2.0 * a01[k, None, None] * dx * dy \
                + a11[k, None, None] * dy * dy
            a = np.minimum(alpha[k, None, None] * np.exp(-0.5 * q), MAX_ALPHA)
            inside = (ii >= 0) & (ii < xs.size) & (jj >= 0) & (jj < ys.size) & (a >= MIN_ALPHA)
            flat = np.broadcast_to(jj * xs.size + ii, inside.shape)[inside]
            a_in = a[inside]
            # each splat's share of the pixel: its alpha times the transmittance of the
            # chunks in front (within a chunk, a few centimetres deep, order is not kept)
            share = a_in * np.exp(acc[flat])
            wsum += np.bincount(flat, weights=share, minlength=acc.size)
            zk = np.broadcast_to(z[k, None, None], inside.shape)[inside]
            zsum += np.bincount(flat, weights=share * zk, minlength=acc.size)
            acc += np.bincount(flat, weights=np.log1p(-a_in), minlength=acc.size)
        log_clear = acc.reshape(ys.size, xs.size)
        with np.errstate(invalid="ignore", divide="ignore"):
            depth = np.where(wsum > 0, zsum / wsum, np.nan).reshape(ys.size, xs.size)
        return (1.0 - np.exp(log_clear)).astype(np.float32), depth


def foreground_of_click(index: SplatIndex, camera: Camera, click: FloatArray, depth_m: float,
                        model_matrix: FloatArray | None = None, ball_px: float = BALL_PX
                        ) -> Foreground:
    """The foreground of a click (window coordinates in ``camera``'s view) whose feature lies
    ``depth_m`` metres along its ray (the depth hint): the splats within ``ball_px`` pixels'
    worth of the view at that depth (ifov x depth x ball_px metres) of that point."""
    ray = camera.pick_ray(np.asarray(click, dtype=np.float64))[0]
    point = camera.position + float(depth_m) * ray
    return Foreground.near(index, point, ball_px * camera.ifov * float(depth_m), model_matrix)
