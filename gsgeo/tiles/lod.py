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

from collections.abc import Iterator
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
    index: np.ndarray                 # splat indices held by this tile (sorted)
    lo: np.ndarray                    # box of the whole subtree (root frame, metres)
    hi: np.ndarray
    level: int
    name: str
    children: list[Node] = field(default_factory=list)
    start: int = 0                    # the tile's splats are TreeInput.perm[start:stop]
    stop: int = 0

    @property
    def geometric_error(self) -> float:
        if not self.children:
            return 0.0
        return float(np.linalg.norm(self.hi - self.lo)) * ERROR_PER_DIAGONAL

    def walk(self) -> Iterator[Node]:
        yield self
        for c in self.children:
            yield from c.walk()


def importance(alphas_u8: np.ndarray, scales_u8: np.ndarray) -> np.ndarray:
    """Prominence of SPZ-quantised splats: alpha x (s1 s2 s3)^(2/3) (a projected area)."""
    s = scales_u8.astype(np.int16)
    log_vol = (s[:, 0] + s[:, 1] + s[:, 2]).astype(np.float32) / 16.0 - 30.0
    return alphas_u8.astype(np.float32) * np.exp(log_vol * (2.0 / 3.0))


class TreeInput:
    """Splat centres, radii, keys and indices, permuted in place by :func:`build_tree_in_place`
    so that every tree node is one contiguous range. A node is split with index arithmetic
    on its own range and the columns are permuted once per node.

    ``pos_t`` (3, N) float32 centres (root frame, metres), ``radius`` (N,) float32 box radii,
    ``key`` (N,) float32 prominence (ties already broken), ``perm`` (N,) int32 splat indices.
    """

    def __init__(self, pos_t: np.ndarray, radius: np.ndarray, key: np.ndarray,
                 perm: np.ndarray) -> None:
        self.pos, self.radius, self.key, self.perm = pos_t, radius, key, perm

    @classmethod
    def from_splats(cls, pos: np.ndarray, radius: np.ndarray,
                    prominence: np.ndarray) -> TreeInput:
        """Copies of (N, 3) centres, radii and prominence; ties broken by index."""
        n = pos.shape[0]
        if n >= 2**31:
            raise ValueError("more than 2**31 splats")
        idx = np.arange(n, dtype=np.int32)
        return cls(np.array(np.asarray(pos).T, dtype=np.float32, order="C"),
                   np.array(radius, np.float32),
                   np.asarray(prominence, np.float32) * tie_breaker(idx), idx)

    def box(self, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Box of the splat centres in [a, b) grown by the largest splat radius there: a
        little loose but cheap, and a parent's box still contains its children's."""
        p = self.pos[:, a:b]
        r = float(self.radius[a:b].max())
        return p.min(axis=1).astype(np.float64) - r, p.max(axis=1).astype(np.float64) + r

    def columns(self) -> tuple[np.ndarray, ...]:
        """The arrays that are permuted together."""
        return (self.pos[0], self.pos[1], self.pos[2], self.radius, self.key, self.perm)

    def first_split(self, a: int, b: int, keep: int
                    ) -> tuple[np.ndarray, list[int], list[tuple[int, int]]]:
        """Stage one of :meth:`partition`, moving nothing: the order of [a, b) (offsets from
        a) with the ``keep`` largest keys first and the rest split at its median on the first
        split axis; the split axes (each whose spread over the node's splats is at least half
        the largest); and the halves of the rest as ranges of ``order[keep:]``."""
        m = b - a
        order = np.argpartition(-self.key[a:b], keep - 1) if keep < m else np.arange(m)
        p = self.pos[:, a:b]
        # the spread of the whole node: the kept splats lie all over it, and contiguous rows
        # reduce far faster than a gather of the rest
        spread = p.max(axis=1) - p.min(axis=1)
        axes = [ax for ax in np.argsort(-spread) if spread[ax] >= 0.5 * spread.max()] or [0]
        return order, axes, split_parts(p, order[keep:], axes[:1])

    def partition(self, a: int, b: int, keep: int) -> list[tuple[int, int]]:
        """Reorder [a, b): the ``keep`` largest keys first, then the rest split at medians,
        one split on each axis whose spread (over the node's splats) is at least half the
        largest (up to 8 parts).
        Returns the parts as ranges (the kept splats are [a, a + keep))."""
        order, axes, halves = self.first_split(a, b, keep)
        rest, p = order[keep:], self.pos[:, a:b]
        parts = [(lo + x, lo + y) for lo, hi in halves
                 for x, y in split_parts(p, rest[lo:hi], axes[1:])]
        for arr in self.columns():
            arr[a:b] = np.take(arr[a:b], order)
        base = a + keep
        return [(base + lo, base + hi) for lo, hi in parts if hi > lo]


def part_ranges(m: int, levels: int) -> list[tuple[int, int]]:
    """The parts (ranges of [0, m)) after ``levels`` rounds of median splits of every part
    of at least two: they depend on the sizes only."""
    parts = [(0, m)]
    for _ in range(levels):
        parts = [q for lo, hi in parts
                 for q in (((lo, lo + (hi - lo) // 2), (lo + (hi - lo) // 2, hi))
                           if hi - lo >= 2 else ((lo, hi),))]
    return parts


def split_parts(p: np.ndarray, rest: np.ndarray, axes: list[int]) -> list[tuple[int, int]]:
    """Split ``rest`` (column offsets into the centres ``p`` (3, M)) in place at its median
    along each of ``axes`` in turn, every part at each level; returns the parts as ranges of
    ``rest`` (:func:`part_ranges`). Parts of one level are independent, so the halves of a
    first split may be finished separately (in different processes) with the same result."""
    for level, ax in enumerate(axes):
        for lo, hi in part_ranges(rest.shape[0], level):
            if hi - lo >= 2:
                sub = rest[lo:hi]
                # np.take: a plain gather loop, faster than fancy indexing
                rest[lo:hi] = np.take(sub, np.argpartition(np.take(p[ax], sub), (hi - lo) // 2))
    return part_ranges(rest.shape[0], len(axes))


def tie_breaker(idx: np.ndarray) -> np.ndarray:
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

    Every node's ``index`` is sorted (tiles gather their attributes near-sequentially)."""
    return build_tree_in_place(TreeInput.from_splats(pos, radius, prominence),
                               max_splats=max_splats, parent_splats=parent_splats)


def build_tree_in_place(w: TreeInput, *, max_splats: int = 131_072,
                        parent_splats: int | None = None) -> Node:
    """The tile tree over ``w``, whose arrays are permuted in place: a level of the tree
    costs a few passes over N, not a gather of every node's subset. Each node's ``index``
    is ``w.perm[start:stop]``, sorted."""
    max_splats, parent_splats = tree_limits(max_splats, parent_splats)
    root = root_node(w)
    grow(w, root, 0, w.perm.shape[0], max_splats, parent_splats)
    attach_indices(w, root)
    return root


def tree_limits(max_splats: int, parent_splats: int | None) -> tuple[int, int]:
    if max_splats < 1:
        raise ValueError("max_splats must be positive")
    if parent_splats is None:
        parent_splats = max(1, max_splats // 4)
    return max_splats, min(parent_splats, max_splats)


def root_node(w: TreeInput) -> Node:
    n = w.perm.shape[0]
    lo, hi = w.box(0, n) if n else (np.zeros(3), np.zeros(3))
    return Node(w.perm[:0], lo, hi, 0, "0")


def expand(w: TreeInput, node: Node, a: int, b: int, max_splats: int,
           parent_splats: int) -> list[tuple[Node, int, int]]:
    """Make ``node`` (splats [a, b) of ``w``) a leaf, or a parent keeping the most prominent
    splats with children for the rest; returns the children still to expand. Only the
    range [a, b) of ``w`` is touched, so disjoint ranges may be expanded concurrently."""
    if b - a <= max_splats:
        w.perm[a:b].sort()
        node.start, node.stop = a, b
        return []
    parts = w.partition(a, b, parent_splats)
    w.perm[a:a + parent_splats].sort()
    node.start, node.stop = a, a + parent_splats
    out = []
    for i, (clo, chi) in enumerate(parts):
        blo, bhi = w.box(clo, chi)
        child = Node(w.perm[:0], blo, bhi, node.level + 1, f"{node.name}_{i}")
        node.children.append(child)
        out.append((child, clo, chi))
    return out


def grow(w: TreeInput, node: Node, a: int, b: int, max_splats: int, parent_splats: int) -> Node:
    """Expand ``node`` over [a, b) down to the leaves."""
    stack = [(node, a, b)]
    while stack:
        stack += expand(w, *stack.pop(), max_splats, parent_splats)
    return node


def attach_indices(w: TreeInput, root: Node) -> None:
    """Set every node's ``index`` to its (sorted) slice of ``w.perm``."""
    for nd in root.walk():
        nd.index = w.perm[nd.start:nd.stop]


def splat_radius(scales_u8: np.ndarray) -> np.ndarray:
    """Box radius per splat (metres) from SPZ-quantised log scales."""
    smax = np.maximum(np.maximum(scales_u8[:, 0], scales_u8[:, 1]), scales_u8[:, 2])
    smax = smax.astype(np.float32) / 16.0 - 10.0
    return np.minimum(EXTENT_SIGMAS * np.exp(smax), EXTENT_CAP_M)
