"""The workplace in a real browser against a point someone else changed meanwhile: the
viewer's change is refused (412, its If-Match names the version it loaded), it says so, and
the other change stays."""

from __future__ import annotations

import httpx
import pytest

import tests.e2e.test_workplace as workplace
from tests.e2e.workplace import SCENE
from tests.servertools import london_rays

pytestmark = pytest.mark.e2e



data_dir, server = workplace.data_dir, workplace.server  # a box scene and server of its own


def test_a_change_on_a_stale_point_is_refused_and_said(server, browser):
    api = f"{server}/api/projects"
    assert httpx.post(api, json={"name": "E2E 412", "id": "e412", "scene": SCENE,
                                 "crs": workplace.GRID}).status_code == 201
    r = httpx.post(f"{api}/e412/points", json={"id": "P1", "rays": london_rays(3)})
    assert r.status_code == 201, r.text
    p = workplace.Page(browser, f"{server}/?project=e412")
    try:
        p.page.click("#points-table tbody tr[data-id='P1']")
        p.page.wait_for_selector("#point-detail button:text('exclude')")
        theirs = httpx.patch(f"{api}/e412/points/P1", json={"code": "theirs"})
        assert theirs.status_code == 200 and theirs.headers["ETag"] == '"2"'
        with p.page.expect_response(lambda r: r.request.method == "PATCH") as resp:
            p.page.locator("#point-detail button:text('exclude')").first.click()
        assert resp.value.status == 412
        assert resp.value.request.headers.get("if-match") == '"1"'
        p.page.wait_for_selector("#messages .error:text('Changed by someone else meanwhile')")
        stored = httpx.get(f"{api}/e412/points/P1").json()
        assert stored["code"] == "theirs" and stored["excluded"] == [] and stored["version"] == 2
    finally:
        p.close()
