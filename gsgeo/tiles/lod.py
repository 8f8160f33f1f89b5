"""Level of detail: a balanced spatial tree with a bounded number of splats per tile.

The tree is a k-d tree split at medians, up to 8 children per node (one median split on
each axis whose spread is at least half of the largest, so flat scenes become quadtrees).
Refinement is ADD: every input splat is in exactly one tile. A node with more than
``max_splats`` splats keeps the ``parent_splats`` most prominent of them — largest
opacity x projected area, i.e. those that dominate a distant view — and hands the rest to
its children; a node with at most ``max_splats`` is a leaf holding all of them. Full detail
(all tiles loaded) is therefore exactly the input.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: A splat's box extent is three standard deviations, capped so floaters do not inflate tiles.
EXTENT_SIGMAS = 3.0
EXTENT_CAP_M = 2.0
#: geometricError of an internal tile = this fraction of its box diagonal (leaves: 0). With
#: Cesium's default maximumScreenSpaceError of 16, children load once the camera is within
#: roughly 8 box diagonals at 1000 px canvas height.
ERROR_PER_DIAGONAL = 0.25


@dataclass
class Node:
    index: np.ndarray                 # splat indices held by this tile
    lo: np.ndarray                    # box of the whole subtree (root frame, metres)
    hi: np.ndarray
    level: int
    name: str
    children: list[Node] = field(default_factory=list)

    @property
    def geometric_error(self) -> float:
        if not self.children:
            return 0.0
        return float(np.linalg.norm(self.hi - self.lo)) * ERROR_PER_DIAGONAL

    def walk(self):
        yield self
        for c in self.children:
            yield from c.walk()


def importance(alphas_u8: np.ndarray, scales_u8: np.ndarray) -> np.ndarray:
    """Prominence of SPZ-quantised splats: alpha x (s1 s2 s3)^(2/3) (a projected area)."""
    log_vol = scales_u8.astype(np.float32).sum(axis=1) / 16.0 - 30.0
    return alphas_u8.astype(np.float32) * np.exp(log_vol * (2.0 / 3.0))


def _split(pos_t: np.ndarray, radius: np.ndarray, idx: np.ndarray):
    """Split indices at medians; returns (indices, lo, hi) per child. pos_t is (3, N)."""
    p = pos_t[:, idx]
    r = radius[idx]
    spread = p.max(axis=1) - p.min(axis=1)
    axes = [a for a in np.argsort(-spread) if spread[a] >= 0.5 * spread.max()] or [0]
    parts = [np.arange(idx.shape[0])]
    for a in axes:
        nxt = []
        for part in parts:
            if part.shape[0] < 2:
                nxt.append(part)
                continue
            half = part.shape[0] // 2
            order = np.argpartition(p[a, part], half)
            nxt += [part[order[:half]], part[order[half:]]]
        parts = nxt
    out = []
    for part in parts:
        if part.shape[0]:
            # centres' box grown by the largest splat radius: a little loose but cheap, and
            # a parent's box still contains its children's
            pp, rr = p[:, part], r[part].max()
            out.append((idx[np.sort(part)], pp.min(axis=1) - rr, pp.max(axis=1) + rr))
    return out


def _tie_breaker(idx: np.ndarray) -> np.ndarray:
    """Factors in [1, 1 + 1e-4) from a hash of the splat index.

    Prominence comes from quantised bytes, so many splats tie; without this the parent would
    keep the tied splats in file order, i.e. a strip of the scene. The factor is far below
    one quantisation step (about 4 % in area), so it only reorders ties, and it is
    deterministic.
    """
    h = (idx.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFFFF)
    return 1.0 + h.astype(np.float32) * np.float32(1e-4 / 2**32)


def build_tree(pos: np.ndarray, radius: np.ndarray, prominence: np.ndarray, *,
               max_splats: int = 131_072, parent_splats: int | None = None) -> Node:
    """Build the tile tree over splat centres ``pos`` (N, 3) with box radii ``radius`` (N,).

    Parents' indices are not sorted; sort them before gathering attributes."""
    if max_splats < 1:
        raise ValueError("max_splats must be positive")
    if parent_splats is None:
        parent_splats = max(1, max_splats // 4)
    parent_splats = min(parent_splats, max_splats)
    n = pos.shape[0]
    idx_dtype = np.int32 if n < 2**31 else np.int64
    pos_t = np.ascontiguousarray(np.asarray(pos).T)
    root_idx = np.arange(n, dtype=idx_dtype)
    if n:
        r = radius.max()
        lo, hi = pos_t.min(axis=1) - r, pos_t.max(axis=1) + r
    else:
        lo, hi = np.zeros(3), np.zeros(3)
    root = Node(root_idx, lo, hi, 0, "0")
    stack = [root]
    while stack:
        node = stack.pop()
        idx = node.index
        if idx.shape[0] <= max_splats:
            continue
        order = np.argpartition(-(prominence[idx] * _tie_breaker(idx)), parent_splats - 1)
        # argpartition scrambles the order; sorted indices keep gathers near-sequential
        node.index, rest = idx[order[:parent_splats]], np.sort(idx[order[parent_splats:]])
        for i, (part, clo, chi) in enumerate(_split(pos_t, radius, rest)):
            child = Node(part, clo, chi, node.level + 1, f"{node.name}_{i}")
            node.children.append(child)
            stack.append(child)
    return root


def splat_radius(scales_u8: np.ndarray) -> np.ndarray:
    """Box radius per splat (metres) from SPZ-quantised log scales."""
    smax = scales_u8.max(axis=1).astype(np.float32) / 16.0 - 10.0
    return np.minimum(EXTENT_SIGMAS * np.exp(smax), EXTENT_CAP_M)
