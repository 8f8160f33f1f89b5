"""Volume, footprint, heights, slopes and roof type of a building's shell, with 1-sigma values.

Inputs are in a local Cartesian frame in metres (the adjustment's): the shell's vertices
(roof vertices, then one ground vertex under each outline corner), its faces, the roof
vertices' joint covariance (3n x 3n, m²) and the ground height's variance (m²). A ground
vertex takes E, N from the roof corner above it and H from the ground, so every quantity is a
function of the roof vertices and the ground height; its variance is gᵀ Σ g + (∂f/∂g)² σg²
with g its gradient (first-order propagation through the JOINT covariance: the adjusted
vertices of a face are correlated).

- volume (m³): divergence theorem over the closed shell, V = Σ over fan triangles (a, b, c) of
  a·(b×c)/6; its gradient is analytic (∂V/∂a = b×c/6, ...);
- footprint area (m²): the ground ring's area in plan;
- eaves height: mean height of the eave vertices; ridge height: mean height of the roof
  vertices within RIDGE_TOLERANCE_M of the highest (both in metres here; the model converts);
- slope of a roof face: angle of its plane to the horizontal (degrees); aspect: azimuth of its
  downhill direction from grid north, clockwise (degrees); the slope's sigma by numerical
  differentiation over the face's vertices.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from gsgeo.buildings.solid import Surface
from gsgeo.buildings.topology import FLAT_DEG, Topology, newell_normal
from gsgeo.solve.linalg import FloatArray

#: Roof vertices this close to the highest one (m) are on the ridge.
RIDGE_TOLERANCE_M = 0.1


@dataclass
class Shell:
    """A building's shell for the measures: vertices (n + k, 3, metres), faces, the number of
    roof vertices ``n``, the roof vertex under each ground vertex ``corner_of`` (k,), the roof
    vertices' joint covariance ``cov`` (3n, 3n) and the ground's variance ``ground_var``."""

    vertices: FloatArray
    surfaces: Sequence[Surface]
    n: int
    corner_of: Sequence[int]
    cov: FloatArray
    ground_var: float

    def variance(self, grad: FloatArray) -> float:
        """Variance of a quantity whose gradient w.r.t. all vertices is ``grad`` (n + k, 3)."""
        g = grad[:self.n].copy()
        gg = grad[self.n:]
        under = np.asarray(self.corner_of, dtype=np.int64)
        g[:, 0] += np.bincount(under, weights=gg[:, 0], minlength=self.n)
        g[:, 1] += np.bincount(under, weights=gg[:, 1], minlength=self.n)
        flat = g.ravel()
        dg = float(gg[:, 2].sum())
        return float(flat @ self.cov @ flat) + dg * dg * self.ground_var


def fan_triangles(surfaces: Sequence[Surface]) -> npt.NDArray[np.int64]:
    """(T, 3) vertex indices of a fan triangulation of every face (signed volumes add up for
    any planar polygon, convex or not)."""
    tris = [(s.ring[0], s.ring[k], s.ring[k + 1]) for s in surfaces for k in range(1, len(s.ring) - 1)]
    return np.asarray(tris, dtype=np.int64)


def volume(shell: Shell) -> tuple[float, float]:
    """Volume of the closed shell (m³) and its 1-sigma."""
    t = fan_triangles(shell.surfaces)
    a, b, c = (shell.vertices[t[:, k]] for k in range(3))
    vol = float(np.einsum("ij,ij->", a, np.cross(b, c))) / 6.0
    nv = shell.vertices.shape[0]
    grad = np.zeros_like(shell.vertices)
    for k, part in enumerate((np.cross(b, c), np.cross(c, a), np.cross(a, b))):
        for ax in range(3):
            grad[:, ax] += np.bincount(t[:, k], weights=part[:, ax], minlength=nv) / 6.0
    return vol, math.sqrt(max(shell.variance(grad), 0.0))


def footprint_area(shell: Shell, ground_ring: Sequence[int]) -> tuple[float, float]:
    """Plan area of the ground face (m²) and its 1-sigma."""
    r = np.asarray(ground_ring, dtype=np.int64)
    x, y = shell.vertices[r, 0], shell.vertices[r, 1]
    area = -0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))  # ground ring is CW
    nv = shell.vertices.shape[0]
    grad = np.zeros_like(shell.vertices)
    grad[:, 0] = np.bincount(r, weights=-0.5 * (np.roll(y, -1) - np.roll(y, 1)), minlength=nv)
    grad[:, 1] = np.bincount(r, weights=-0.5 * (np.roll(x, 1) - np.roll(x, -1)), minlength=nv)
    return area, math.sqrt(max(shell.variance(grad), 0.0))


def mean_height(shell: Shell, vertices: Sequence[int]) -> tuple[float, float]:
    """Mean height (m) of roof ``vertices`` and its 1-sigma."""
    idx = np.asarray(vertices, dtype=np.int64)
    grad = np.zeros_like(shell.vertices)
    grad[idx, 2] = 1.0 / idx.size
    return float(shell.vertices[idx, 2].mean()), math.sqrt(max(shell.variance(grad), 0.0))


def ridge_vertices(roof_xyz: FloatArray) -> list[int]:
    """Roof vertices within RIDGE_TOLERANCE_M of the highest."""
    top = float(roof_xyz[:, 2].max())
    return [int(i) for i in np.flatnonzero(roof_xyz[:, 2] >= top - RIDGE_TOLERANCE_M)]


def _slopes(x: FloatArray) -> FloatArray:
    """Slope (degrees) of each ring in ``x`` (B, k, 3), from its Newell normal."""
    y = np.roll(x, -1, axis=1)
    nx = np.sum((x[..., 1] - y[..., 1]) * (x[..., 2] + y[..., 2]), axis=-1)
    ny = np.sum((x[..., 2] - y[..., 2]) * (x[..., 0] + y[..., 0]), axis=-1)
    nz = np.sum((x[..., 0] - y[..., 0]) * (x[..., 1] + y[..., 1]), axis=-1)
    return np.degrees(np.arctan2(np.hypot(nx, ny), nz))


def roof_slopes(shell: Shell, roofs: Sequence[tuple[int, ...]]) -> list[dict[str, float | int]]:
    """Per roof face: slope and aspect (degrees) and the slope's 1-sigma."""
    out: list[dict[str, float | int]] = []
    step = 1e-6
    for i, ring in enumerate(roofs):
        idx = list(ring)
        x = shell.vertices[idx]
        nrm = newell_normal(x)
        slope = math.degrees(math.atan2(math.hypot(nrm[0], nrm[1]), nrm[2]))
        aspect = math.degrees(math.atan2(nrm[0], nrm[1])) % 360.0
        k = len(idx)
        # central differences, every coordinate of the face at once: (2, 3k, k, 3) copies
        bump = np.eye(3 * k).reshape(3 * k, k, 3) * step
        both = _slopes(np.concatenate([x + bump, x - bump]))
        grad = np.zeros_like(shell.vertices)
        grad[idx] = ((both[:3 * k] - both[3 * k:]) / (2 * step)).reshape(k, 3)
        out.append({"face": i, "slope_deg": slope,
                    "sigma_slope_deg": math.sqrt(max(shell.variance(grad), 0.0)),
                    "aspect_deg": aspect})
    return out


def roof_type(topo: Topology, slopes: Sequence[dict[str, float | int]]) -> str:
    """"flat" (no pitched face), "shed" (one pitched face), "gable" (two pitched faces sharing
    a ridge edge, facing opposite ways), "hip" (three or more pitched faces whose outline lies
    all at the eaves), else "complex"."""
    pitched = [float(s["slope_deg"]) > FLAT_DEG for s in slopes]
    if not any(pitched):
        return "flat"
    if not all(pitched):
        return "complex"
    if len(pitched) == 1:
        return "shed"
    if len(pitched) == 2:
        a, b = (set(zip(r, r[1:] + r[:1], strict=True)) for r in topo.roofs)
        shares = any((q, p) in b for p, q in a)
        turn = abs((float(slopes[0]["aspect_deg"]) - float(slopes[1]["aspect_deg"]) + 180) % 360
                   - 180)
        return "gable" if shares and turn > 150 else "complex"
    if set(topo.outline) <= set(topo.eaves):
        return "hip"
    return "complex"
