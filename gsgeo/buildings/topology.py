"""The topology of a building from its point ids: oriented faces, the outline, the wall groups.

Everything here is decided by the ids the faces share; coordinates only orient faces (which
side is up), test that the outline's consecutive edges are collinear in plan (one wall), and
find the eave and ridge vertices. Vertices are indices into the list of roof point ids.

- Roof faces are turned counter-clockwise seen from above (outward normal up).
- Walls given by the user (vertical steps between roof parts) are turned to run against the
  roof edges they share.
- The outline is the loop of edges that only one face uses. It must be one simple loop: two
  loops are a hole (one turns clockwise) or separate parts; a vertex with two outline edges
  leaving it makes the outline touch itself.
- The outline's edges are grouped into walls: consecutive edges whose plan projections are
  collinear (the middle vertex within 3.29 sigma, p = 0.001, of the chord, and turning less
  than 15 degrees) form one wall; a vertical edge of a given wall (a step between a lower and
  a higher roof part, of zero length in plan) joins the wall it lies in.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from gsgeo.errors import GeometryError
from gsgeo.measure.features import ring_self_intersection
from gsgeo.solve.linalg import FloatArray

#: A roof face steeper than this is refused as vertical (degrees).
MAX_ROOF_SLOPE_DEG = 84.0
#: A face flatter than this is flat (roof type, eaves) (degrees).
FLAT_DEG = 5.0
#: Collinearity in plan: the middle vertex within this many sigmas of the chord (p = 0.001)...
COLLINEAR_SIGMAS = 3.29
#: ... and the direction turning less than this (degrees).
COLLINEAR_MAX_TURN_DEG = 15.0
#: Chi-square(2) at 0.999: a wall's outline edge is vertical when its plan length passes this.
VERTICAL_EDGE_CHI2 = 13.8155


@dataclass
class Topology:
    """The building's faces and outline, as vertex indices.

    ``roofs``/``walls``: oriented rings (outward normals); ``outline``: the boundary loop,
    counter-clockwise seen from above; ``groups``: the outline cut into walls, each a chain of
    consecutive outline vertices (the first and last are the wall's corners; the last of one
    group is the first of the next); ``vertical_edges``: outline edges (a, b) of zero length in
    plan; ``eaves``: eave vertices (on the outline, at the lowest level of a pitched face; all
    outline vertices when every face is flat); ``pitched``: per roof face, steeper than
    FLAT_DEG.
    """

    roofs: list[tuple[int, ...]]
    walls: list[tuple[int, ...]]
    outline: list[int]
    groups: list[list[int]]
    vertical_edges: set[tuple[int, int]]
    eaves: list[int]
    pitched: list[bool]


def newell_normal(x: FloatArray) -> FloatArray:
    """Newell's normal of the ring ``x`` (k, 3): length = twice the area, right-hand rule."""
    y = np.roll(x, -1, axis=0)
    return np.array([np.sum((x[:, 1] - y[:, 1]) * (x[:, 2] + y[:, 2])),
                     np.sum((x[:, 2] - y[:, 2]) * (x[:, 0] + y[:, 0])),
                     np.sum((x[:, 0] - y[:, 0]) * (x[:, 1] + y[:, 1]))])


def plan_area(xy: FloatArray) -> float:
    """Signed area of the ring ``xy`` (k, 2+) in plan (positive counter-clockwise)."""
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def face_label(kind: str, i: int, ids: Sequence[str]) -> str:
    """How messages name a face: ``roof face 1 (E3, E4, R1, R2)``."""
    return f"{kind} {i} ({', '.join(ids)})"


def _orient_roofs(rings: Sequence[tuple[int, ...]], xyz: FloatArray,
                  ids: Sequence[str]) -> tuple[list[tuple[int, ...]], list[bool]]:
    out: list[tuple[int, ...]] = []
    pitched: list[bool] = []
    for i, ring in enumerate(rings):
        nrm = newell_normal(xyz[list(ring)])
        size = float(np.linalg.norm(nrm))
        label = face_label("roof face", i, [ids[k] for k in ring])
        if size == 0.0 or not math.isfinite(size):
            raise GeometryError(f"{label} has no area: its points are collinear",
                                field=f"roofs[{i}]")
        slope = math.degrees(math.acos(min(1.0, abs(nrm[2]) / size)))
        if slope > MAX_ROOF_SLOPE_DEG:
            raise GeometryError(f"{label} is vertical (slope {slope:.0f} degrees): a roof face "
                                "must not be steeper than "
                                f"{MAX_ROOF_SLOPE_DEG:g} degrees; give a vertical step between "
                                "roof parts as a wall (\"walls\")", field=f"roofs[{i}]")
        hit = ring_self_intersection(xyz[list(ring), :2])
        if hit is not None:
            a, b = hit
            raise GeometryError(f"{label} crosses itself in plan (its edges from "
                                f"{ids[ring[a]]} and from {ids[ring[b]]} meet): give its points "
                                "in order around the face", field=f"roofs[{i}]")
        out.append(ring if nrm[2] > 0 else tuple(reversed(ring)))
        pitched.append(slope > FLAT_DEG)
    return out, pitched


def _edges(ring: Sequence[int]) -> list[tuple[int, int]]:
    return [(ring[k], ring[(k + 1) % len(ring)]) for k in range(len(ring))]


def _check_vertical_wall(i: int, ring: tuple[int, ...], xyz: FloatArray,
                         ids: Sequence[str]) -> None:
    nrm = newell_normal(xyz[list(ring)])
    size = float(np.linalg.norm(nrm))
    label = face_label("wall", i, [ids[k] for k in ring])
    if size == 0.0:
        raise GeometryError(f"{label} has no area: its points are collinear",
                            field=f"walls[{i}]")
    tilt = math.degrees(math.asin(min(1.0, abs(nrm[2]) / size)))
    if tilt > 90.0 - MAX_ROOF_SLOPE_DEG:
        raise GeometryError(f"{label} is not vertical (it leans {tilt:.0f} degrees from the "
                            "vertical): give sloping faces as roofs", field=f"walls[{i}]")


def build_topology(roof_rings: Sequence[tuple[int, ...]], wall_rings: Sequence[tuple[int, ...]],
                   xyz: FloatArray, cov: FloatArray, ids: Sequence[str]) -> Topology:
    """The topology of the faces ``roof_rings`` and ``wall_rings`` (vertex indices) over the
    measured vertices ``xyz`` (n, 3, metres, local frame) with covariances ``cov`` (n, 3, 3);
    ``ids`` names the vertices in messages. GeometryError for anything that is not one
    closed, simple building: a vertical roof face, faces folded over each other, an edge of
    three faces, a hole, separate parts, an outline touching itself."""
    roofs, pitched = _orient_roofs(roof_rings, xyz, ids)
    owner: dict[tuple[int, int], str] = {}

    def add(edge: tuple[int, int], label: str) -> None:
        a, b = edge
        if edge in owner:
            raise GeometryError(f"{owner[edge]} and {label} overlap in plan: both run along "
                                f"the edge {ids[a]}-{ids[b]} in the same direction")
        owner[edge] = label

    for i, ring in enumerate(roofs):
        label = face_label("roof face", i, [ids[k] for k in ring])
        for e in _edges(ring):
            add(e, label)
    walls: list[tuple[int, ...]] = []
    for i, ring in enumerate(wall_rings):
        _check_vertical_wall(i, ring, xyz, ids)
        es = _edges(ring)
        same = sum(1 for e in es if e in owner)
        against = sum(1 for a, b in es if (b, a) in owner)
        label = face_label("wall", i, [ids[k] for k in ring])
        if same == 0 and against == 0:
            raise GeometryError(f"{label} shares no edge with the roof faces",
                                field=f"walls[{i}]")
        if same > against:
            ring = tuple(reversed(ring))
        for e in _edges(ring):
            add(e, label)
        walls.append(ring)
    undirected: dict[frozenset[int], int] = {}
    for a, b in owner:
        key = frozenset((a, b))
        undirected[key] = undirected.get(key, 0) + 1
    for key, count in undirected.items():
        if count > 2:
            a, b = sorted(key)
            raise GeometryError(f"the edge {ids[a]}-{ids[b]} belongs to {count} faces: an edge "
                                "joins at most two faces")
    boundary = [(a, b) for a, b in owner if (b, a) not in owner]
    nxt: dict[int, int] = {}
    for a, b in boundary:
        if a in nxt:
            raise GeometryError(f"the outline of the roof is not one simple loop: it passes "
                                f"through point {ids[a]} twice (faces meet only at that point)")
        nxt[a] = b
    loops: list[list[int]] = []
    seen: set[int] = set()
    for start in nxt:
        if start in seen:
            continue
        loop = [start]
        seen.add(start)
        v = nxt[start]
        while v != start:
            if v in seen or v not in nxt:
                raise GeometryError("the outline of the roof is not one simple loop (it "
                                    f"breaks at point {ids[v]})")
            loop.append(v)
            seen.add(v)
            v = nxt[v]
        loops.append(loop)
    if not loops:
        raise GeometryError("the roof faces have no outline: they close on themselves")
    if len(loops) > 1:
        areas = [plan_area(xyz[lp]) for lp in loops]
        inner = [lp for lp, a in zip(loops, areas, strict=True) if a < 0]
        if inner:
            raise GeometryError("the roof has a hole (an inner outline through "
                                f"{', '.join(ids[k] for k in inner[0])}): a building here is "
                                "one solid without courtyards")
        raise GeometryError(f"the roof faces form {len(loops)} separate parts (outlines "
                            + "; ".join(", ".join(ids[k] for k in lp) for lp in loops)
                            + "): join them by shared points or a wall")
    outline = loops[0]
    if plan_area(xyz[outline]) <= 0:
        raise GeometryError("the outline of the roof turns clockwise seen from above: the "
                            "roof faces are folded over each other")
    wall_edges = {e for w in walls for e in _edges(w)}
    vertical_edges: set[tuple[int, int]] = set()
    for k, a in enumerate(outline):
        b = outline[(k + 1) % len(outline)]
        if (a, b) in wall_edges:
            d = xyz[b, :2] - xyz[a, :2]
            c2 = cov[a, :2, :2] + cov[b, :2, :2]
            m2 = float(d @ np.linalg.solve(c2, d))
            if m2 > VERTICAL_EDGE_CHI2:
                raise GeometryError(f"the wall edge {ids[a]}-{ids[b]} on the outline is not "
                                    f"vertical ({float(np.hypot(*d)):.3f} m apart in plan): "
                                    "a wall's free edges are the vertical steps")
            vertical_edges.add((a, b))
    groups = _groups(outline, vertical_edges, xyz, cov, ids)
    eaves = _eaves(roofs, pitched, set(outline), xyz, cov)
    return Topology(roofs=roofs, walls=walls, outline=outline, groups=groups,
                    vertical_edges=vertical_edges, eaves=eaves, pitched=pitched)


def _offset_ratio(a: int, mids: Sequence[int], c: int, xyz: FloatArray, cov: FloatArray) -> float:
    """Largest distance of the vertices ``mids`` from the plan line a-c, in sigmas."""
    d = xyz[c, :2] - xyz[a, :2]
    length = float(np.hypot(*d))
    if length == 0.0:
        return math.inf
    nrm = np.array([-d[1], d[0]]) / length
    worst = 0.0
    for b in mids:
        t = float((xyz[b, :2] - xyz[a, :2]) @ d) / length ** 2
        off = float((xyz[b, :2] - xyz[a, :2]) @ nrm)
        var = float(nrm @ cov[b, :2, :2] @ nrm + (1 - t) ** 2 * (nrm @ cov[a, :2, :2] @ nrm)
                    + t ** 2 * (nrm @ cov[c, :2, :2] @ nrm))
        worst = max(worst, abs(off) / math.sqrt(max(var, 1e-300)))
    return worst


def _groups(outline: list[int], vertical: set[tuple[int, int]], xyz: FloatArray,
            cov: FloatArray, ids: Sequence[str]) -> list[list[int]]:
    """The outline cut at its corners into chains of plan-collinear edges (walls)."""
    n = len(outline)
    # Runs: each non-vertical edge with the vertical edges that follow it.
    runs: list[list[int]] = []  # vertex chains, first = start, last = end
    starts = [k for k in range(n) if (outline[k], outline[(k + 1) % n]) not in vertical]
    if len(starts) < 3:
        raise GeometryError("the outline of the roof has fewer than three edges in plan")
    for s_i, k in enumerate(starts):
        end = starts[(s_i + 1) % len(starts)]
        chain = [outline[k]]
        j = (k + 1) % n
        while True:
            chain.append(outline[j])
            if j == end:
                break
            j = (j + 1) % n
        runs.append(chain)
    # runs[i] = [a, b, (vertical successors of b...)]: join run i to run i+1 when collinear.
    # A corner: the junction between two runs that are not collinear.
    def collinear(r0: list[int], r1: list[int]) -> bool:
        a, c = r0[0], r1[1]
        da = xyz[r0[1], :2] - xyz[r0[0], :2]
        dc = xyz[r1[1], :2] - xyz[r1[0], :2]
        na, nc = float(np.hypot(*da)), float(np.hypot(*dc))
        if na == 0 or nc == 0:
            return False
        cosang = float(da @ dc) / (na * nc)
        if cosang < math.cos(math.radians(COLLINEAR_MAX_TURN_DEG)):
            return False
        mids = r0[1:]
        return _offset_ratio(a, mids, c, xyz, cov) < COLLINEAR_SIGMAS

    m = len(runs)
    joined = [collinear(runs[i], runs[(i + 1) % m]) for i in range(m)]
    if all(joined):
        raise GeometryError("the outline of the roof is a straight line in plan")
    # Start after a corner.
    first = (joined.index(False) + 1) % m
    groups: list[list[int]] = []
    group: list[int] = []
    for s in range(m):
        i = (first + s) % m
        group = runs[i] if not group else group + runs[i][1:]
        if not joined[i]:
            groups.append(group)
            group = []
    if len(groups) < 3:
        raise GeometryError("the outline of the roof has fewer than three corners in plan: "
                            f"{', '.join(ids[g[0]] for g in groups)}")
    return groups


def _eaves(roofs: list[tuple[int, ...]], pitched: list[bool], on_outline: set[int],
           xyz: FloatArray, cov: FloatArray) -> list[int]:
    out: dict[int, None] = {}
    if not any(pitched):
        return [v for ring in roofs for v in ring if v in on_outline]
    for ring, pt in zip(roofs, pitched, strict=True):
        if not pt:
            continue
        idx = np.asarray(ring)
        hs = xyz[idx, 2]
        low = float(hs.min())
        span = float(hs.max()) - low
        for v in ring:
            tol = min(max(0.05, 4.0 * math.sqrt(max(float(cov[v, 2, 2]), 0.0))), 0.5 * span)
            if v in on_outline and xyz[v, 2] - low <= tol:
                out.setdefault(v)
    return list(out)
