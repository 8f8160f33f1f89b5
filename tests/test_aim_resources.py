"""The matching routes' bounds: a view's size is read from its header and refused before any
decoding when the request's pixel budget is exceeded (a decompression bomb costs nothing),
and at most a few image jobs run at once, the others queued, then refused with 503 and
Retry-After."""

from __future__ import annotations

import base64
import copy
import threading

import cv2
import numpy as np
import pytest
from fastapi.testclient import TestClient
from test_aim_match import CLICKS, REF, camera, oblique, render, textured, truth

import gsgeo.aim.images as images
import gsgeo.server.aim as aim_routes
from gsgeo.aim.images import MAX_MATCH_PIXELS, encode_png, image_header
from gsgeo.server.app import ServerConfig, create_app


def match_body() -> dict:
    """A match the matcher finds (as tests/test_aim_api.py's): 640 x 480 views."""
    tex = textured(np.random.default_rng(3))
    tgt = camera(oblique(40.0), [0.4, -0.3, 0.0])
    _, t = truth(REF, tgt, CLICKS[0])
    return {"reference": {"image": encode_png(render(REF, tex)), "camera": REF.to_json(),
                          "pixel": CLICKS[0].tolist()},
            "target": {"image": encode_png(render(tgt, tex)), "origin": [0, 0],
                       "camera": tgt.to_json()},
            "depth": {"near_m": t - 0.5, "far_m": t + 0.5, "depth_m": t}}


@pytest.fixture(scope="module")
def served(tmp_path_factory):
    app = create_app(ServerConfig(data_dir=tmp_path_factory.mktemp("match"),
                                  allowed_hosts={"testserver"}))
    with TestClient(app) as client:
        yield client, match_body()


def flat(w: int, h: int, ext: str = ".png") -> str:
    """A flat grey image: a few kilobytes for millions of pixels."""
    ok, buf = cv2.imencode(ext, np.full((h, w), 90, np.uint8))
    assert ok
    return base64.b64encode(buf.tobytes()).decode("ascii")


@pytest.fixture
def no_decoding(monkeypatch):
    """cv2.imdecode must not be reached."""
    def refuse(*_a, **_k):
        raise AssertionError("the image was decoded")

    monkeypatch.setattr(images.cv2, "imdecode", refuse)


@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_the_header_gives_the_size_without_decoding(ext, no_decoding):
    h = image_header(flat(300, 200, ext), "target.image")
    assert (h.width, h.height) == (300, 200)


@pytest.mark.parametrize("ext", [".png", ".jpg"])
def test_a_view_over_the_pixel_budget_is_refused_before_decoding(served, ext, no_decoding):
    client, body = served
    body = copy.deepcopy(body)
    side = int(np.sqrt(MAX_MATCH_PIXELS)) + 64  # alone over the budget, 5-30 kB sent
    body["target"]["image"] = flat(side, side, ext)
    body["target"]["camera"].update(width=side, height=side)
    r = client.post("/api/match", json=body)
    assert r.status_code == 422, r.text
    msg = r.json()["message"]
    assert r.json()["field"] == "target.image" and f"{side}x{side}" in msg
    assert f"{MAX_MATCH_PIXELS}" in msg


def test_the_budget_is_of_both_views_together(served, no_decoding):
    client, body = served
    body = copy.deepcopy(body)
    w = 3000
    h = MAX_MATCH_PIXELS // w // 2 + 8  # each just over half the budget
    for side in ("reference", "target"):
        body[side]["image"] = flat(w, h)
        body[side]["camera"].update(width=w, height=h)
    r = client.post("/api/match", json=body)
    assert r.status_code == 422 and r.json()["field"] == "target.image", r.text


def test_a_view_within_the_budget_still_matches(served):
    client, body = served
    body = copy.deepcopy(body)
    r = client.post("/api/match", json=body)
    assert r.status_code == 200 and r.json()["ok"] is True, r.text


def test_image_jobs_beyond_the_slots_and_queue_get_503_with_retry_after(tmp_path, monkeypatch):
    """One slot, no queue: while a match runs, the next is refused at once (no thread waits
    for it, no image of it decoded); after it, matching goes on."""
    started, release = threading.Event(), threading.Event()
    calls = []

    def slow_match(*args, **kwargs):
        calls.append(1)
        if len(calls) == 1:
            started.set()
            assert release.wait(10)
        return {"ok": False, "pixel": None, "score": None, "second": None, "depth_m": None,
                "reason": "test"}

    monkeypatch.setattr(aim_routes, "match_views", slow_match)
    body = match_body()
    app = create_app(ServerConfig(data_dir=tmp_path, allowed_hosts={"testserver"},
                                  image_jobs=1, image_queue=0))
    with TestClient(app) as client:
        first: list = []
        t = threading.Thread(target=lambda: first.append(client.post("/api/match", json=body)))
        t.start()
        try:
            assert started.wait(10)
            r = client.post("/api/match", json=body)
            assert r.status_code == 503, r.text
            assert int(r.headers["retry-after"]) >= 1
            assert "busy" in r.json()["message"] and len(calls) == 1
        finally:
            release.set()
            t.join(10)
        assert first[0].status_code == 200
        assert client.post("/api/match", json=body).status_code == 200 and len(calls) == 2
