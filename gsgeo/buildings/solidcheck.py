"""Checks that a shell is a valid solid: closed, 2-manifold, consistently oriented, outward,
with planar faces. Run before a building is written; the tests use them too.

``solid_problems`` lists what is wrong (empty when the shell is valid):

- every face has at least 3 distinct vertices and no repeated vertex, and its boundary
  neither touches nor crosses itself;
- every edge is used by exactly two faces, once in each direction (closed, no dangling or
  folded faces, orientation consistent);
- around every vertex the faces form one single fan (vertex 2-manifold);
- Euler characteristic V - E + F = 2 (one shell of genus 0, no handle);
- the enclosed volume is positive (normals point outward);
- every face lies in a plane within ``planarity_m`` (metres).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from gsgeo.errors import GeometryError
from gsgeo.measure.features import ring_self_intersection
from gsgeo.solve.linalg import FloatArray

#: Largest distance (m) of a face's vertex from the face's best plane.
PLANARITY_M = 1e-6


def _fans_are_single(rings: Sequence[Sequence[int]]) -> list[int]:
    """Vertices whose incident faces do not form one cycle around them."""
    link: dict[int, dict[int, int]] = {}
    for ring in rings:
        k = len(ring)
        for i, v in enumerate(ring):
            prev_v, next_v = ring[i - 1], ring[(i + 1) % k]
            link.setdefault(v, {})[next_v] = prev_v
    bad = []
    for v, step in link.items():
        start = next(iter(step))
        u = start
        count = 0
        while True:
            if u not in step:
                bad.append(v)
                break
            u = step[u]
            count += 1
            if u == start:
                if count != len(step):
                    bad.append(v)
                break
            if count > len(step):
                bad.append(v)
                break
    return bad


def _crosses_itself(p: FloatArray) -> bool:
    """Whether the (planar) ring ``p`` (k, 3) touches or crosses itself, tested in the
    coordinate plane its normal is closest to."""
    q = p - p.mean(axis=0)
    r = np.roll(q, -1, axis=0)
    normal = np.array([np.dot(q[:, 1] - r[:, 1], q[:, 2] + r[:, 2]),
                       np.dot(q[:, 2] - r[:, 2], q[:, 0] + r[:, 0]),
                       np.dot(q[:, 0] - r[:, 0], q[:, 1] + r[:, 1])])
    drop = int(np.argmax(np.abs(normal)))
    keep = [k for k in range(3) if k != drop]
    return ring_self_intersection(q[:, keep]) is not None


def solid_problems(vertices: FloatArray, rings: Sequence[Sequence[int]],
                   planarity_m: float = PLANARITY_M) -> list[str]:
    """What keeps ``rings`` over ``vertices`` (V, 3, metres) from being a valid solid."""
    out: list[str] = []
    nv = vertices.shape[0]
    for f, ring in enumerate(rings):
        if len(ring) < 3 or len(set(ring)) != len(ring):
            out.append(f"face {f} has fewer than 3 distinct vertices or repeats one")
        if any(not 0 <= v < nv for v in ring):
            out.append(f"face {f} names a vertex that does not exist")
    if out:
        return out
    for f, ring in enumerate(rings):
        if _crosses_itself(vertices[list(ring)]):
            out.append(f"face {f} crosses itself (its boundary touches or crosses itself)")
    directed: dict[tuple[int, int], int] = {}
    for f, ring in enumerate(rings):
        for i, a in enumerate(ring):
            b = ring[(i + 1) % len(ring)]
            if (a, b) in directed:
                out.append(f"edge {a}-{b} runs the same way in faces {directed[(a, b)]} and {f} "
                           "(inconsistent orientation or a fold)")
            directed[(a, b)] = f
    for (a, b), f in directed.items():
        if (b, a) not in directed:
            out.append(f"edge {a}-{b} of face {f} has no neighbour: the shell is not closed")
    if out:
        return out
    bad = _fans_are_single(rings)
    if bad:
        out.append(f"vertices {bad[:5]} are not manifold: their faces form more than one fan")
    used = {v for ring in rings for v in ring}
    euler = len(used) - len(directed) // 2 + len(rings)
    if euler != 2:
        out.append(f"Euler characteristic {euler}, not 2: not one simple closed shell")
    centre = vertices[sorted(used)].mean(axis=0)
    x = vertices - centre
    tris = np.array([(r[0], r[k], r[k + 1]) for r in rings for k in range(1, len(r) - 1)])
    a, b, c3 = x[tris[:, 0]], x[tris[:, 1]], x[tris[:, 2]]
    vol = float(np.einsum("ij,ij->", a, np.cross(b, c3))) / 6.0
    for f, ring in enumerate(rings):
        p = x[list(ring)]
        c = p.mean(axis=0)
        q = np.roll(p, -1, axis=0)
        u = np.array([np.dot(p[:, 1] - q[:, 1], p[:, 2] + q[:, 2]),
                      np.dot(p[:, 2] - q[:, 2], p[:, 0] + q[:, 0]),
                      np.dot(p[:, 0] - q[:, 0], p[:, 1] + q[:, 1])])  # Newell's normal
        size = float(np.sqrt(u @ u))
        if size == 0.0:
            out.append(f"face {f} has no area")
            continue
        dev = float(np.abs((p - c) @ (u / size)).max())
        if dev > planarity_m:
            out.append(f"face {f} is not planar: a vertex is {dev:.2g} m off its plane")
    if vol <= 0:
        out.append(f"the shell encloses a volume of {vol:.3g} m³: its normals point inward")
    return out


def check_solid(vertices: FloatArray, rings: Sequence[Sequence[int]], label: str,
                planarity_m: float = PLANARITY_M) -> None:
    """GeometryError naming ``label`` and every problem when the shell is not a valid solid."""
    problems = solid_problems(vertices, rings, planarity_m)
    if problems:
        raise GeometryError(f"{label}: not a valid solid: " + "; ".join(problems))
