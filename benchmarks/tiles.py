"""Benchmark `gsgeo tiles` against `@playcanvas/splat-transform` (PLY -> SPZ) in one run.

    python benchmarks/tiles.py [--sizes 1000000,5000000] [--repeat 3] [--skip-splat-transform]

Inputs (written to benchmarks/out/, git-ignored):
- real.ply: the shared real scene (../shared/data/white-sculpture, 690 573 splats, SH 3)
  rebuilt as an INRIA PLY in its root ENU frame (171 MB);
- synth_<N>.ply: SH-3 PLYs of N splats made of copies of the real scene side by side, each
  copy with jittered centres, so they compress like real data (random values would not).
  Without the shared data, random splats are used instead (and the table says so).

Each tool runs once for memory and then --repeat times (default 3) for time on each input,
the tools taking turns, each run a separate process under /usr/bin/time; the best wall time
is reported (the machine's speed varies from minute to minute) with the worst beside it.
Reported: wall time, CPU time, peak memory against the bound 1.5 x input + 300 MB (in the
memory run, sampled every 0.1 s as the sum of the proportional set sizes of the tool's whole
process tree, gsgeo's worker processes included; sampling slows the tool, so timed runs do
not sample; /usr/bin/time's maximum RSS of the largest single process over all runs is shown
beside it), output size.
gsgeo runs with its defaults (gzip level 1 through ISA-L, one worker process per CPU,
georeference by --transform for real.ply and by --origin for the synthetic ones);
splat-transform writes one .spz (no tiling).
Results: benchmarks/out/tiles.json and a Markdown table on stdout.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
OUT = HERE / "out"
SHARED = REPO.parent / "shared" / "data" / "white-sculpture"
SPLAT_TRANSFORM = HERE / "node" / "node_modules" / ".bin" / "splat-transform"

sys.path.insert(0, str(REPO))


def _log(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


def real_splats():
    from tests.tiles_real import real_root_frame
    return real_root_frame(SHARED)


def make_inputs(sizes: list[int]) -> list[tuple[str, Path, list[str]]]:
    from gsgeo.tiles.ply import write_ply
    from gsgeo.tiles.splats import Splats
    OUT.mkdir(parents=True, exist_ok=True)
    inputs = []
    have_real = (SHARED / "tileset.json").is_file()
    base = None
    if have_real:
        real_ply = OUT / "real.ply"
        if not real_ply.exists():
            _log("writing real.ply ...")
            base, root = real_splats()
            write_ply(real_ply, base)
            (OUT / "real_root.json").write_text(json.dumps(root.T.reshape(-1).tolist()))
        inputs.append(("real scene", real_ply, ["--transform", str(OUT / "real_root.json")]))
    rng = np.random.default_rng(5)
    for n in sizes:
        path = OUT / f"synth_{n}.ply"
        if not path.exists():
            _log(f"writing {path.name} ...")
            if have_real:
                if base is None:
                    base, _ = real_splats()
                reps = -(-n // base.count)
                side = int(np.ceil(np.sqrt(reps)))
                parts = []
                for r in range(reps):
                    m = min(base.count, n - r * base.count)
                    s = base.take(slice(0, m))
                    shift = np.array([(r % side) * 120.0, (r // side) * 120.0, 0.0])
                    jitter = rng.normal(scale=0.002, size=(m, 3))
                    parts.append(Splats(s.positions + shift + jitter, s.scales, s.rotations,
                                        s.opacities, s.colors, s.sh))
                s = Splats.concatenate(parts)
            else:
                from tests.tiles_helpers import random_splats
                s = random_splats(rng, n, 3, extent=200.0)
            write_ply(path, s)
            del s
        inputs.append((f"synthetic {n / 1e6:g} M" + ("" if have_real else " (random)"), path,
                       ["--origin", "40.0,-83.0,200"]))
    return inputs


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        out.append(p)
        try:
            for t in os.listdir(f"/proc/{p}/task"):
                with open(f"/proc/{p}/task/{t}/children") as f:
                    todo += [int(c) for c in f.read().split()]
        except OSError:
            pass
    return out


def _pss_mb(pids: list[int]) -> float:
    """Memory of a process tree: the sum of proportional set sizes (shared pages counted
    once in all, split among the processes sharing them)."""
    kb = 0
    for p in pids:
        try:
            with open(f"/proc/{p}/smaps_rollup") as f:
                for line in f:
                    if line.startswith("Pss:"):
                        kb += int(line.split()[1])
                        break
        except OSError:
            pass
    return kb / 1024


def timed(cmd: list[str], cwd: Path | None = None, sample_memory: bool = False) -> dict:
    """Run cmd under /usr/bin/time. With ``sample_memory``, also sample the memory of its
    whole process tree (worker processes included) every 0.1 s: /usr/bin/time's maximum RSS
    is that of the single largest process, which understates a multi-process tool. Sampling
    reads smaps_rollup, which walks page tables and on two CPUs slows the tool measured by
    about 10 %, so timed runs do not sample (``peak_tree_mb`` is then None)."""
    tf = OUT / "time.txt"
    t0 = time.monotonic()
    proc = subprocess.Popen(["/usr/bin/time", "-f", "%e %M %U %S", "-o", str(tf)] + cmd,
                            cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    peak = 0.0 if sample_memory else None
    while sample_memory and proc.poll() is None:
        peak = max(peak, _pss_mb(_descendants(proc.pid)[1:]))   # not /usr/bin/time itself
        time.sleep(0.1)
    out, err = proc.communicate()
    wall = time.monotonic() - t0
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd[0]} failed ({proc.returncode}): {err[-2000:]}")
    e, m, u, s = tf.read_text().split()[-4:]
    return {"wall_s": float(e) if float(e) > 0 else wall, "peak_rss_mb": int(m) / 1024,
            "peak_tree_mb": peak, "cpu_s": float(u) + float(s), "stdout": out}


def _size_mb(p: Path) -> float:
    if p.is_dir():
        return sum(f.stat().st_size for f in p.rglob("*") if f.is_file()) / 1e6
    return p.stat().st_size / 1e6


def count(path: Path) -> int:
    from gsgeo.tiles.ply import read_layout
    return read_layout(path).count


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="1000000,5000000")
    ap.add_argument("--skip-splat-transform", action="store_true")
    ap.add_argument("--levels", default="1", help="gzip levels for gsgeo, e.g. 1,6")
    ap.add_argument("--repeat", type=int, default=3,
                    help="runs of each tool on each input; the best wall time is reported")
    args = ap.parse_args()
    sizes = [int(s) for s in args.sizes.split(",") if s]
    inputs = make_inputs(sizes)
    st_ok = SPLAT_TRANSFORM.exists() and not args.skip_splat_transform
    if not st_ok and not args.skip_splat_transform:
        _log("splat-transform not installed (cd benchmarks/node && npm ci); skipping it")
    # gsgeo as installed: its modules byte-compiled, as pip does for a package (this
    # sandbox sets PYTHONDONTWRITEBYTECODE, which would recompile gsgeo at every start)
    subprocess.run([sys.executable, "-m", "compileall", "-q", str(REPO / "gsgeo")], check=True,
                   env={k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"})
    rows = []
    for label, path, georef in inputs:
        n = count(path)
        in_mb = path.stat().st_size / 1e6
        bound = 1.5 * path.stat().st_size / 2**20 + 300
        runs: dict[str, list[dict]] = {}
        # the tools take turns, so a slow spell of the (shared, virtual) machine hits both;
        # run 0 samples the memory of the process tree and is not timed
        for rep in range(args.repeat + 1):
            what = "memory" if rep == 0 else f"run {rep}"
            for level in [int(v) for v in args.levels.split(",")]:
                out = OUT / f"tiles_{path.stem}_l{level}"
                _log(f"gsgeo tiles {path.name} (level {level}, {what}) ...")
                r = timed([sys.executable, "-m", "gsgeo", "tiles", str(path), "-o", str(out),
                           "--overwrite", "--quiet", "--json", "--level", str(level)] + georef,
                          sample_memory=rep == 0)
                summ = json.loads(r.pop("stdout"))
                r.update(output_mb=_size_mb(out), tiles=summ["tiles"], levels=summ["levels"])
                runs.setdefault(f"gsgeo tiles (gzip {level})", []).append(r)
                shutil.rmtree(out, ignore_errors=True)
            if st_ok:
                out = OUT / f"st_{path.stem}.spz"
                _log(f"splat-transform {path.name} ({what}) ...")
                r = timed([str(SPLAT_TRANSFORM), "-q", str(path), str(out)],
                          sample_memory=rep == 0)
                r.pop("stdout")
                r.update(output_mb=_size_mb(out))
                runs.setdefault("splat-transform -> .spz", []).append(r)
                out.unlink(missing_ok=True)
        for tool, rs in runs.items():
            mem, timed_runs = rs[0], rs[1:]
            best = min(timed_runs, key=lambda r: r["wall_s"])
            rows.append({"tool": tool, "input": label, "splats": n, "input_mb": in_mb, **best,
                         "wall_worst_s": max(r["wall_s"] for r in timed_runs),
                         "peak_tree_mb": mem["peak_tree_mb"],
                         "peak_rss_mb": max(r["peak_rss_mb"] for r in rs),
                         "splats_per_s": n / best["wall_s"], "rss_bound_mb": bound,
                         "runs": len(timed_runs)})
    meta = {"cpus": os.cpu_count(), "python": platform.python_version(),
            "load_avg_at_end": os.getloadavg(), "date": time.strftime("%Y-%m-%d %H:%M UTC",
                                                                        time.gmtime())}
    (OUT / "tiles.json").write_text(json.dumps({"meta": meta, "rows": rows}, indent=1))
    print(f"CPUs {meta['cpus']}, load average at end {meta['load_avg_at_end'][0]:.1f}, "
          f"{meta['date']}\n")
    print("| input | splats | tool | wall s best (worst) | splats/s | CPU s | peak memory MB "
          "(all processes) | peak RSS MB (largest process) | bound MB | output MB |")
    print("|---|---:|---|---:|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        print(f"| {r['input']} | {r['splats']:,} | {r['tool']} | {r['wall_s']:.2f} "
              f"({r['wall_worst_s']:.2f}) | {r['splats_per_s']:,.0f} | {r['cpu_s']:.1f} | "
              f"{r['peak_tree_mb']:.0f} | {r['peak_rss_mb']:.0f} | {r['rss_bound_mb']:.0f} | "
              f"{r['output_mb']:.1f} |")
    by = {}
    for r in rows:
        by.setdefault(r["input"], {})[r["tool"]] = r["wall_s"]
    for inp, d in by.items():
        st = d.get("splat-transform -> .spz")
        g = [v for k, v in d.items() if k.startswith("gsgeo")]
        if st and g:
            print(f"\n{inp}: gsgeo is {st / min(g):.1f}x faster than splat-transform", end="")
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main())
