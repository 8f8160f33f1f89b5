"""`build_tileset`: 3DGS PLY/SPZ -> georeferenced OGC 3D Tiles 1.1 of SPZ-compressed glTF splats.

Pipeline: bounds of the input (one streaming pass) -> scene centre and root ENU frame ->
second streaming pass turning each block into the root frame and quantising it to SPZ bytes
(about 84 bytes a splat at SH degree 3 are held) -> tile tree -> tiles compressed and written
by worker threads (zlib releases the GIL) into a temporary directory beside OUTDIR, which is
renamed into place at the end.
"""

from __future__ import annotations

import json
import os
import shutil
import sys
import tempfile
import time
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TextIO

import numpy as np

from gsgeo.errors import InputError
from gsgeo.tiles import gltf, lod, ply, spz
from gsgeo.tiles.georef import Georeference, ecef_to_geodetic
from gsgeo.tiles.splats import Splats

#: The scene centre (origin of the root ENU frame) is the centre of the bounding box of this
#: many splat centres spread through the file; the true extent is checked after reading.
CENTRE_SAMPLE = 65_536


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


def _spz_file(path: Path) -> Splats:
    try:
        data = path.read_bytes()
    except OSError as exc:
        raise InputError(f"{path}: cannot read ({exc.strerror})") from None
    return spz.decode(data)[0]


def _source(path: Path, block: int, ring: int):
    """(count, sh_degree, size_bytes, bounds(), blocks()) of a PLY or SPZ input."""
    suffix = path.suffix.lower()
    if suffix == ".spz":
        s = _spz_file(path)
        ok = np.isfinite(s.positions).all(axis=1)

        def bounds():
            p = s.positions[ok]
            return (p.min(axis=0), p.max(axis=0), int(ok.sum())) if p.size else \
                (np.zeros(3), np.zeros(3), 0)

        def blocks():
            for i in range(0, s.count, block):
                yield s.take(slice(i, i + block))
        return s.count, s.sh_degree, path.stat().st_size, bounds, blocks
    if suffix != ".ply":
        raise InputError(f"{path}: unsupported input; expected a .ply or .spz file")
    layout = ply.read_layout(path)
    if isinstance(layout, ply.CompressedLayout):
        def cbounds():
            lo, hi, n = np.full(3, np.inf), np.full(3, -np.inf), 0
            chunks = np.fromfile(layout.path, layout.chunk_dtype, layout.n_chunks,
                                 offset=layout.chunk_offset)
            for i, c in enumerate("xyz"):
                lo[i], hi[i] = np.nanmin(chunks[f"min_{c}"]), np.nanmax(chunks[f"max_{c}"])
            n = layout.count if np.isfinite(lo).all() and np.isfinite(hi).all() else 0
            return lo, hi, n
        return (layout.count, layout.sh_degree, layout.size_bytes, cbounds,
                lambda: ply.iter_compressed(layout, block))
    return (layout.count, layout.sh_degree, layout.size_bytes,
            lambda: ply.ply_bounds(layout, sample=CENTRE_SAMPLE),
            lambda: ply.iter_ply(layout, block, ring))


def _prepare_outdir(outdir: Path, overwrite: bool) -> Path:
    if outdir.exists() and not outdir.is_dir():
        raise InputError(f"{outdir} exists and is not a directory")
    if outdir.exists() and any(outdir.iterdir()) and not overwrite:
        raise InputError(f"{outdir} exists and is not empty; pass --overwrite to replace it")
    outdir.parent.mkdir(parents=True, exist_ok=True)
    return Path(tempfile.mkdtemp(prefix=f".{outdir.name}.", suffix=".tmp", dir=outdir.parent))


def _commit(tmp: Path, outdir: Path) -> None:
    """Swap the finished temporary directory into place; an old OUTDIR is removed only after."""
    # mkdtemp makes the directory 0700; a tileset is served and shared like any output
    # directory, so give it the mode a plain mkdir would (0777 less the umask).
    umask = os.umask(0)
    os.umask(umask)
    os.chmod(tmp, 0o777 & ~umask)
    old = None
    if outdir.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{outdir.name}.", suffix=".old", dir=outdir.parent))
        os.rmdir(old)
        os.replace(outdir, old)
    os.replace(tmp, outdir)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)


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


def build_tileset(input_path: str | os.PathLike, outdir: str | os.PathLike,
                  georef: Georeference | None = None, *, max_splats: int = 131_072,
                  parent_splats: int | None = None, spz_version: int = 3, level: int = 1,
                  workers: int | None = None, overwrite: bool = False,
                  progress: TextIO | None = sys.stderr, block: int = 65_536) -> Summary:
    """Convert a 3DGS PLY or SPZ file into a tileset directory ``outdir``.

    ``level`` is the gzip level of the SPZ payloads (1 fastest, 9 smallest); ``workers``
    the number of threads compressing tiles (default: CPU count). The result is written to a
    temporary directory beside ``outdir`` and renamed into place when complete.
    """
    t0 = time.monotonic()
    src = Path(input_path)
    out = Path(outdir)
    georef = georef or Georeference("none")
    if spz_version not in (2, 3):
        raise InputError("SPZ file version must be 2 or 3")
    if not 0 <= level <= 9:
        raise InputError("gzip level must be 0..9")
    if max_splats < 1000:
        raise InputError("--max-splats must be at least 1000")
    nthreads = workers or os.cpu_count() or 2
    # at most nthreads blocks are in flight while the next is read (see below)
    count, sh_degree, _, bounds, blocks = _source(src, block, ring=nthreads + 2)
    if count == 0:
        raise InputError(f"{src}: the file holds no splats")
    lo, hi, n_finite = bounds()
    if n_finite == 0:   # the sample may have missed the few finite ones: look at all
        lo, hi, n_finite = ply.ply_bounds(ply.read_layout(src)) if src.suffix.lower() == \
            ".ply" else (lo, hi, 0)
    if n_finite == 0:
        raise InputError(f"{src}: no splat has finite coordinates")
    placement = georef.placement(lo, hi)
    tmp = _prepare_outdir(out, overwrite)
    try:
        # pass 2: to the root frame, quantised
        k = sh_degree and {1: 3, 2: 8, 3: 15}[sh_degree]
        held = spz.SpzBytes(np.empty((count, 3)), np.empty(count, np.uint8),
                            np.empty((count, 3), np.uint8), np.empty((count, 3), np.uint8),
                            np.empty(count, np.uint32) if spz_version == 3
                            else np.empty((count, 3), np.uint8),
                            np.empty((count, 3 * k), np.uint8))
        bar = Progress(progress, count, "reading")
        n = 0

        def prepare(s: Splats) -> spz.SpzBytes | None:
            ok = s.finite_mask()
            if not ok.all():
                s = s.take(ok)
            return spz.quantize(placement.apply(s), spz_version) if s.count else None

        with ThreadPoolExecutor(max_workers=nthreads) as pool:
            pending: deque = deque()
            # numpy releases the GIL in its loops: blocks are turned and quantised in
            # parallel, at most nthreads + 1 in flight (bounded memory), kept in file order
            for s in blocks():
                pending.append((pool.submit(prepare, s), s.count))
                while len(pending) > nthreads:
                    n = _store(held, n, *pending.popleft(), bar)
            while pending:
                n = _store(held, n, *pending.popleft(), bar)
        bar.close()
        dropped = count - n
        if n == 0:
            raise InputError(f"{src}: every splat has NaN or infinite values")
        held = held.take(slice(0, n))
        extent = float(np.abs(held.positions).max())
        frac = spz.fractional_bits_for(extent)
        if frac < spz.DEFAULT_FRACTIONAL_BITS:
            georef.warnings.append(
                f"the scene reaches {extent:.0f} m from its centre: SPZ positions use {frac} "
                f"fractional bits ({1000 / 2 ** frac:.2f} mm steps) instead of 12")
        root = lod.build_tree(held.positions.astype(np.float32), lod.splat_radius(held.scales),
                              lod.importance(held.alphas, held.scales),
                              max_splats=max_splats, parent_splats=parent_splats)
        nodes = [nd for nd in root.walk() if nd.index.shape[0]]
        (tmp / "tiles").mkdir()
        bar = Progress(progress, n, "writing")

        def write(node: lod.Node) -> int:
            b = held.take(np.sort(node.index))   # sorted: a near-sequential gather
            blob = spz.pack(b, sh_degree, version=spz_version, fractional_bits=frac, level=level)
            p = b.positions
            data = gltf.tile_glb(blob, b.count, sh_degree, p.min(axis=0), p.max(axis=0))
            (tmp / "tiles" / f"{node.name}.glb").write_bytes(data)
            return b.count

        with ThreadPoolExecutor(max_workers=workers or os.cpu_count() or 2) as pool:
            # biggest first so the last tiles to finish are small
            for done in pool.map(write, sorted(nodes, key=lambda nd: -nd.index.shape[0])):
                bar.update(done)
        bar.close()
        lon, lat, h = ecef_to_geodetic(_corners(root.lo.astype(float), root.hi.astype(float))
                                       @ placement.r_root
                                       + placement.centre_ecef)
        summary = Summary(
            input=str(src), output=str(out), splats_in=count, splats_written=n,
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
                                      "root_frame": "ENU at the scene centre (WGS 84)"}})
        _commit(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    summary.seconds = time.monotonic() - t0
    return summary


def _store(held: spz.SpzBytes, n: int, fut, block_count: int, bar: Progress) -> int:
    q = fut.result()
    bar.update(block_count)
    if q is None:
        return n
    m = q.count
    for f in ("positions", "alphas", "colors", "scales", "rotations", "sh"):
        getattr(held, f)[n:n + m] = getattr(q, f)
    return n + m


def _corners(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    g = np.array(np.meshgrid([0, 1], [0, 1], [0, 1], indexing="ij")).reshape(3, -1).T
    return lo + g * (hi - lo)
