"""The closed shell of a building: roof faces, walls extruded from the outline, one ground face.

Each wall group of the outline (a chain of plan-collinear outline vertices, see
gsgeo.buildings.topology) becomes ONE wall polygon: the chain down to the ground at its two
corners (a gable wall is a pentagon, a wall with a vertical step between a lower and a higher
roof part keeps the step in its ring). The ground face joins the ground vertices under the
corners. Rings are oriented so that their right-hand normals point out of the solid: roofs
counter-clockwise seen from above, the ground clockwise, walls counter-clockwise seen from
outside.

Vertex indices: the roof vertices first (0..n-1, as the adjustment numbers them), then one
ground vertex per outline corner (n + j for the j-th group's first vertex).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from gsgeo.buildings.topology import Topology, plan_area
from gsgeo.errors import GeometryError
from gsgeo.measure.features import ring_self_intersection
from gsgeo.solve.linalg import FloatArray

SURFACE_KINDS = ("RoofSurface", "WallSurface", "GroundSurface")


@dataclass(frozen=True)
class Surface:
    """One face of the shell: ``ring`` indices into the model's vertices (open ring, outward
    normal by the right-hand rule), ``kind`` its CityJSON semantic type."""

    ring: tuple[int, ...]
    kind: str


def corners(topo: Topology) -> list[int]:
    """The outline's corners (roof vertex indices), counter-clockwise seen from above."""
    return [g[0] for g in topo.groups]


def shell_vertices(roof_xyz: FloatArray, topo: Topology, ground: float) -> FloatArray:
    """All vertices (n + k, 3): the roof vertices, then a ground vertex (at height ``ground``)
    under each outline corner."""
    cs = corners(topo)
    g = np.column_stack([roof_xyz[cs, 0], roof_xyz[cs, 1], np.full(len(cs), ground)])
    return np.vstack([roof_xyz, g])


def shell_surfaces(topo: Topology, n_roof: int) -> list[Surface]:
    """The faces of the closed shell over ``n_roof`` roof vertices (see the module docstring)."""
    cs = corners(topo)
    under = {c: n_roof + j for j, c in enumerate(cs)}
    out = [Surface(r, "RoofSurface") for r in topo.roofs]
    out += [Surface(w, "WallSurface") for w in topo.walls]
    for chain in topo.groups:
        ring = (*reversed(chain), under[chain[0]], under[chain[-1]])
        out.append(Surface(tuple(ring), "WallSurface"))
    out.append(Surface(tuple(under[c] for c in reversed(cs)), "GroundSurface"))
    return out


def check_plan(topo: Topology, roof_xyz: FloatArray, ids: list[str]) -> None:
    """GeometryError when the adjusted outline crosses itself in plan or roof faces overlap in
    plan (their plan areas add up to more than the outline encloses)."""
    cs = corners(topo)
    hit = ring_self_intersection(roof_xyz[cs, :2])
    if hit is not None:
        a, b = hit
        raise GeometryError("the outline of the roof crosses itself in plan: the walls from "
                            f"{ids[cs[a]]} and from {ids[cs[b]]} meet")
    outline = plan_area(roof_xyz[cs])
    faces = [plan_area(roof_xyz[list(r)]) for r in topo.roofs]
    if sum(faces) > outline * (1 + 1e-6) + 1e-6:
        raise GeometryError(f"roof faces overlap in plan: their plan areas add up to "
                            f"{sum(faces):.2f} m² but the outline encloses {outline:.2f} m²"
                            + _overlapping_pair(topo, roof_xyz, ids))


def _inside(p: FloatArray, poly: FloatArray) -> bool:
    x, y = p
    xs, ys = poly[:, 0], poly[:, 1]
    xn, yn = np.roll(xs, -1), np.roll(ys, -1)
    cross = (ys > y) != (yn > y)
    with np.errstate(divide="ignore", invalid="ignore"):
        xi = xs + (y - ys) * (xn - xs) / (yn - ys)
    return bool(np.count_nonzero(cross & (x < xi)) % 2)


def _overlapping_pair(topo: Topology, xyz: FloatArray, ids: list[str]) -> str:
    rings = [xyz[list(r), :2] for r in topo.roofs]
    for i in range(len(rings)):
        for j in range(len(rings)):
            if i == j:
                continue
            shared = set(topo.roofs[i]) & set(topo.roofs[j])
            for k, v in enumerate(topo.roofs[i]):
                if v not in shared and _inside(rings[i][k], rings[j]):
                    return (f" (roof face {i} has point {ids[v]} inside roof face {j} in "
                            "plan)")
    return ""
