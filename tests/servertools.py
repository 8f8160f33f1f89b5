"""Helpers for the store and server tests: synthetic rays at a known point, free ports."""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import numpy as np
import pyproj

REPO = Path(__file__).resolve().parents[1]
TO_ECEF = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)

#: A point in London: longitude, latitude (degrees), ellipsoidal height (m) on WGS 84.
LONDON = (-0.1276, 51.5072, 50.0)


def ecef_of(lon: float, lat: float, h: float) -> np.ndarray:
    return np.array(TO_ECEF.transform(lon, lat, h))


def rays_at(target_ecef, n: int = 4, rng: np.random.Generator | None = None,
            noise_rad: float = 0.0, ifov: float | None = None, radius: float = 30.0,
            height: float = 40.0) -> list[dict]:
    """Session-JSON rays from n cameras on a circle above the target, aimed at it.

    Cameras sit ``radius`` m away horizontally (in ECEF axes, which is fine for tests) and
    ``height`` m higher; ``noise_rad`` perturbs each direction by that angle (1 sigma).
    """
    rng = rng or np.random.default_rng(0)
    x = np.asarray(target_ecef, dtype=float)
    up = x / np.linalg.norm(x)
    east = np.cross([0.0, 0.0, 1.0], up)
    east /= np.linalg.norm(east)
    north = np.cross(up, east)
    rays = []
    for k in range(n):
        az = 2 * np.pi * k / n + 0.3
        o = x + radius * (np.cos(az) * east + np.sin(az) * north) + height * up
        d = (x - o) / np.linalg.norm(x - o)
        if noise_rad:
            d = d + rng.normal(0.0, noise_rad, 3)
        ray = {"origin": o.tolist(), "direction": d.tolist()}
        if ifov is not None:
            ray["ifov"] = ifov
        rays.append(ray)
    return rays


def london_rays(n: int = 4, **kw) -> list[dict]:
    return rays_at(ecef_of(*LONDON), n, **kw)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def start_server(data: Path, *extra: str, env: dict | None = None,
                 timeout: float = 30.0) -> tuple[subprocess.Popen, str]:
    """`gsgeo serve --data DATA` on a free loopback port; returns (process, base URL)."""
    port = free_port()
    proc = subprocess.Popen(
        [sys.executable, "-m", "gsgeo", "serve", "--data", str(data), "--port", str(port),
         *extra],
        cwd=REPO, env={**os.environ, **(env or {})},
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    base = f"http://127.0.0.1:{port}"
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            raise RuntimeError(f"gsgeo serve exited: {proc.stderr.read()}")
        try:
            if httpx.get(base + "/api/info", timeout=1.0).status_code in (200, 401):
                return proc, base
        except httpx.HTTPError:
            time.sleep(0.1)
    proc.kill()
    raise RuntimeError("gsgeo serve did not start in time")
