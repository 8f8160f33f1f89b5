"""The aiming routes over HTTP: answers on a real (tiny) tileset, and 404 / 409 / 422 cases."""

from __future__ import annotations

import numpy as np
import pytest
from aim_helpers import plane_tileset
from fastapi.testclient import TestClient

from gsgeo.server.app import ServerConfig, create_app


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    data = tmp_path_factory.mktemp("aimdata")
    m = plane_tileset(data / "scenes" / "plane", np.random.default_rng(7))
    (data / "scenes" / "hosted").mkdir()
    (data / "scenes" / "hosted" / "tileset.json").write_text(
        (data / "scenes" / "plane" / "tileset.json").read_text())
    app = create_app(ServerConfig(data_dir=data, allowed_hosts={"testserver"},
                                  scene_urls={"hosted": "https://tiles.example/h/"}))
    with TestClient(app) as client:
        yield client, m


def _ray(m: np.ndarray, local_origin, local_target) -> dict:
    o = m[:3, :3] @ np.asarray(local_origin, float) + m[:3, 3]
    t = m[:3, :3] @ np.asarray(local_target, float) + m[:3, 3]
    return {"origin": o.tolist(), "direction": (t - o).tolist(), "ifov": 1e-3}


def test_depth_of_the_plane(served):
    client, m = served
    r = client.post("/api/scenes/plane/depth", json={"ray": _ray(m, [3, 4, 10], [1, 1, 0])})
    assert r.status_code == 200, r.text
    body = r.json()
    expected = float(np.linalg.norm([2, 3, 10]))
    assert body["hit"] is True and body["reason"] is None
    assert abs(body["depth_m"] - expected) < 0.03
    target = m[:3, :3] @ [1, 1, 0] + m[:3, 3]
    assert np.linalg.norm(np.array(body["point_ecef"]) - target) < 0.03
    assert body["near_m"] < body["depth_m"] < body["far_m"]
    assert body["n_splats"] > 0


def test_depth_into_the_sky(served):
    client, m = served
    r = client.post("/api/scenes/plane/depth", json={"ray": _ray(m, [0, 0, 2], [0, 1, 5])})
    assert r.status_code == 200
    assert r.json()["hit"] is False and "sky" in r.json()["reason"]


def test_depth_of_an_unknown_scene_is_404(served):
    client, m = served
    for name in ("nosuch", "..", "a%2Fb"):
        r = client.post(f"/api/scenes/{name}/depth", json={"ray": _ray(m, [0, 0, 2], [0, 0, 0])})
        assert r.status_code == 404, (name, r.text)


def test_depth_of_a_scene_on_a_static_host_is_409(served):
    client, m = served
    r = client.post("/api/scenes/hosted/depth", json={"ray": _ray(m, [0, 0, 2], [0, 0, 0])})
    assert r.status_code == 409
    assert "static host" in r.json()["message"]


@pytest.mark.parametrize("ray, field", [
    ({"origin": [0, 0], "direction": [0, 0, 1]}, "ray.origin"),
    ({"origin": [1e6, 0, 0], "direction": [0, 0, 0]}, "ray.direction"),
    ({"origin": [1e6, 0, 0], "direction": [0, 0, 1], "ifov": -1}, "ray.ifov"),
    ({"origin": [1e6, 0, 0], "direction": [0, 0, 1], "model_matrix": [0] * 16}, "model_matrix"),
])
def test_depth_of_a_bad_ray_is_422_naming_the_field(served, ray, field):
    client, _ = served
    r = client.post("/api/scenes/plane/depth", json={"ray": ray})
    assert r.status_code == 422, r.text
    assert field in r.json()["message"]
