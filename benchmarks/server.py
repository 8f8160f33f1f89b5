"""Benchmark `gsgeo serve` on loopback: POST /api/intersect latency and tile throughput.

    python benchmarks/server.py [--clients 50] [--requests 40] [--think 2] [--seconds 10]
        [--workers 1] [--solver-threads 1] [--client-procs 2] [--loads one operators saturation]

1. Intersect latency: 50 concurrent clients, each a keep-alive HTTP/1.1 connection of an
   asyncio client (spread over `--client-procs` processes, so that the clients neither share
   one GIL nor cost much CPU: raw requests, answers read by Content-Length), each send
   `--requests` POST /api/intersect requests of a 5-ray point (angular model, output in
   EPSG:27700). Three load models:
   - "operators": each client waits an exponential think time (mean `--think` s, default 2)
     between requests, like people aiming and clicking (the viewer asks for a live solution
     at every click);
   - "saturation": no think time (closed loop), which measures the server's capacity;
   - "one client": a single client, no think time: the latency floor without queueing.
   Reported: p50, p90, p99, max latency (ms), requests/s, and the server's and the clients'
   CPU per request.
2. Tile throughput: the same scene files fetched for `--seconds` by 8 concurrent clients from
   gsgeo serve (/scenes/<name>/...) and from `python -m http.server` on the scene directory,
   in the same run. The scene is ../shared/data/white-sculpture when present, else a
   synthetic one of 16 files of 1 MiB.

Everything runs on 127.0.0.1; client and servers share the machine, so the figures are a
lower bound for a dedicated server.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import math
import multiprocessing as mp
import os
import random
import shutil
import socket
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx
import numpy as np

from gsgeo.crs.transformers import transformer

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))
from tests.servertools import rays_at  # noqa: E402  (the rays the API tests use)

SHARED_SCENE = REPO.parent / "shared" / "data" / "white-sculpture"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def wait_up(url: str, proc: subprocess.Popen, timeout: float = 60) -> None:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        if proc.poll() is not None:
            raise RuntimeError(f"server exited: {proc.stderr.read() if proc.stderr else ''}")
        try:
            httpx.get(url, timeout=1)
            return
        except httpx.HTTPError:
            time.sleep(0.1)
    raise RuntimeError(f"{url} did not come up")


def point_rays(rng: np.random.Generator, n: int = 5) -> list[dict]:
    """n rays at a random point near London, 1 px aiming noise, ifov 1 mrad."""
    t = transformer("EPSG:4979", "EPSG:4978")  # cached: not one Transformer per point
    lon, lat = -0.1276 + rng.uniform(-1e-3, 1e-3), 51.5072 + rng.uniform(-1e-3, 1e-3)
    x = np.array(t.transform(lon, lat, 50.0))
    return rays_at(x, n, rng, noise_rad=1e-3, ifov=1e-3, radius=30.0, height=20.0)


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process and its children (worker processes), seconds."""
    total = 0.0
    tick = os.sysconf("SC_CLK_TCK")
    pids = [pid]
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
        pids += [int(c) for c in children]
    except OSError:
        pass
    for p in pids:
        try:
            fields = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        total += (int(fields[11]) + int(fields[12])) / tick  # utime, stime
    return total


async def _read_response(reader: asyncio.StreamReader) -> tuple[int, bytes]:
    """One HTTP/1.1 response (status line, headers, Content-Length body) from a keep-alive stream."""
    head = await reader.readuntil(b"\r\n\r\n")
    lines = head.split(b"\r\n")
    status = int(lines[0].split(b" ", 2)[1])
    length = 0
    for line in lines[1:]:
        name, _, value = line.partition(b":")
        if name.strip().lower() == b"content-length":
            length = int(value)
    return status, await reader.readexactly(length)


async def _clients(port: int, requests: list[bytes], ids: list[int], n: int, think: float,
                   seed: int, start_at: float) -> tuple[list[float], int, float, float]:
    """The clients ``ids`` of one process: each a keep-alive connection sending ``n`` requests.

    Latency is from writing the request to having read the whole response (client-side,
    think time excluded). Returns (latencies s, errors, first send, last answer).
    """
    lat: list[float] = []
    errors = 0
    first, last = math.inf, 0.0

    async def client(c: int) -> None:
        nonlocal errors, first, last
        r = random.Random(seed * 1000 + c)
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        writer.write(requests[c % len(requests)])  # connect and warm up
        status, body = await _read_response(reader)
        doc = json.loads(body)
        if status != 200 or not isinstance(doc.get("easting"), float):
            raise RuntimeError(f"bad warm-up answer {status}: {body[:200]!r}")
        await asyncio.sleep(max(0.0, start_at - time.perf_counter()))
        for i in range(n):
            if think > 0:
                await asyncio.sleep(r.expovariate(1.0 / think))
            t0 = time.perf_counter()
            writer.write(requests[(c + i) % len(requests)])
            status, _ = await _read_response(reader)
            t1 = time.perf_counter()
            lat.append(t1 - t0)
            errors += status != 200
            first, last = min(first, t0), max(last, t1)
        writer.close()

    await asyncio.gather(*(client(c) for c in ids))
    return lat, errors, first, last


def _client_process(conn, port: int, requests: list[bytes], ids: list[int], n: int,
                    think: float, seed: int, start_at: float) -> None:
    try:
        import uvloop

        uvloop.install()
    except ImportError:
        pass
    cpu0 = time.process_time()
    try:
        out = asyncio.run(_clients(port, requests, ids, n, think, seed, start_at))
        conn.send(("ok", *out, time.process_time() - cpu0))
    except Exception as exc:  # noqa: BLE001 - reported by the parent
        conn.send(("error", repr(exc)))
    conn.close()


def latency_run(port: int, clients: int, requests: int, think: float, seed: int,
                procs: int) -> dict:
    """``clients`` keep-alive connections spread over ``procs`` client processes (asyncio)."""
    rng = np.random.default_rng(seed)
    reqs = []
    for _ in range(64):
        body = json.dumps({"rays": point_rays(rng), "crs": "EPSG:27700",
                           "sigma_px": 1.0}).encode()
        reqs.append(b"POST /api/intersect HTTP/1.1\r\nHost: 127.0.0.1:%d\r\n"
                    b"Content-Type: application/json\r\nContent-Length: %d\r\n\r\n"
                    % (port, len(body)) + body)
    procs = max(1, min(procs, clients))
    ctx = mp.get_context("fork")
    start_at = time.perf_counter() + 1.0 + 0.02 * clients  # all connected and warm by then
    pipes, workers = [], []
    for p in range(procs):
        parent, child = ctx.Pipe(duplex=False)
        w = ctx.Process(target=_client_process, args=(
            child, port, reqs, list(range(p, clients, procs)), requests, think, seed, start_at))
        w.start()
        pipes.append(parent)
        workers.append(w)
    parts = [p.recv() for p in pipes]
    for w in workers:
        w.join()
    bad = [p[1] for p in parts if p[0] != "ok"]
    if bad:
        raise RuntimeError(f"client process failed: {bad[0]}")
    a = np.array([x for p in parts for x in p[1]]) * 1000
    wall = max(p[4] for p in parts) - min(p[3] for p in parts)
    return {"requests": int(a.size), "errors": sum(p[2] for p in parts),
            "p50_ms": float(np.percentile(a, 50)), "p90_ms": float(np.percentile(a, 90)),
            "p99_ms": float(np.percentile(a, 99)), "max_ms": float(a.max()),
            "req_per_s": a.size / wall, "client_procs": procs,
            "client_cpu_ms_per_request": sum(p[5] for p in parts) * 1000 / a.size,
            "latencies_ms": a.tolist()}


def throughput_run(urls: list[str], seconds: float, clients: int = 8) -> dict:
    stop = time.perf_counter() + seconds
    counts = []
    lock = threading.Lock()

    def client(c: int) -> None:
        n = nbytes = 0
        with httpx.Client(timeout=60) as h:
            i = c
            while time.perf_counter() < stop:
                r = h.get(urls[i % len(urls)])
                r.raise_for_status()
                n += 1
                nbytes += len(r.content)
                i += 1
        with lock:
            counts.append((n, nbytes))

    threads = [threading.Thread(target=client, args=(c,)) for c in range(clients)]
    t0 = time.perf_counter()
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    wall = time.perf_counter() - t0
    n = sum(c[0] for c in counts)
    b = sum(c[1] for c in counts)
    return {"requests": n, "req_per_s": n / wall, "MiB_per_s": b / wall / 2**20}


def make_scene(root: Path) -> Path:
    if (SHARED_SCENE / "tileset.json").is_file():
        (root / "scenes").mkdir(parents=True, exist_ok=True)
        # a copy: a linked scene folder leading out of the scenes root is not served
        shutil.copytree(SHARED_SCENE, root / "scenes" / "bench")
        return root / "scenes" / "bench"
    scene = root / "scenes" / "bench"
    scene.mkdir(parents=True)
    rng = np.random.default_rng(0)
    (scene / "tileset.json").write_text(json.dumps({"asset": {"version": "1.1"}, "root": {}}))
    for k in range(16):
        (scene / f"tile_{k}.glb").write_bytes(rng.bytes(2**20))
    return scene


def plot(results: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4))
    for name, r in results["intersect"].items():
        a = np.sort(np.array(r["latencies_ms"]))
        ax.plot(a, np.arange(1, a.size + 1) / a.size, label=f"{name} (p99 {r['p99_ms']:.1f} ms)")
    ax.axvline(25, color="grey", ls="--", lw=1, label="target p99 25 ms")
    ax.set_xscale("log")
    ax.set_xlabel("POST /api/intersect latency (ms)")
    ax.set_ylabel("fraction of requests")
    ax.set_title(f"POST /api/intersect on loopback, {results['workers']} worker(s), "
                 f"{results['solver_threads']} solver thread(s); load average "
                 f"{results['loadavg_start']:.1f} on {results['cpus']} CPUs",
                 fontsize=10)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--clients", type=int, default=50)
    ap.add_argument("--requests", type=int, default=40, help="requests per client")
    ap.add_argument("--think", type=float, default=2.0,
                    help="mean think time between an operator's requests, s")
    ap.add_argument("--seconds", type=float, default=10.0, help="tile throughput duration")
    ap.add_argument("--workers", type=int, default=1, help="gsgeo serve --workers")
    ap.add_argument("--solver-threads", type=int, default=1, help="gsgeo serve --solver-threads")
    ap.add_argument("--client-procs", type=int, default=2,
                    help="client processes the intersect clients are spread over")
    ap.add_argument("--loads", nargs="+", default=["one", "operators", "saturation"],
                    choices=["one", "operators", "saturation"], help="which intersect loads to run")
    ap.add_argument("--plot", default=str(REPO / "benchmarks" / "server_latency.png"))
    ap.add_argument("--json", default=None, help="write the figures here")
    args = ap.parse_args()

    tmp = Path(tempfile.mkdtemp(prefix="gsgeo-bench-"))
    procs = []
    try:
        scene = make_scene(tmp / "data")
        port, hport = free_port(), free_port()
        cmd = [sys.executable, "-m", "gsgeo", "serve", "--data", str(tmp / "data"),
               "--port", str(port)]
        if args.workers > 1:
            cmd += ["--workers", str(args.workers)]
        cmd += ["--solver-threads", str(args.solver_threads)]
        gs = subprocess.Popen(cmd, cwd=REPO, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True)
        procs.append(gs)
        hs = subprocess.Popen([sys.executable, "-m", "http.server", str(hport), "--bind",
                               "127.0.0.1", "--directory", str(scene.resolve())],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        procs.append(hs)
        base = f"http://127.0.0.1:{port}"
        wait_up(base + "/api/info", gs)
        wait_up(f"http://127.0.0.1:{hport}/tileset.json", hs)

        print(f"load average at the start: {os.getloadavg()[0]:.1f} (1 min)", file=sys.stderr)
        results: dict = {"clients": args.clients, "loadavg_start": os.getloadavg()[0], "cpus": os.cpu_count(),
                         "workers": args.workers, "solver_threads": args.solver_threads,
                         "intersect": {}, "tiles": {}}
        print(f"gsgeo serve on {base} ({args.workers} worker(s)); {os.cpu_count()} CPUs",
              file=sys.stderr)
        runs = (("one client", 1, 200, 0.0), ("operators", args.clients, args.requests, args.think),
                ("saturation", args.clients, args.requests, 0.0))
        for name, clients, requests, think in runs:
            if name.split()[0] not in args.loads:
                continue
            print(f"intersect, {name}: {clients} clients x {requests} requests...",
                  file=sys.stderr)
            cpu0 = cpu_seconds(gs.pid)
            r = latency_run(port, clients, requests, think, seed=1, procs=args.client_procs)
            # each client's warm-up request counts towards the server's CPU too
            r["server_cpu_ms_per_request"] = ((cpu_seconds(gs.pid) - cpu0) * 1000
                                              / (r["requests"] + clients))
            results["intersect"][name] = r
            print(f"  p50 {r['p50_ms']:.1f} ms  p90 {r['p90_ms']:.1f} ms  p99 {r['p99_ms']:.1f} ms"
                  f"  max {r['max_ms']:.1f} ms  {r['req_per_s']:.0f} req/s  errors {r['errors']}"
                  f"  server CPU {r['server_cpu_ms_per_request']:.1f} ms/request"
                  f"  client CPU {r['client_cpu_ms_per_request']:.2f} ms/request"
                  f"  load average {os.getloadavg()[0]:.1f}",
                  file=sys.stderr)

        files = sorted(p.name for p in scene.iterdir() if p.is_file())
        tile_servers = (("gsgeo serve", f"{base}/scenes/bench/"),
                        ("python -m http.server", f"http://127.0.0.1:{hport}/"))
        for name, url in tile_servers if args.seconds > 0 else ():
            print(f"tiles, {name}: {len(files)} files, {args.seconds:.0f} s...", file=sys.stderr)
            r = throughput_run([url + f for f in files], args.seconds)
            results["tiles"][name] = r
            print(f"  {r['req_per_s']:.0f} req/s  {r['MiB_per_s']:.0f} MiB/s", file=sys.stderr)
        if args.plot:
            plot(results, Path(args.plot))
            print(f"plot: {args.plot}", file=sys.stderr)
        if args.json:
            slim = json.loads(json.dumps(results))
            for r in slim["intersect"].values():
                r.pop("latencies_ms")
            Path(args.json).write_text(json.dumps(slim, indent=2))
        print(f"\nload average at the end: {os.getloadavg()[0]:.1f} (1 min)")
        print("\n| load | requests | p50 ms | p90 ms | p99 ms | max ms | req/s | server CPU ms/req |")
        print("|---|---|---|---|---|---|---|---|")
        for name, r in results["intersect"].items():
            print(f"| {name} | {r['requests']} | {r['p50_ms']:.1f} | {r['p90_ms']:.1f} | "
                  f"{r['p99_ms']:.1f} | {r['max_ms']:.1f} | {r['req_per_s']:.0f} | "
                  f"{r['server_cpu_ms_per_request']:.1f} |")
        print("\n| tile server | req/s | MiB/s |")
        print("|---|---|---|")
        for name, r in results["tiles"].items():
            print(f"| {name} | {r['req_per_s']:.0f} | {r['MiB_per_s']:.0f} |")
    finally:
        for p in procs:
            p.terminate()
            try:
                p.wait(10)
            except subprocess.TimeoutExpired:
                p.kill()
        shutil.rmtree(tmp, ignore_errors=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
