"""A click snapped onto the feature it was meant for: the centre of a checker target (a saddle),
a corner, the centre of a small dot, found within a few pixels of where the operator clicked.

A person's click is a pixel or two off the feature. Auto-aim finds *the clicked spot* in the
other views, so every auto ray inherits that error (gsgeo.solve.sharedaim states it). Where
the clicked spot is a point feature, the image says where the feature is more precisely than
the hand: OpenCV's ``cornerSubPix`` moves a point to where the image gradients around it are
orthogonal to the lines towards it, which is the centre of a saddle, the tip of a corner and,
by symmetry, the centre of a round dot. It does not find a point on a straight edge or in a
flat patch, so the snap is kept only when

- it started from five points about the click (the click and 1.5 px to each side) and all
  five arrived within ``AGREE_PX`` of each other (an edge lets each slide to its own place),
- the image around it has gradients in two directions (the smaller eigenvalue of the
  structure tensor at least ``MIN_ISOTROPY`` of the larger, and the gradients strong:
  ``MIN_GRADIENT`` grey levels a pixel, root mean square),
- it lies within ``MAX_SHIFT_PX`` of the click (a person misses by a pixel or two; a feature
  further away is another one).

A colour image is tried twice: projected onto its colours' principal axis in the 21 x 21
pixels about the click (a red roof against a grey wall differ in colour more than in
brightness: an eaves corner that grey alone cannot place) and as its brightness (a dark pole
top on green grass, where the principal axis runs along the grass's own variation). Where
both place the feature the one nearer the click is kept; where neither does, the click stays
as it was, with the reason. Pixel coordinates are window
coordinates (CSS px, x right, y down; a pixel's centre at +0.5) like the clicks'.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from gsgeo.solve.linalg import FloatArray

#: Half the side of the window the snap looks at (px): 9 x 9 pixels.
WINDOW_HALF = 4
#: Offsets (px) of the five starting points about the click.
STARTS = np.array([[0.0, 0.0], [1.5, 0.0], [-1.5, 0.0], [0.0, 1.5], [0.0, -1.5]])
#: The five snapped points must agree within this (px).
AGREE_PX = 0.3
#: The snapped point may lie at most this far from the click (px): a person misses by 1-2 px;
#: further away lies another feature (a pole top's corner beside its centre).
MAX_SHIFT_PX = 2.5
#: Smallest ratio of the structure tensor's eigenvalues: gradients in two directions.
MIN_ISOTROPY = 0.1
#: Smallest gradient along the weaker direction (grey levels a pixel, RMS over the window).
MIN_GRADIENT = 3.0
#: Half the side (px) of the window whose colours give the axis a colour image is projected on.
COLOUR_HALF = 10
#: cornerSubPix stops after this many iterations or a step under this (px).
CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 50, 0.005)


@dataclass(frozen=True)
class Snap:
    """Where the click went: ``pixel`` (window coordinates, px) is the feature when ``ok``,
    else the click itself; ``moved_px`` how far it moved; ``reason`` why it was not snapped."""

    ok: bool
    pixel: FloatArray
    moved_px: float = 0.0
    isotropy: float | None = None
    reason: str | None = None

    def to_json(self) -> dict[str, object]:
        return {"ok": self.ok, "pixel": self.pixel.tolist(), "moved_px": self.moved_px,
                "isotropy": self.isotropy, "reason": self.reason}


def structure(image: np.ndarray, at: FloatArray, half: int = WINDOW_HALF) -> tuple[float, float]:
    """Eigenvalues (smaller, larger) of the mean structure tensor of grey ``image`` (H, W)
    over the (2 half + 1)^2 pixels nearest image position ``at`` (px, pixel centres at
    integer + 0.5): mean squared gradient (grey levels per pixel)^2 along the weaker and the
    stronger direction."""
    cx, cy = int(np.floor(at[0])), int(np.floor(at[1]))
    y0, y1, x0, x1 = cy - half - 1, cy + half + 2, cx - half - 1, cx + half + 2
    patch = image[y0:y1, x0:x1].astype(np.float64)
    gx = (patch[1:-1, 2:] - patch[1:-1, :-2]) / 2.0
    gy = (patch[2:, 1:-1] - patch[:-2, 1:-1]) / 2.0
    j = np.array([[np.mean(gx * gx), np.mean(gx * gy)], [np.mean(gx * gy), np.mean(gy * gy)]])
    lo, hi = np.linalg.eigvalsh(j)
    return float(max(lo, 0.0)), float(hi)


def principal_projection(image: np.ndarray, at: FloatArray, half: int = COLOUR_HALF
                         ) -> np.ndarray:
    """Colour ``image`` (H, W, C) projected onto the principal axis of the colours of the
    (2 half + 1)^2 pixels about image position ``at`` (px): (H, W) float32 in the image's
    units, the channel in which those pixels differ most."""
    x, y = int(at[0]), int(at[1])
    win = image[max(y - half, 0):y + half + 1, max(x - half, 0):x + half + 1]
    colours = win.reshape(-1, image.shape[2]).astype(np.float64)
    _, vectors = np.linalg.eigh(np.cov(colours.T))
    axis = vectors[:, -1]
    return np.asarray(image.astype(np.float64) @ axis, dtype=np.float32)


def snap_click(image: np.ndarray, origin: FloatArray, click: FloatArray,
               max_shift_px: float = MAX_SHIFT_PX) -> Snap:
    """The point feature at or near ``click`` (window coordinates, px) in ``image`` (H, W
    grey or H, W, 3 BGR colour; levels 0-255) whose top-left corner is at window position
    ``origin``; the click itself with the reason when there is none to snap to (see the
    module's tests)."""
    click = np.asarray(click, dtype=np.float64)
    local = click - np.asarray(origin, dtype=np.float64)
    h, w = image.shape[:2]
    margin = max(WINDOW_HALF + max_shift_px + 3, COLOUR_HALF + 1)
    if not (margin <= local[0] <= w - margin and margin <= local[1] <= h - margin):
        return Snap(False, click, reason="the click is too near the edge of its image")
    if image.ndim == 2:
        return snap_channel(image, origin, click, max_shift_px)
    bgr = np.asarray(image, dtype=np.float32)
    brightness = bgr @ np.array([0.114, 0.587, 0.299], dtype=np.float32)
    tries = [snap_channel(principal_projection(bgr, local), origin, click, max_shift_px),
             snap_channel(brightness, origin, click, max_shift_px)]
    placed = [t for t in tries if t.ok]
    return min(placed, key=lambda t: t.moved_px) if placed else tries[0]


def snap_channel(image: np.ndarray, origin: FloatArray, click: FloatArray,
                 max_shift_px: float = MAX_SHIFT_PX) -> Snap:
    """snap_click on one channel ``image`` (H, W), the click already checked to lie inside."""
    local = click - np.asarray(origin, dtype=np.float64)
    img = np.ascontiguousarray(image, dtype=np.float32)
    # OpenCV's corner functions take pixel centres at integers
    starts = (local - 0.5 + STARTS).astype(np.float32).reshape(-1, 1, 2)
    ends = cv2.cornerSubPix(img, starts.copy(), (WINDOW_HALF, WINDOW_HALF), (-1, -1), CRITERIA)
    ends = ends.reshape(-1, 2).astype(np.float64) + 0.5
    centre = np.median(ends, axis=0)
    spread = float(np.max(np.linalg.norm(ends - centre, axis=1)))
    if spread > AGREE_PX:
        return Snap(False, click, reason=f"no single point feature here (the snap from about "
                                          f"the click spread over {spread:.1f} px)")
    moved = float(np.linalg.norm(centre - local))
    if moved > max_shift_px:
        return Snap(False, click, moved_px=moved,
                    reason=f"the nearest point feature is {moved:.1f} px from the click "
                           f"(more than {max_shift_px:g})")
    lo, hi = structure(img, centre)
    isotropy = lo / hi if hi > 0 else 0.0
    if hi <= 0 or isotropy < MIN_ISOTROPY:
        return Snap(False, click, moved_px=moved, isotropy=isotropy,
                    reason="an edge, not a point feature (gradients in one direction)")
    if np.sqrt(lo) < MIN_GRADIENT:
        return Snap(False, click, moved_px=moved, isotropy=isotropy,
                    reason="too little contrast about the click to place it better")
    return Snap(True, centre + np.asarray(origin, dtype=np.float64), moved_px=moved,
                isotropy=isotropy)
