"""An export that cannot measure its points says why: a grid whose geoid is not installed
(EPSG:7405, British National Grid + ODN heights, needs OSGM15) names the grid and how to
supply it, as POST /api/intersect does, not "no solved points" (every format, the query's
crs and the project's own)."""

from __future__ import annotations

import warnings

import pytest
from servertools import london_rays

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.crs import to_grid
from gsgeo.errors import DatumError
from gsgeo.server.app import ServerConfig, create_app


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    app = create_app(ServerConfig(data_dir=tmp_path_factory.mktemp("data"),
                                  allowed_hosts={"testserver"}))
    with TestClient(app) as c:
        for pid, crs in (("p", "EPSG:27700"), ("odn", "EPSG:27700")):
            assert c.post("/api/projects", json={"name": pid, "id": pid, "crs": crs}
                          ).status_code == 201
            assert c.post(f"/api/projects/{pid}/points",
                          json={"id": "P1", "rays": london_rays(4)}).status_code == 201
        assert c.patch("/api/projects/odn", json={"crs": "EPSG:7405"}).status_code == 200
        yield c


def test_the_grid_is_really_missing_here():
    with pytest.raises(DatumError, match="OSGM15"):
        to_grid([3978000.0, -8700.0, 4968000.0], None, "EPSG:7405")


@pytest.mark.parametrize("fmt", ["csv", "gpkg", "geojson", "geojson-grid", "cityjson"])
def test_export_in_a_crs_without_its_geoid_names_the_grid(client, fmt):
    r = client.get(f"/api/projects/p/export?format={fmt}&crs=EPSG:7405")
    assert r.status_code == 422, r.text
    body = r.json()
    assert body["field"] == "crs"
    assert "uk_os_OSGM15_GB.tif" in body["message"] and "not installed" in body["message"]
    assert "no solved points" not in body["message"]


def test_export_of_a_project_whose_points_all_failed_says_why(client):
    r = client.get("/api/projects/odn/export?format=csv")
    assert r.status_code == 422, r.text
    msg = r.json()["message"]
    assert "P1" in msg and "uk_os_OSGM15_GB.tif" in msg, msg

