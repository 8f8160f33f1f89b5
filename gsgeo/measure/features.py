"""Lengths, areas and perimeters of lines and polygons built from measured points, with sigmas.

Plain numpy over grid coordinates; no CRS, no I/O. The caller passes the points of one line or
polygon in order:

- ``xyz`` (N, 3): easting, northing, height in the grid CRS's units (height may be NaN when
  unknown; 3-D values then come back None);
- ``cov`` (N, 3, 3) or None: each point's covariance in (E, N, H), **m²** (gsgeo.crs keeps
  covariances in metres even where the CRS's unit is the foot);
- ``unit_m`` / ``vertical_unit_m``: metres per unit of E, N and of H (1.0 for metric CRSs).

Results are in metres and m². Lengths and areas are *grid* values (the projection's scale
factor included), as a GIS computes them in that CRS.

Standard deviations come from first-order propagation, var = Σᵢ gᵢᵀ Σᵢ gᵢ, with gᵢ the gradient
of the quantity with respect to point i. Points are taken as uncorrelated: each is intersected
from its own rays. (The datum transformation's offset is shared by all points and moves no
length or area.) tests/test_export_features.py checks the sigmas against Monte-Carlo runs.
"""

from __future__ import annotations

import functools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from gsgeo.errors import GeometryError, InputError
from gsgeo.solve.linalg import FloatArray


@dataclass
class LineMeasures:
    """Length of a polyline through N points (metres) and their 1-sigma standard deviations."""

    n_points: int
    length_2d: float
    sigma_length_2d: float | None  # None without covariances
    length_3d: float | None  # None when a height is unknown
    sigma_length_3d: float | None


@dataclass
class PolygonMeasures:
    """Area (m²) and perimeter (m) of a closed ring of N distinct points, with 1-sigma values.

    ``counterclockwise`` tells the orientation of the points as given, in (E, N).
    """

    n_points: int
    area_2d: float
    sigma_area_2d: float | None
    perimeter_2d: float
    sigma_perimeter_2d: float | None
    counterclockwise: bool


def _name(ids: Sequence[str] | None, i: int) -> str:
    return f"'{ids[i]}'" if ids is not None else f"point {i + 1}"


def _check(xyz: ArrayLike, cov: ArrayLike | None, ids: Sequence[str] | None,
           what: str) -> tuple[np.ndarray, np.ndarray | None]:
    p = np.asarray(xyz, dtype=np.float64)
    if p.ndim != 2 or p.shape[1] not in (2, 3):
        raise InputError(f"the {what}'s coordinates must be an N x 3 array (E, N, H), got shape "
                         f"{p.shape}")
    if p.shape[1] == 2:
        p = np.column_stack([p, np.full(p.shape[0], np.nan)])
    if ids is not None and len(ids) != p.shape[0]:
        raise InputError(f"the {what} has {len(ids)} ids for {p.shape[0]} points")
    bad = ~np.all(np.isfinite(p[:, :2]), axis=1)
    if bad.any():
        raise InputError(f"the {what}'s point {_name(ids, int(np.flatnonzero(bad)[0]))} has no "
                         "finite easting/northing")
    c = None
    if cov is not None:
        c = np.asarray(cov, dtype=np.float64)
        if c.shape != (p.shape[0], 3, 3):
            raise InputError(f"the {what}'s covariances must be N x 3 x 3 (m²), got shape "
                             f"{c.shape}")
        if not np.all(np.isfinite(c[:, :2, :2])):
            raise InputError(f"the {what}'s covariances contain NaN or infinite values")
    return p, c


def _variance(grad: np.ndarray, cov: np.ndarray) -> float:
    """Σᵢ gᵢᵀ Σᵢ gᵢ for gradients (N, 3) and covariances (N, 3, 3); NaN entries where g is 0 ignored."""
    c = np.where(grad[:, :, None] * grad[:, None, :] != 0, cov, 0.0)
    return float(max(np.einsum("ni,nij,nj->", grad, c, grad), 0.0))


@functools.lru_cache(maxsize=64)
def _next(n: int) -> np.ndarray:
    return np.r_[1:n, 0]


@functools.lru_cache(maxsize=64)
def _prev(n: int) -> np.ndarray:
    return np.r_[n - 1, 0:n - 1]


@functools.lru_cache(maxsize=64)
def _edge_pairs(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Pairs (i < j) of non-adjacent edges of a closed ring of n edges."""
    i, j = np.triu_indices(n, k=2)
    keep = ~((i == 0) & (j == n - 1))  # first and last edges share point 0
    return i[keep], j[keep]


def _path_length(p: np.ndarray, dims: int, closed: bool) -> tuple[float, np.ndarray]:
    """Length of the path through p[:, :dims] and its gradient (N, 3) w.r.t. every point."""
    q = p[:, :dims]
    d = (q[_next(q.shape[0])] - q) if closed else (q[1:] - q[:-1])
    seg = np.sqrt(np.einsum("ki,ki->k", d, d))
    u = np.divide(d, seg[:, None], out=np.zeros_like(d), where=seg[:, None] > 0)
    g = np.zeros((p.shape[0], 3))
    if closed:
        g[:, :dims] = u[_prev(u.shape[0])] - u  # edge k runs from point k to point k+1
    else:
        g[1:, :dims] += u
        g[:-1, :dims] -= u
    return float(seg.sum()), g


def line_measures(xyz: ArrayLike, cov: ArrayLike | None = None, ids: Sequence[str] | None = None,
                  *, unit_m: float = 1.0,
                  vertical_unit_m: float = 1.0) -> LineMeasures:
    """3-D and 2-D length of the polyline through the points in order, with 1-sigma values.

    Parameters
    ----------
    xyz : (N, 3) easting, northing, height in the CRS's units; NaN height: no 3-D length.
    cov : (N, 3, 3) covariances in (E, N, H), m², or None (no sigmas).
    ids : the points' ids, used in error messages only.
    unit_m, vertical_unit_m : metres per coordinate unit (horizontal, vertical).

    Raises InputError for malformed arrays and GeometryError for fewer than 2 distinct points.
    """
    p, c = _check(xyz, cov, ids, "line")
    p = p * np.array([unit_m, unit_m, vertical_unit_m])
    if p.shape[0] < 2 or np.all(p[1:, :2] == p[0, :2]):
        raise GeometryError(f"a line needs at least 2 distinct points, got {p.shape[0]}"
                            + (" (all at the same position)" if p.shape[0] >= 2 else ""))
    l2, g2 = _path_length(p, 2, closed=False)
    s2 = None if c is None else float(np.sqrt(_variance(g2, c)))
    l3 = s3 = None
    if np.all(np.isfinite(p[:, 2])):
        l3, g3 = _path_length(p, 3, closed=False)
        if c is not None and np.all(np.isfinite(c)):
            s3 = float(np.sqrt(_variance(g3, c)))
    return LineMeasures(int(p.shape[0]), l2, s2, l3, s3)


def _orient(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """Sign of the turn a -> b -> c (cross product z), vectorised over leading axes."""
    return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                   - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))


def _on_segment(a: np.ndarray, b: np.ndarray, c: np.ndarray) -> np.ndarray:
    """c within the bounding box of segment a-b (for collinear points)."""
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    return np.all((lo <= c) & (c <= hi), axis=-1)


def _edges_touch(a: np.ndarray, b: np.ndarray, i: np.ndarray, j: np.ndarray) -> np.ndarray:
    """Whether edges a[i]-b[i] and a[j]-b[j] touch or cross, for rings (..., N, 2): (..., pairs)."""
    p1, p2, p3, p4 = a[..., i, :], b[..., i, :], a[..., j, :], b[..., j, :]
    o1, o2 = _orient(p1, p2, p3), _orient(p1, p2, p4)
    o3, o4 = _orient(p3, p4, p1), _orient(p3, p4, p2)
    hit = (o1 * o2 < 0) & (o3 * o4 < 0)
    hit |= (o1 == 0) & _on_segment(p1, p2, p3)
    hit |= (o2 == 0) & _on_segment(p1, p2, p4)
    hit |= (o3 == 0) & _on_segment(p3, p4, p1)
    hit |= (o4 == 0) & _on_segment(p3, p4, p2)
    return hit


def ring_self_intersection(xy: np.ndarray) -> tuple[int, int] | None:
    """First pair of edges (k, m) of the closed ring xy (N, 2) that touch or cross, else None.

    Edge k runs from point k to point k+1 (mod N). Adjacent edges count when they fold back
    onto each other. Exact orientation tests on coordinates centred at their mean.
    """
    q = np.asarray(xy, dtype=np.float64)
    q = q - q.mean(axis=0)
    n = q.shape[0]
    a, b = q, q[_next(n)]
    i, j = _edge_pairs(n)
    if i.size:
        hit = _edges_touch(a, b, i, j)
        if hit.any():
            k = int(np.flatnonzero(hit)[0])
            return int(i[k]), int(j[k])
    # Adjacent edges k and k+1 fold back: collinear with opposite directions.
    d0 = b - a
    d1 = d0[_next(n)]
    cross = d0[:, 0] * d1[:, 1] - d0[:, 1] * d1[:, 0]
    fold = (cross == 0) & (np.einsum("ki,ki->k", d0, d1) < 0)
    if fold.any():
        k = int(np.flatnonzero(fold)[0])
        return k, (k + 1) % n
    return None


def polygon_measures(xyz: ArrayLike, cov: ArrayLike | None = None,
                     ids: Sequence[str] | None = None, *, unit_m: float = 1.0,
                     vertical_unit_m: float = 1.0) -> PolygonMeasures:
    """Area and perimeter (2-D, in E, N) of the polygon through the points, with 1-sigma values.

    The ring closes itself: give the points once each (a last point equal to the first is
    dropped). Parameters as for `line_measures`; heights play no part.

    Raises GeometryError for fewer than 3 distinct points, a repeated point, a
    self-intersecting (or self-touching) ring, or collinear points (zero area).
    """
    p, c = _check(xyz, cov, ids, "polygon")
    ids = list(ids) if ids is not None else None
    given = p.shape[0]  # the count the caller gave, before dropping a closing point
    if p.shape[0] >= 2 and np.all(p[-1, :2] == p[0, :2]):
        p = p[:-1]
        c = None if c is None else c[:-1]
        ids = None if ids is None else ids[:-1]
    n = p.shape[0]
    xy = p[:, :2] * unit_m
    same = np.all(xy[:, None, :] == xy[None, :, :], axis=-1)  # small n: pairwise is cheapest
    repeat = np.triu(same, k=1).any(axis=0)  # point j equals an earlier point
    distinct = n - int(repeat.sum())
    if n < 3 or distinct < 3:
        raise GeometryError(
            f"a polygon needs at least 3 distinct points, got {distinct}"
            + (f" (of {given} given)" if given != distinct else ""))
    if distinct < n:
        k = int(np.flatnonzero(repeat)[0])
        raise GeometryError(f"the polygon visits {_name(ids, k)} (or its position) more than once")
    hit = ring_self_intersection(xy)
    if hit is not None:
        k, m = hit

        def edge(e: int) -> str:
            return f"{_name(ids, e)}-{_name(ids, (e + 1) % n)}"

        raise GeometryError(f"the polygon is self-intersecting: edge {edge(k)} meets edge {edge(m)}")
    q = xy - xy.mean(axis=0)
    nxt, prv = q[_next(n)], q[_prev(n)]
    signed = 0.5 * float(np.sum(q[:, 0] * nxt[:, 1] - nxt[:, 0] * q[:, 1]))
    if signed == 0.0:
        raise GeometryError("the polygon's points are collinear: its area is zero")
    sgn = 1.0 if signed > 0 else -1.0
    g_area = np.zeros((n, 3))
    g_area[:, 0] = 0.5 * sgn * (nxt[:, 1] - prv[:, 1])
    g_area[:, 1] = 0.5 * sgn * (prv[:, 0] - nxt[:, 0])
    perim, g_perim = _path_length(np.column_stack([xy, np.zeros(n)]), 2, closed=True)
    s_area = s_perim = None
    if c is not None:
        s_area = float(np.sqrt(_variance(g_area, c)))
        s_perim = float(np.sqrt(_variance(g_perim, c)))
    return PolygonMeasures(n, abs(signed), s_area, perim, s_perim, signed > 0)


# Many lines or polygons at once -----------------------------------------------------------------
# The functions below give what line_measures / polygon_measures give, vectorised over all
# features of one vertex count. They do not raise: a feature that fails any check of the
# single-feature function (or one they cannot be sure of) is flagged not ok, its values NaN;
# the caller passes it to the single-feature function, which raises the error or gives its values.


@dataclass
class LineArrays:
    """line_measures of K lines as arrays (NaN where the single function gives None)."""

    n_points: np.ndarray  # (K,) int
    length_2d: FloatArray
    sigma_length_2d: FloatArray
    length_3d: FloatArray
    sigma_length_3d: FloatArray


@dataclass
class PolygonArrays:
    """polygon_measures of K polygons as arrays."""

    n_points: np.ndarray  # (K,) int
    area_2d: FloatArray
    sigma_area_2d: FloatArray
    perimeter_2d: FloatArray
    sigma_perimeter_2d: FloatArray
    counterclockwise: np.ndarray  # (K,) bool


def _groups(sizes: np.ndarray) -> Iterator[tuple[int, np.ndarray]]:
    """(n, indices of the features with n points) for each distinct size."""
    for n in np.unique(sizes):
        yield int(n), np.flatnonzero(sizes == n)


def _variance_many(grad: np.ndarray, cov: np.ndarray) -> np.ndarray:
    """_variance for (K, N, 3) gradients and (K, N, 3, 3) covariances."""
    c = np.where(grad[..., :, None] * grad[..., None, :] != 0, cov, 0.0)
    return np.maximum(np.einsum("kni,knij,knj->k", grad, c, grad), 0.0)


def _path_length_many(p: np.ndarray, dims: int, closed: bool) -> tuple[np.ndarray, np.ndarray]:
    """_path_length for (K, N, 3) points: lengths (K,) and gradients (K, N, 3)."""
    q = p[..., :dims]
    n = q.shape[1]
    d = (q[:, _next(n)] - q) if closed else (q[:, 1:] - q[:, :-1])
    seg = np.sqrt(np.einsum("kni,kni->kn", d, d))
    u = np.divide(d, seg[..., None], out=np.zeros_like(d), where=seg[..., None] > 0)
    g = np.zeros(p.shape[:2] + (3,))
    if closed:
        g[..., :dims] = u[:, _prev(n)] - u
    else:
        g[:, 1:, :dims] += u
        g[:, :-1, :dims] -= u
    return seg.sum(axis=1), g


def _finite_cov(cov: np.ndarray) -> np.ndarray:
    return np.all(np.isfinite(cov[..., :2, :2]), axis=(1, 2, 3))


def line_measures_many(xyz: Sequence[np.ndarray], cov: Sequence[np.ndarray], *,
                       unit_m: float = 1.0, vertical_unit_m: float = 1.0
                       ) -> tuple[LineArrays, np.ndarray]:
    """`line_measures` of many lines: (measures, ok). xyz[k] (N_k, 3), cov[k] (N_k, 3, 3), m²."""
    k_all = len(xyz)
    sizes = np.fromiter(map(len, xyz), dtype=np.int64, count=k_all)
    out = LineArrays(sizes.copy(), *(np.full(k_all, np.nan) for _ in range(4)))
    ok = np.zeros(k_all, dtype=bool)
    scale = np.array([unit_m, unit_m, vertical_unit_m])
    for n, sel in _groups(sizes):
        if n < 2:
            continue
        p = np.stack([np.asarray(xyz[i], dtype=np.float64) for i in sel]) * scale
        c = np.stack([np.asarray(cov[i], dtype=np.float64) for i in sel])
        good = (np.all(np.isfinite(p[..., :2]), axis=(1, 2)) & _finite_cov(c)
                & np.any(p[:, 1:, :2] != p[:, :1, :2], axis=(1, 2)))
        l2, g2 = _path_length_many(p, 2, closed=False)
        out.length_2d[sel] = l2
        out.sigma_length_2d[sel] = np.sqrt(_variance_many(g2, c))
        h = np.all(np.isfinite(p[..., 2]), axis=1)
        l3, g3 = _path_length_many(p, 3, closed=False)
        out.length_3d[sel] = np.where(h, l3, np.nan)
        s3 = np.sqrt(_variance_many(g3, np.where(np.isfinite(c), c, 0.0)))
        out.sigma_length_3d[sel] = np.where(h & np.all(np.isfinite(c), axis=(1, 2, 3)), s3, np.nan)
        ok[sel] = good
    return out, ok


def polygon_measures_many(xyz: Sequence[np.ndarray], cov: Sequence[np.ndarray], *,
                          unit_m: float = 1.0) -> tuple[PolygonArrays, np.ndarray]:
    """`polygon_measures` of many polygons: (measures, ok). Rings given once each (not closed)."""
    k_all = len(xyz)
    sizes = np.fromiter(map(len, xyz), dtype=np.int64, count=k_all)
    out = PolygonArrays(sizes.copy(), np.full(k_all, np.nan), np.full(k_all, np.nan),
                        np.full(k_all, np.nan), np.full(k_all, np.nan), np.zeros(k_all, dtype=bool))
    ok = np.zeros(k_all, dtype=bool)
    for n, sel in _groups(sizes):
        if n < 3:
            continue
        p = np.stack([np.asarray(xyz[i], dtype=np.float64) for i in sel])
        c = np.stack([np.asarray(cov[i], dtype=np.float64) for i in sel])
        xy = p[..., :2] * unit_m
        good = np.all(np.isfinite(p[..., :2]), axis=(1, 2)) & _finite_cov(c)
        good &= ~np.all(p[:, -1, :2] == p[:, 0, :2], axis=1)  # closed explicitly: single path
        same = np.all(xy[:, :, None, :] == xy[:, None, :, :], axis=-1)
        good &= ~np.triu(same, k=1).any(axis=(1, 2))
        q = xy - xy.mean(axis=1, keepdims=True)
        a, b = q, q[:, _next(n)]
        i, j = _edge_pairs(n)
        if i.size:
            good &= ~_edges_touch(a, b, i, j).any(axis=1)
        d0 = b - a
        d1 = d0[:, _next(n)]
        cross = d0[..., 0] * d1[..., 1] - d0[..., 1] * d1[..., 0]
        good &= ~((cross == 0) & (np.einsum("kni,kni->kn", d0, d1) < 0)).any(axis=1)
        nxt, prv = q[:, _next(n)], q[:, _prev(n)]
        signed = 0.5 * np.sum(q[..., 0] * nxt[..., 1] - nxt[..., 0] * q[..., 1], axis=1)
        good &= signed != 0.0
        sgn = np.where(signed > 0, 1.0, -1.0)[:, None]
        g_area = np.zeros(p.shape[:2] + (3,))
        g_area[..., 0] = 0.5 * sgn * (nxt[..., 1] - prv[..., 1])
        g_area[..., 1] = 0.5 * sgn * (prv[..., 0] - nxt[..., 0])
        flat = np.concatenate([xy, np.zeros(xy.shape[:2] + (1,))], axis=-1)
        perim, g_perim = _path_length_many(flat, 2, closed=True)
        out.area_2d[sel] = np.abs(signed)
        out.sigma_area_2d[sel] = np.sqrt(_variance_many(g_area, c))
        out.perimeter_2d[sel] = perim
        out.sigma_perimeter_2d[sel] = np.sqrt(_variance_many(g_perim, c))
        out.counterclockwise[sel] = signed > 0
        ok[sel] = good
    return out, ok
