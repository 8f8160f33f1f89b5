"""`build_tileset`: 3DGS PLY/SPZ -> georeferenced OGC 3D Tiles 1.1 of SPZ-compressed glTF splats.

Pipeline: bounds of the input (a sample of the centres) -> scene centre and root ENU frame ->
blocks of splats turned into the root frame and quantised to SPZ bytes by worker processes
into shared memory (80 bytes a splat at SH degree 3, and 52 for the tree's columns) ->
tile tree (the root's prominent splats and first split in the parent, the rest of the root's
split and the subtrees in the workers) -> tiles packed,
compressed and written by the workers into a temporary directory beside OUTDIR, which is
marked as ours and swapped into place at the end (gsgeo.tiles.outdir says which OUTDIR may
be written or replaced, gsgeo.tiles.swap how).
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TextIO, cast

import numpy as np

from gsgeo.crs.ellipsoid import ecef_to_geodetic_closed_form
from gsgeo.errors import InputError
from gsgeo.tiles import gltf, lod, spz, swap
from gsgeo.tiles import outdir as outdir_mod
from gsgeo.tiles.georef import Georeference
from gsgeo.tiles.georefhistory import initial_extras
from gsgeo.tiles.placement import Placement
from gsgeo.tiles.source import Source, open_source
from gsgeo.tiles.workers import Imap, cpu_count, pool, shared_empty

#: Splats per task of the quantising pass: small enough that a block's temporaries stay in
#: the CPU caches, large enough that numpy's per-call overhead is small.
BLOCK = 16_384
#: Below this many splats the work is done in the calling process (forking costs more).
PARALLEL_MIN_SPLATS = 200_000


#: Fractional bits of SPZ positions for a scene tiled without georeference (at most; fewer
#: when its extent needs the range): 1/262144 of a unit, e.g. 0.08 mm for a 20 m unit.
LOCAL_FRACTIONAL_BITS = 18

@dataclass
class Summary:
    input: str
    output: str
    splats_in: int
    splats_written: int
    dropped_nonfinite: int
    sh_degree: int
    tiles: int
    levels: int
    georeference: str
    operation_accuracy_m: float | None
    root_lon_lat_h: tuple[float, float, float]
    bounds_lon_lat_h: dict
    fractional_bits: int
    spz_version: int
    seconds: float
    warnings: list[str] = field(default_factory=list)

    def to_dict(self) -> dict:
        return asdict(self)

    def text(self) -> str:
        b = self.bounds_lon_lat_h
        lines = [
            f"tileset        {self.output}/tileset.json",
            f"splats         {self.splats_written:,} written of {self.splats_in:,} read"
            + (f" ({self.dropped_nonfinite:,} with NaN/inf dropped)" if self.dropped_nonfinite
               else ""),
            f"SH degree      {self.sh_degree}",
            f"tiles          {self.tiles} in {self.levels} level(s), refine ADD "
            "(parents hold the most prominent splats, every splat is in one tile)",
            f"georeference   {self.georeference}",
            f"root (ENU)     lon {self.root_lon_lat_h[0]:.8f}, lat {self.root_lon_lat_h[1]:.8f}, "
            f"h {self.root_lon_lat_h[2]:.3f} m (WGS 84)",
            f"bounds         lon {b['lon'][0]:.7f} .. {b['lon'][1]:.7f}, "
            f"lat {b['lat'][0]:.7f} .. {b['lat'][1]:.7f}, h {b['h'][0]:.2f} .. {b['h'][1]:.2f} m",
            f"SPZ            file version {self.spz_version}, {self.fractional_bits} fractional "
            f"bits ({1000 / 2 ** self.fractional_bits:.2f} mm steps)",
            f"time           {self.seconds:.1f} s "
            f"({self.splats_written / max(self.seconds, 1e-9):,.0f} splats/s)",
        ]
        lines += [f"warning        {w}" for w in self.warnings]
        return "\n".join(lines)


class Progress:
    """A one-line progress bar on a stream (stderr), redrawn at most ten times a second."""

    def __init__(self, stream: TextIO | None, total: int, label: str) -> None:
        self.stream, self.total, self.label = stream, max(total, 1), label
        self.done, self._last = 0, 0.0
        self.t0 = time.monotonic()

    def update(self, n: int) -> None:
        self.done += n
        now = time.monotonic()
        if self.stream is not None and (now - self._last > 0.1 or self.done >= self.total):
            self._last = now
            f = min(self.done / self.total, 1.0)
            bar = "#" * int(f * 30)
            self.stream.write(f"\r{self.label:<10} [{bar:<30}] {f * 100:5.1f}% "
                              f"{now - self.t0:6.1f} s")
            self.stream.flush()

    def close(self) -> None:
        if self.stream is not None:
            self._last = 0.0
            self.update(0)
            self.stream.write("\n")
            self.stream.flush()


def _prepare_outdir(out: Path, outdir: Path) -> Path:
    """Create the parent of ``out`` (OUTDIR ``outdir`` checked and resolved), remove stale
    temporaries of killed runs beside it and make this run's temporary directory there."""
    try:
        out.parent.mkdir(parents=True, exist_ok=True)
        swap.clean_stale(out.parent)
        return swap.make_temp(out)
    except FileExistsError:
        raise InputError(f"-o {outdir}: {out.parent} is not a directory") from None
    except OSError as exc:
        raise InputError(f"-o {outdir}: cannot write a directory in {out.parent} "
                         f"({exc.strerror})") from None


def _commit(tmp: Path, outdir: Path) -> None:
    """Mark the finished temporary directory as ours and swap it into place (an old OUTDIR
    is removed only after; see gsgeo.tiles.swap)."""
    # mkdtemp makes the directory 0700; a tileset is served and shared like any output
    # directory, so give it the mode a plain mkdir would (0777 less the umask).
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)
    try:
        outdir_mod.write_marker(tmp)
        swap.commit(tmp, outdir)
    except OSError as exc:
        raise InputError(f"{outdir}: cannot put the finished tileset in place "
                         f"({exc.strerror})") from None


def _colmajor(m: np.ndarray) -> list[float]:
    return [float(v) for v in np.asarray(m).T.reshape(-1)]


def _box(lo: np.ndarray, hi: np.ndarray) -> list[float]:
    c = (lo + hi) / 2
    h = np.maximum((hi - lo) / 2, 1e-3)
    return [float(c[0]), float(c[1]), float(c[2]), float(h[0]), 0.0, 0.0,
            0.0, float(h[1]), 0.0, 0.0, 0.0, float(h[2])]


def _content_ext() -> dict:
    exts = [gltf.EXT, gltf.EXT_SPZ]
    return {"3DTILES_content_gltf": {"extensionsUsed": exts, "extensionsRequired": exts}}


def _tile_json(node: lod.Node) -> dict:
    t = {"boundingVolume": {"box": _box(node.lo, node.hi)},
         "geometricError": node.geometric_error, "refine": "ADD"}
    if node.index.shape[0]:
        t["content"] = {"uri": f"tiles/{node.name}.glb"}
    if node.children:
        t["children"] = [_tile_json(c) for c in node.children]
    return t


def write_tileset_json(path: Path, root: lod.Node, root_transform: np.ndarray,
                       extra: dict | None = None) -> None:
    tile = _tile_json(root)
    tile["transform"] = _colmajor(root_transform)
    doc = {
        "asset": {"version": "1.1", "generator": "gsgeo tiles"},
        "geometricError": max(float(np.linalg.norm(root.hi - root.lo)), root.geometric_error),
        "extensionsUsed": ["3DTILES_content_gltf"],
        "extensionsRequired": ["3DTILES_content_gltf"],
        "extensions": _content_ext(),
        "root": tile,
    }
    if extra:
        doc["extras"] = extra
    path.write_text(json.dumps(doc, indent=1))


@dataclass
class WorkerJob:
    """What forked workers read (set before the pool forks; see gsgeo.tiles.workers)."""
    source: Source
    placement: Placement
    held: spz.SpzBytes          # arrays in shared memory, one row per input splat
    tree: lod.TreeInput         # the tile tree's inputs, shared too, filled with held
    spz_version: int
    sh_degree: int
    level: int
    # for the root split in the workers (None when it is done in one process): a second set
    # of tree columns the root's halves are moved into, and the root's order of the splats
    tree2: lod.TreeInput | None = None
    order: np.ndarray | None = None

    def trees(self, t: int) -> lod.TreeInput:
        if t:
            # t == 1 only comes from build_tree's root split, which needs tree2
            return cast(lod.TreeInput, self.tree2)
        return self.tree


WORKER_JOB: WorkerJob | None = None
#: One build at a time per process: the workers' state is the module-level WORKER_JOB.
_BUILD_LOCK = threading.Lock()


def _job() -> WorkerJob:
    """The build this (forked) process works for: WORKER_JOB, set before the pool forks."""
    job = WORKER_JOB
    if job is None:
        raise RuntimeError("no tiles build is running in this process")
    return job


def _quantise_blocks(task: tuple[int, int, int]) -> list[tuple[int, int, float]]:
    """:func:`_quantise_block` over [start, stop) in blocks of ``block`` splats (one task
    holds several blocks: fewer messages between the processes, smaller temporaries)."""
    start, stop, block = task
    return [_quantise_block(a, min(stop, a + block)) for a in range(start, stop, block)]


def _quantise_block(start: int, stop: int) -> tuple[int, int, float]:
    """Read splats [start, stop), drop non-finite ones, turn them into the root frame and
    quantise them into held rows [start, start + kept), with the tree's inputs. Returns
    (start, kept, largest |coordinate| in metres)."""
    job = _job()
    s, ok = job.source.read_finite(start, stop)
    if not ok.all():
        s = s.take(ok)
    m, extent = s.count, 0.0
    if m:
        end = start + m
        q = spz.quantize(job.placement.apply(s), job.spz_version,
                         out=job.held.take(slice(start, end)))
        t = job.tree
        t.pos[:, start:end] = q.positions.T
        t.radius[start:end] = lod.splat_radius(q.scales)
        t.key[start:end] = lod.importance(q.alphas, q.scales) * lod.tie_breaker(
            np.arange(start, end, dtype=np.int64))
        t.perm[start:end] = np.arange(start, end, dtype=np.int32)
        extent = float(np.abs(q.positions).max())
    return start, m, extent


RootHalfPart = tuple[int, int, np.ndarray, np.ndarray, "lod.Node | None"]


def _finish_root_half(task: tuple[int, int, int, list[int], int, int, tuple[int, int] | None]
                      ) -> list[RootHalfPart]:
    """Finish the root's split on one half of its rest (``job.order[keep + lo:keep + hi]``,
    offsets into the first tree columns; the remaining axes), move that half's columns into
    the second set and return its non-empty parts as (lo, hi, box lo, box hi, node), ranges
    of the rest. With ``grow`` (max_splats, parent_splats), the parts become the root's
    children from number ``first`` on, grown to the leaves here (``node``; else None)."""
    keep, lo, hi, axes, n, first, grow = task
    job = _job()
    # the root split in the workers runs only with both (see build_tree)
    src, dst = job.tree, cast(lod.TreeInput, job.tree2)
    idx = cast(np.ndarray, job.order)[keep + lo:keep + hi]
    parts = lod.split_parts(src.pos[:, :n], idx, axes)
    for s, d in zip(src.columns(), dst.columns(), strict=True):
        np.take(s, idx, out=d[keep + lo:keep + hi], mode="clip")
    out: list[RootHalfPart] = []
    for x, y in parts:
        if y > x:
            a, b = keep + lo + x, keep + lo + y
            blo, bhi = dst.box(a, b)
            node = None
            if grow:
                node = lod.grow(dst, lod.Node(dst.perm[:0], blo, bhi, 1, f"0_{first + len(out)}"),
                                a, b, *grow)
            out.append((lo + x, lo + y, blo, bhi, node))
    return out


def _grow_subtree(task: tuple[int, lod.Node, int, int, int, int]) -> lod.Node:
    """Grow the subtree of a node over the range [a, b) of tree columns t in place."""
    t, node, a, b, max_splats, parent_splats = task
    return lod.grow(_job().trees(t), node, a, b, max_splats, parent_splats)


def _write_tile(task: tuple[int, str, int, int, int, str]) -> int:
    """Pack, compress and write one tile (its splats: held rows perm[start:stop] of tree
    columns t, sorted, so the gather is near-sequential); returns its number of splats."""
    t, name, start, stop, frac, folder = task
    job = _job()
    rows = job.trees(t).perm[start:stop]
    blob, lo, hi = spz.pack_bounded(job.held, job.sh_degree, version=job.spz_version,
                                    fractional_bits=frac, level=job.level, rows=rows)
    data = gltf.tile_glb(blob, rows.shape[0], job.sh_degree, lo, hi)
    with open(os.path.join(folder, f"{name}.glb"), "wb") as f:
        f.write(data)
    return int(rows.shape[0])


def build_tree(tree: lod.TreeInput, imap: Imap, nproc: int, max_splats: int,
                parent_splats: int | None, tree2: lod.TreeInput | None = None,
                order: np.ndarray | None = None) -> tuple[lod.Node, int]:
    """The tile tree and which tree columns hold it (0: ``tree``, 1: ``tree2``).

    With ``tree2`` and ``order`` (shared, as long as ``tree``), the root is split by the
    workers: here only its most prominent splats and its first median split are chosen; each
    worker finishes the split of one half and moves that half into ``tree2`` while this
    process moves the kept splats. Then the top levels are expanded here until there is a
    subtree for each worker (median splits make them equal), and the workers grow those on
    disjoint ranges. The tree is the one :func:`gsgeo.tiles.lod.build_tree` builds in one
    process, node for node."""
    max_splats, parent_splats = lod.tree_limits(max_splats, parent_splats)
    n = tree.perm.shape[0]
    root = lod.root_node(tree)
    frontier = [(root, 0, n)]
    t = 0
    if tree2 is not None and order is not None and n > max_splats:
        o, axes, halves = tree.first_split(0, n, parent_splats)
        order[:n] = o
        # with a half per worker, the workers go on to grow the root's children themselves
        grow = (max_splats, parent_splats) if len(halves) >= nproc else None
        tasks, first = [], 0
        for lo, hi in halves:
            tasks.append((parent_splats, lo, hi, axes[1:], n, first, grow))
            first += sum(y > x for x, y in lod.part_ranges(hi - lo, len(axes) - 1))
        done = imap(_finish_root_half, tasks)
        kept = order[:parent_splats]
        for src, dst in zip(tree.columns(), tree2.columns(), strict=True):
            np.take(src, kept, out=dst[:parent_splats], mode="clip")
        tree2.perm[:parent_splats].sort()
        parts = sorted((p for half in done for p in half), key=lambda p: (p[0], p[1]))
        tree, t = lod.TreeInput(tree2.pos[:, :n], tree2.radius[:n], tree2.key[:n],
                                tree2.perm[:n]), 1
        root.start, root.stop = 0, parent_splats
        frontier = []
        for lo, hi, blo, bhi, grown in parts:
            child = grown if grown is not None else \
                lod.Node(tree.perm[:0], blo, bhi, 1, f"0_{len(root.children)}")
            root.children.append(child)
            if grown is None:
                frontier.append((child, parent_splats + lo, parent_splats + hi))
    while frontier and len(frontier) < nproc:
        big = max(range(len(frontier)), key=lambda i: frontier[i][2] - frontier[i][1])
        if frontier[big][2] - frontier[big][1] <= max_splats:
            break
        frontier += lod.expand(tree, *frontier.pop(big), max_splats, parent_splats)
    by_name = {nd.name: nd for nd, _, _ in frontier}
    subtrees = [(t, nd, a, b, max_splats, parent_splats) for nd, a, b in frontier]
    for grown in imap(_grow_subtree, subtrees):
        nd = by_name[grown.name]     # the worker's copy: take its subtree and range
        nd.children, nd.start, nd.stop = grown.children, grown.start, grown.stop
    lod.attach_indices(tree, root)
    return root, t


def _shared_tree(count: int) -> lod.TreeInput:
    return lod.TreeInput(shared_empty((3, count), np.float32), shared_empty(count, np.float32),
                         shared_empty(count, np.float32), shared_empty(count, np.int32))


def _held_arrays(count: int, sh_degree: int, spz_version: int) -> spz.SpzBytes:
    k = sh_degree and {1: 3, 2: 8, 3: 15}[sh_degree]
    e = shared_empty
    return spz.SpzBytes(e((count, 3), np.float64), e(count, np.uint8), e((count, 3), np.uint8),
                        e((count, 3), np.uint8),
                        e(count, np.uint32) if spz_version == 3 else e((count, 3), np.uint8),
                        e((count, 3 * k), np.uint8))


def build_tileset(input_path: str | os.PathLike, outdir: str | os.PathLike,
                  georef: Georeference | None = None, *, max_splats: int = 131_072,
                  parent_splats: int | None = None, spz_version: int = 3, level: int = 1,
                  workers: int | None = None, overwrite: bool = False,
                  progress: TextIO | None = sys.stderr, block: int = BLOCK,
                  on_start: Callable[[], None] | None = None) -> Summary:
    """Convert a 3DGS PLY or SPZ file into a tileset directory ``outdir``.

    ``level`` is the gzip level of the SPZ payloads (1 fastest, 9 smallest); ``workers``
    the number of worker processes (default: the CPUs this process may use; inputs under
    :data:`PARALLEL_MIN_SPLATS` splats are done in this process). The result is written to
    a temporary directory beside ``outdir`` and swapped into place when complete; an
    existing ``outdir`` must be empty, or with ``overwrite`` a tileset gsgeo wrote (see
    :mod:`gsgeo.tiles.outdir`). ``on_start`` is called once the input is open and the output
    checked, before the splats are read. Calls from several threads run one after the other.
    """
    with _BUILD_LOCK:
        return _build(input_path, outdir, georef, max_splats=max_splats,
                      parent_splats=parent_splats, spz_version=spz_version, level=level,
                      workers=workers, overwrite=overwrite, progress=progress, block=block,
                      on_start=on_start)


def _build(input_path: str | os.PathLike, outdir: str | os.PathLike,
           georef: Georeference | None, *, max_splats: int, parent_splats: int | None,
           spz_version: int, level: int, workers: int | None, overwrite: bool,
           progress: TextIO | None, block: int,
           on_start: Callable[[], None] | None) -> Summary:
    global WORKER_JOB
    t0 = time.monotonic()
    src_path = Path(input_path)
    out = Path(outdir)
    georef = georef or Georeference("none")
    if spz_version not in (2, 3):
        raise InputError("SPZ file version must be 2 or 3")
    if not 0 <= level <= 9:
        raise InputError("gzip level must be 0..9")
    if max_splats < 1000:
        raise InputError("--max-splats must be at least 1000")
    if block < 1:
        raise InputError("block must be positive")
    dest = outdir_mod.check_output(src_path, out, overwrite)
    src = open_source(src_path, block)
    count, sh_degree = src.count, src.sh_degree
    if count == 0:
        raise InputError(f"{src_path}: the file holds no splats")
    if count >= 2**31:
        raise InputError(f"{src_path}: {count} splats; at most 2**31 - 1 are supported")
    tmp = _prepare_outdir(dest, out)
    try:
        if on_start is not None:
            on_start()
        lo, hi, n_finite = src.bounds()
        if n_finite == 0:
            raise InputError(f"{src_path}: no splat has finite coordinates")
        placement = georef.placement(lo, hi)
        nproc = workers or cpu_count()
        if workers is None and count < PARALLEL_MIN_SPLATS:
            nproc = 1
        held = _held_arrays(count, sh_degree, spz_version)
        tree = _shared_tree(count)
        tree2 = order = None
        if nproc > 1 and count > max_splats:     # the root is split by the workers
            tree2, order = _shared_tree(count), shared_empty(count, np.int32)
        WORKER_JOB = WorkerJob(src, placement, held, tree, spz_version, sh_degree, level, tree2, order)
        with pool(nproc) as imap:
            bar = Progress(progress, count, "reading")
            kept: list[tuple[int, int]] = []
            extent = 0.0
            # about eight tasks per worker, each a few blocks
            step = block * min(8, max(1, count // (8 * nproc * block)))
            tasks = [(i, min(count, i + step), block) for i in range(0, count, step)]
            for done in imap(_quantise_blocks, tasks):
                for start, m, ext in done:
                    kept.append((start, m))
                    extent = max(extent, ext)
                    bar.update(min(count, start + block) - start)
            bar.close()
            kept.sort()
            n = sum(m for _, m in kept)
            dropped = count - n
            if n == 0:
                raise InputError(f"{src_path}: every splat has NaN or infinite values")
            if n < count:
                # rows of dropped splats are left out of the tree: the kept ones move to
                # the front, in place (the workers see the same shared memory)
                rows = np.concatenate([np.arange(a, a + m, dtype=np.int32) for a, m in kept])
                for arr in (*tree.pos, tree.radius, tree.key, tree.perm):
                    arr[:n] = arr[rows]
                tree = lod.TreeInput(tree.pos[:, :n], tree.radius[:n], tree.key[:n],
                                     tree.perm[:n])
            # A scene without georeference is in its trainer's unit, which may be many metres
            # (a normalised COLMAP frame): keep all the precision the 24-bit range allows, so
            # that a later georeference (which scales the root) does not magnify the steps.
            most = LOCAL_FRACTIONAL_BITS if georef.kind == "none" else spz.DEFAULT_FRACTIONAL_BITS
            frac = spz.fractional_bits_for(extent, most)
            if frac < spz.DEFAULT_FRACTIONAL_BITS:
                georef.warnings.append(
                    f"the scene reaches {extent:.0f} m from its centre: SPZ positions use "
                    f"{frac} fractional bits ({1000 / 2 ** frac:.2f} mm steps) instead of 12")
            root, t = build_tree(tree, imap, nproc, max_splats, parent_splats, tree2, order)
            nodes = [nd for nd in root.walk() if nd.index.shape[0]]
            (tmp / "tiles").mkdir()
            bar = Progress(progress, n, "writing")
            # biggest first so the last tiles to finish are small
            tile_tasks = [(t, nd.name, nd.start, nd.stop, frac, str(tmp / "tiles"))
                     for nd in sorted(nodes, key=lambda nd: -nd.index.shape[0])]
            for done in imap(_write_tile, tile_tasks):
                bar.update(done)
            bar.close()
            imap.close()   # the workers exit while the tileset JSON is written
            lon, lat, h = ecef_to_geodetic_closed_form(
                _corners(root.lo.astype(float), root.hi.astype(float)) @ placement.r_root
                + placement.centre_ecef)
            summary = Summary(
                input=str(src_path), output=str(out), splats_in=count, splats_written=n,
                dropped_nonfinite=dropped, sh_degree=sh_degree, tiles=len(nodes),
                levels=1 + max(nd.level for nd in root.walk()),
                georeference=georef.describe(), operation_accuracy_m=placement.operation_accuracy_m,
                root_lon_lat_h=placement.centre_lonlath,
                bounds_lon_lat_h={"lon": [float(lon.min()), float(lon.max())],
                                  "lat": [float(lat.min()), float(lat.max())],
                                  "h": [float(h.min()), float(h.max())]},
                fractional_bits=frac, spz_version=spz_version, seconds=0.0,
                warnings=list(georef.warnings))
            write_tileset_json(tmp / "tileset.json", root, placement.root_transform,
                               {"gsgeo": {"georeference": summary.georeference,
                                          "operation": placement.operation,
                                          "splats": n, "sh_degree": sh_degree,
                                          "root_frame": "ENU at the scene centre (WGS 84)",
                                          "georef": initial_extras(placement.root_transform)}})
            # again: OUTDIR may have been made or filled while the build ran
            outdir_mod.check_output(src_path, out, overwrite)
            _commit(tmp, dest)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        WORKER_JOB = None
    summary.seconds = time.monotonic() - t0
    return summary


def _corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    g = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    return lo + g * (hi - lo)
