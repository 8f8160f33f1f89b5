"""The aiming routes over HTTP: answers on a real (tiny) tileset, and 404 / 409 / 422 cases."""

from __future__ import annotations

import json

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
    up = m[:3, 2] / np.linalg.norm(m[:3, 2])                  # the plane's normal, local up
    assert np.dot(body["normal_ecef"], up) > 0.99


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


# /api/match ---------------------------------------------------------------------------------
def _match_body(angle: float = 40.0) -> tuple[dict, np.ndarray]:
    from test_aim_match import CLICKS, REF, camera, oblique, render, textured, truth

    from gsgeo.aim.images import encode_png

    tex = textured(np.random.default_rng(3))
    tgt = camera(oblique(angle), [0.4, -0.3, 0.0])
    px, t = truth(REF, tgt, CLICKS[0])
    body = {"reference": {"image": "data:image/png;base64," + encode_png(render(REF, tex)),
                          "camera": REF.to_json(), "pixel": CLICKS[0].tolist()},
            "target": {"image": encode_png(render(tgt, tex)), "origin": [0, 0],
                       "camera": tgt.to_json()},
            "depth": {"near_m": t - 0.5, "far_m": t + 0.5, "depth_m": t}}
    return body, px


def test_match_finds_the_click_in_the_target_view(served):
    client, _ = served
    body, px = _match_body()
    r = client.post("/api/match", json=body)
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["ok"] is True and out["reason"] is None
    # PNG keeps 8 bits: the truth within 0.3 px still
    assert np.linalg.norm(np.array(out["pixel"]) - px) < 0.3
    assert out["score"] > 0.9


def test_match_declines_with_a_reason_and_200(served):
    client, _ = served
    body, _ = _match_body()
    body["reference"]["pixel"] = [3.0, 3.0]
    r = client.post("/api/match", json=body)
    assert r.status_code == 200
    assert r.json()["ok"] is False and r.json()["pixel"] is None
    assert r.json()["reason"].startswith("outside the view")


@pytest.mark.parametrize("change, field", [
    (lambda b: b["reference"].update(image="not base64!"), "reference.image"),
    (lambda b: b["target"].update(image="aGVsbG8gd29ybGQ="), "target.image"),
    (lambda b: b["target"]["camera"].update(up=b["target"]["camera"]["direction"]),
     "target.camera.up"),
    (lambda b: b["target"]["camera"].update(direction=[0, 0, 0]), "target.camera.direction"),
    (lambda b: b["reference"]["camera"].update(fovy=4.0), "reference.camera.fovy"),
    (lambda b: b["depth"].update(near_m=b["depth"]["far_m"] + 1), "depth"),
    (lambda b: b["depth"].update(depth_m=b["depth"]["far_m"] + 1), "depth.depth_m"),
    (lambda b: b["reference"].pop("pixel"), "reference.pixel"),
    (lambda b: b.pop("depth"), "depth"),
    (lambda b: b["target"]["camera"].update(width=640, height=360), "target.image"),
    (lambda b: b["depth"].update(normal_ecef=[0, 0, 0]), "depth.normal_ecef"),
    (lambda b: b["reference"].update(origin=[100, 0]), "reference.image"),
])
def test_match_of_a_bad_request_is_422_naming_the_field(served, change, field):
    client, _ = served
    body, _ = _match_body()
    change(body)
    r = client.post("/api/match", json=body)
    assert r.status_code == 422, r.text
    assert field in r.json()["message"], r.json()["message"]


def test_scene_match_weights_by_the_splats_and_checks_its_scene(served):
    """POST /api/scenes/{scene}/match: the plane's splats placed by the modelMatrix where the
    synthetic views see their plane cover the whole patch and have its shape, so the answer
    is the plain match's (within 0.05 px); an unknown scene is 404, a static host's 409, a
    singular matrix 422."""
    from aim_helpers import AXES, ORIGIN

    client, m = served
    body, px = _match_body()
    to_render = np.eye(4)
    to_render[:3, :3], to_render[:3, 3] = AXES, ORIGIN
    mm = to_render @ np.linalg.inv(m)                      # tileset ECEF -> local -> views'
    body["model_matrix"] = mm.T.reshape(-1).tolist()       # column-major
    r = client.post("/api/scenes/plane/match", json=body)
    assert r.status_code == 200, r.text
    plain = client.post("/api/match", json=body).json()
    assert r.json()["ok"] is True and plain["ok"] is True
    assert np.allclose(r.json()["pixel"], plain["pixel"], atol=0.05)
    assert np.linalg.norm(np.array(r.json()["pixel"]) - px) < 0.3
    assert client.post("/api/scenes/nosuch/match", json=body).status_code == 404
    assert client.post("/api/scenes/hosted/match", json=body).status_code == 409
    body["model_matrix"] = [0.0] * 15 + [1.0]
    r = client.post("/api/scenes/plane/match", json=body)
    assert r.status_code == 422 and "model_matrix" in r.json()["message"], r.text


# /api/scenes/{scene}/views ------------------------------------------------------------------
def _views_body(m: np.ndarray, **extra) -> dict:
    point = (m[:3, :3] @ [1.0, 1.0, 0.0] + m[:3, 3]).tolist()
    return {"rays": [_ray(m, [6, 1, 8], [1, 1, 0])], "point_ecef": point, "k": 3,
            "fovy": 1.0, "width": 1280, "height": 720, **extra}


def test_views_of_a_point_on_the_plane(served):
    client, m = served
    r = client.post("/api/scenes/plane/views", json=_views_body(m))
    assert r.status_code == 200, r.text
    views = r.json()["views"]
    assert len(views) == 3
    for v in views:
        assert v["range_m"] == pytest.approx(np.linalg.norm([5, 0, 8]))
        assert v["min_angle_deg"] > 30 and v["occluded"] is False
        assert set(v["camera"]) == {"position", "direction", "up", "fovy", "width", "height"}


def test_views_404_409_and_422(served):
    client, m = served
    assert client.post("/api/scenes/nosuch/views", json=_views_body(m)).status_code == 404
    assert client.post("/api/scenes/hosted/views", json=_views_body(m)).status_code == 409
    for bad, field in (({"k": 0}, "k"), ({"k": 13}, "k"), ({"rays": []}, "rays"),
                       ({"fovy": 0}, "fovy"), ({"point_ecef": [1, 2]}, "point_ecef"),
                       ({"width": 0}, "width")):
        r = client.post("/api/scenes/plane/views", json=_views_body(m, **bad))
        assert r.status_code == 422, (bad, r.text)
        assert field in r.json()["message"]
    body = _views_body(m)
    body["point_ecef"] = body["rays"][0]["origin"]
    r = client.post("/api/scenes/plane/views", json=body)
    assert r.status_code == 422 and "point_ecef" in r.json()["message"]


def test_the_splats_are_read_once_per_tileset_version(served, tmp_path):
    import shutil

    from gsgeo.aim.splatindex import scene_index

    client, _ = served
    src = client.app.state.config.data_dir / "scenes" / "plane"
    copy = tmp_path / "plane"
    shutil.copytree(src, copy)
    first = scene_index(copy / "tileset.json")
    assert scene_index(copy / "tileset.json") is first
    ts = copy / "tileset.json"
    ts.write_text(ts.read_text() + "\n")          # a regenerated tileset.json
    again = scene_index(ts)
    assert again is not first and again.count == first.count


def test_a_scene_whose_splats_cannot_be_read_is_409_not_500(served, tmp_path):
    client, m = served
    data = client.app.state.config.data_dir
    broken = data / "scenes" / "broken"
    broken.mkdir(exist_ok=True)
    (broken / "tileset.json").write_text('{"asset": {"version": "1.1"}, "root": {"geometricError'
                                         '": 0, "content": {"uri": "t.glb"}}}')
    (broken / "t.glb").write_bytes(b"glTF\x02\x00\x00\x00" + b"\x00" * 30)
    notjson = data / "scenes" / "notjson"
    notjson.mkdir(exist_ok=True)
    (notjson / "tileset.json").write_text("{ this is not json")
    for name in ("broken", "notjson"):
        for path, body in ((f"/api/scenes/{name}/depth", {"ray": _ray(m, [0, 0, 2], [0, 0, 0])}),
                           (f"/api/scenes/{name}/views", _views_body(m))):
            r = client.post(path, json=body)
            assert r.status_code == 409, (name, path, r.text)
            assert "cannot be read" in r.json()["message"]


def test_views_for_the_scene_matcher_are_asked_by_shape_views(served):
    """shape_views true is accepted (the plane's splats are one plane: the same views as
    without it); a value that is not a boolean is 422 naming the field."""
    client, m = served
    plain = client.post("/api/scenes/plane/views", json=_views_body(m))
    shaped = client.post("/api/scenes/plane/views", json=_views_body(m, shape_views=True))
    assert plain.status_code == 200 and shaped.status_code == 200, shaped.text
    assert [v["azimuth_deg"] for v in shaped.json()["views"]] == \
        [v["azimuth_deg"] for v in plain.json()["views"]]
    r = client.post("/api/scenes/plane/views", json=_views_body(m, shape_views=[1]))
    assert r.status_code == 422 and "shape_views" in r.json()["message"], r.text


# absurd numbers: finite, yet no point, camera or pixel of a scene --------------------------
@pytest.mark.parametrize(("change", "field"), [
    ({"point_ecef": [1e300, 0.0, 0.0]}, "point_ecef[0]"),
    ({"point_ecef": [0.0, 0.0, -2e9]}, "point_ecef[2]"),
    ({"point_ecef": [9e8, 9e8, 9e8]}, "point_ecef"),  # each axis in range, not the point
])
def test_views_of_an_absurd_point_are_422(served, change, field):
    client, m = served
    r = client.post("/api/scenes/plane/views", json=_views_body(m, **change))
    assert r.status_code == 422, r.text
    assert r.json()["field"] == field, r.text


@pytest.mark.parametrize(("where", "value", "field"), [
    (("reference", "camera", "position"), [1e300, 0.0, 0.0], "reference.camera.position"),
    (("target", "camera", "position"), [0.0, -1e12, 0.0], "target.camera.position"),
    (("reference", "camera", "direction"), [0.0, 0.0, 0.0], "reference.camera.direction"),
    (("target", "camera", "up"), [1e-300, 0.0, 0.0], "target.camera.up"),
    (("reference", "pixel"), [1e300, 5.0], "reference.pixel"),
    (("target", "origin"), [-1e300, 5.0], "target.origin"),
    (("depth", "normal_ecef"), [1e300, 0.0, 0.0], "depth.normal_ecef"),
    (("depth", "normal_ecef"), [0.0, 0.0, 0.0], "depth.normal_ecef"),
])
def test_match_with_absurd_numbers_is_422_naming_the_field(served, where, value, field):
    client, _ = served
    body, _ = _match_body()
    part = body
    for key in where[:-1]:
        part = part[key]
    part[where[-1]] = value
    for url in ("/api/match", "/api/scenes/plane/match"):
        r = client.post(url, json=body)
        assert r.status_code == 422, (url, r.text)
        assert r.json()["field"].startswith(field), r.text


def test_visible_says_which_points_the_plane_hides(served):
    """POST /scenes/{scene}/visible from 10 m above the plane (local z = 0): a point on it and
    one 3 m above it are seen; one 2 m under it is hidden, the plane's surface at the
    distance where the ray crosses z = 0 (hand geometry); bad input is 4xx naming the field."""
    client, m = served

    def world(p):
        return (m[:3, :3] @ np.asarray(p, float) + m[:3, 3]).tolist()

    origin = [3.0, 4.0, 10.0]
    pts = [[1.0, 1.0, 0.0], [2.0, 2.0, 3.0], [1.0, 1.0, -2.0]]
    r = client.post("/api/scenes/plane/visible",
                    json={"origin": world(origin), "points": [world(p) for p in pts]})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["hidden"] == [False, False, True]
    under = np.subtract(pts[2], origin)
    crossing = float(np.linalg.norm(under) * 10.0 / 12.0)  # z goes 10 -> -2: the plane at 10/12
    assert abs(body["surface_m"][2] - crossing) < 0.05, (body, crossing)
    assert body["distance_m"][2] == pytest.approx(float(np.linalg.norm(under)))
    assert client.post("/api/scenes/nosuch/visible", json={"origin": world(origin),
                                                           "points": [world(pts[0])]}).status_code == 404
    assert client.post("/api/scenes/hosted/visible", json={"origin": world(origin),
                                                           "points": [world(pts[0])]}).status_code == 409
    for bad, field in (({"origin": world(origin), "points": []}, "points"),
                       ({"origin": world(origin), "points": [world(pts[0])] * 201}, "points"),
                       ({"points": [world(pts[0])]}, "origin"),
                       ({"origin": world(origin), "points": [world(origin)]}, "points"),
                       ({"origin": world(origin), "points": [world(pts[0])],
                         "model_matrix": [0.0] * 16}, "model_matrix")):
        r = client.post("/api/scenes/plane/visible", json=bad)
        assert r.status_code == 422, (bad, r.text)
        assert field in r.text, (field, r.text)


# /api/snap ----------------------------------------------------------------------------------
def _snap_body(click) -> dict:
    from test_aim_match import REF
    from test_aim_snap import ORIGIN, checker, drawn

    from gsgeo.aim.images import encode_png

    return {"reference": {"image": encode_png(drawn(checker)), "origin": ORIGIN.tolist(),
                          "camera": REF.to_json(), "pixel": list(click)}}


def test_snap_moves_a_click_onto_the_target_centre_or_says_why_not(served):
    from test_aim_snap import FEATURE, ORIGIN

    client, _ = served
    truth = FEATURE + ORIGIN
    r = client.post("/api/snap", json=_snap_body(truth + [1.2, -0.9]))
    assert r.status_code == 200, r.text
    out = r.json()
    assert out["ok"] is True and out["reason"] is None
    assert np.linalg.norm(np.array(out["pixel"]) - truth) < 0.15  # PNG's 8 bits included
    assert out["moved_px"] == pytest.approx(1.5, abs=0.15)
    far = truth + [10.0, 10.0]  # on the flat white rim: nothing to snap to
    r = client.post("/api/snap", json=_snap_body(far))
    assert r.status_code == 200 and r.json()["ok"] is False
    assert r.json()["pixel"] == pytest.approx(far.tolist()) and r.json()["reason"]


@pytest.mark.parametrize("change, field", [
    (lambda b: b["reference"].update(image="not base64!"), "reference.image"),
    (lambda b: b["reference"].pop("pixel"), "reference.pixel"),
    (lambda b: b["reference"]["camera"].update(fovy=4.0), "reference.camera.fovy"),
    (lambda b: b["reference"].update(origin=[2000, 0]), "reference.image"),
    (lambda b: b["reference"].update(pixel=[float("nan"), 3]), "reference.pixel"),
    (lambda b: b.update(extra=1), "extra"),
])
def test_snap_of_a_bad_request_is_422_naming_the_field(served, change, field):
    from test_aim_snap import FEATURE

    client, _ = served
    body = _snap_body(FEATURE)
    change(body)
    r = client.post("/api/snap", content=json.dumps(body, allow_nan=True),
                    headers={"content-type": "application/json"})
    assert r.status_code == 422, r.text
    assert field in r.json()["message"], r.json()["message"]
