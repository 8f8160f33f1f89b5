"""POST /api/intersect against gsgeo.measure.point, and the solver threads it runs on."""

from __future__ import annotations

import asyncio
import math
import threading
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest
from servertools import LONDON, ecef_of, london_rays, rays_at

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

import gsgeo.server.api as api
from gsgeo.errors import InputError
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.server.intersect_pool import IntersectPool
from gsgeo.session import measure_session_point as measure_point
from gsgeo.session import parse_point


@pytest.fixture
def client(tmp_path):
    app = create_app(ServerConfig(data_dir=tmp_path / "data", allowed_hosts={"testserver"}))
    with TestClient(app) as c:
        yield c


def expected(body: dict) -> dict:
    """What gsgeo.measure.point gives for the request's rays, called here directly."""
    pt = parse_point({"id": body.get("id", "P"), "code": body.get("code", ""),
                      "description": body.get("description", ""), "rays": body["rays"]}, "p")
    m = measure_point(pt, crs=body.get("crs"), vertical=body.get("vertical"),
                      source_crs=body.get("source_crs", "EPSG:4978"),
                      sigma_px=body.get("sigma_px", 1.0), exclude=body.get("exclude", ()))
    return m.to_dict()


def same(got, want, where: str = "") -> None:
    """Equal field by field; NaN and infinities of the pipeline are null in JSON."""
    if isinstance(want, dict):
        assert isinstance(got, dict) and set(got) == set(want), (where, got, want)
        for k in want:
            same(got[k], want[k], f"{where}.{k}")
    elif isinstance(want, (list, tuple)):
        assert isinstance(got, list) and len(got) == len(want), (where, got, want)
        for i, (g, w) in enumerate(zip(got, want, strict=True)):
            same(g, w, f"{where}[{i}]")
    elif isinstance(want, float) and not math.isfinite(want):
        assert got is None, (where, got)
    else:
        assert got == want and type(got) is type(want), (where, got, want)


CASES = {
    "angular, UTM, one ray excluded": {
        "rays": london_rays(5, ifov=1e-3, noise_rad=1e-3, rng=np.random.default_rng(7)),
        "crs": "EPSG:32630", "sigma_px": 0.7, "exclude": [1], "id": "K1", "code": "kerb",
        "description": "north-east corner"},
    "unweighted, British grid": {
        "rays": london_rays(3, noise_rad=2e-4, rng=np.random.default_rng(8)), "crs": "EPSG:27700"},
    "no grid CRS": {"rays": london_rays(4, noise_rad=1e-4, rng=np.random.default_rng(9))},
    "ETRS89 scene": {"rays": london_rays(4, ifov=5e-4), "crs": "EPSG:25830",
                     "source_crs": "EPSG:4936"},
}


@pytest.mark.parametrize("name", list(CASES))
def test_intersect_equals_the_pipeline_field_by_field(client, name):
    body = CASES[name]
    r = client.post("/api/intersect", json=body)
    assert r.status_code == 200, r.text
    assert r.headers["content-type"] == "application/json"
    got, want = r.json(), expected(body)
    assert got.pop("measured_at").endswith("Z") and want.pop("measured_at").endswith("Z")
    same(got, want)
    assert got["point_id"] == body.get("id", "P")
    assert got["n_rays"] == len(body["rays"]) - len(body.get("exclude", []))


def test_non_finite_values_become_null(client):
    # An excluded ray aimed away from the point: its pixel residual has no meaning (NaN).
    rays = london_rays(4, ifov=1e-3)
    rays[3]["direction"] = [-v for v in rays[3]["direction"]]
    body = {"rays": rays, "exclude": [3], "crs": "EPSG:32630"}
    want = expected(body)
    assert math.isnan(want["rays"][3]["residual_px"])  # the case this test is about
    got = client.post("/api/intersect", json=body).json()
    assert got["rays"][3]["residual_px"] is None and got["rays"][3]["excluded"] is True
    assert got["rays"][0]["residual_px"] == want["rays"][0]["residual_px"]


def test_concurrent_requests_each_get_their_own_point(client):
    targets = [(LONDON[0] + 2e-4 * k, LONDON[1] - 1e-4 * k, 30.0 + k) for k in range(24)]

    def post(k: int) -> tuple[int, dict]:
        r = client.post("/api/intersect", json={"rays": rays_at(ecef_of(*targets[k]), 4),
                                                "id": f"T{k}"})
        assert r.status_code == 200, r.text
        return k, r.json()

    with ThreadPoolExecutor(8) as ex:
        results = list(ex.map(post, range(len(targets))))
    for k, out in results:
        assert out["point_id"] == f"T{k}"
        assert out["lon"] == pytest.approx(targets[k][0], abs=1e-9)
        assert out["lat"] == pytest.approx(targets[k][1], abs=1e-9)
        assert out["h_wgs84"] == pytest.approx(targets[k][2], abs=1e-4)


def test_intersect_runs_on_the_long_lived_solver_thread(client, monkeypatch):
    seen = []
    real = api.measure

    def spy(*args, **kw):
        seen.append((threading.current_thread().name, threading.get_ident()))
        return real(*args, **kw)

    monkeypatch.setattr(api, "measure", spy)
    for k in range(5):
        assert client.post("/api/intersect", json={"rays": london_rays(3 + k % 2)}).status_code == 200
    assert len(seen) == 5 and all(name.startswith("gsgeo-solve") for name, _ in seen), seen
    assert len({ident for _, ident in seen}) == 1  # one solver thread by default, kept


def test_solver_pool_threads_errors_and_restart():
    pool = IntersectPool(2)
    warmed = []

    def where() -> tuple[str, int]:
        return threading.current_thread().name, threading.get_ident()

    def fail() -> None:
        raise InputError("rays[0].origin: bad")

    async def go() -> list:
        await pool.warm_up(lambda: warmed.append(where()))
        out = [await pool.run(where) for _ in range(10)]
        with pytest.raises(InputError, match="rays"):
            await pool.run(fail)
        return out

    used = asyncio.run(go())
    assert len({i for _, i in warmed}) == 2  # warm-up reached both threads
    assert {i for _, i in used} <= {i for _, i in warmed}
    assert all(n.startswith("gsgeo-solve") for n, _ in used)
    pool.close()
    assert asyncio.run(pool.run(lambda: 42)) == 42  # usable again after close
    pool.close()
    with pytest.raises(ValueError):
        IntersectPool(0)
