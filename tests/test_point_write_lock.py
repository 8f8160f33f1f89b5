"""A new point is solved before its write transaction: writers do not wait for each other's
solves, and a settings change that lands between the solve and the write is not lost (the
point is measured again, inside the transaction, with the settings it is stored under)."""

from __future__ import annotations

import threading
import time

import pytest
from servertools import london_rays

from gsgeo.service import Projects, open_store


@pytest.fixture
def svc(tmp_path):
    s = open_store(tmp_path)
    yield Projects(s, tmp_path)
    s.close()


def test_a_slow_solve_does_not_hold_other_writers(svc, monkeypatch):
    p = svc.create_project(name="London", crs="EPSG:32630")
    real = Projects._measure_into
    solving = threading.Event()

    def slow(self, pt, *a, **kw):
        if pt.code == "slow":
            solving.set()
            time.sleep(1.5)
        return real(self, pt, *a, **kw)

    monkeypatch.setattr(Projects, "_measure_into", slow)
    worker = threading.Thread(target=svc.add_point,
                              args=(p.id, {"id": "S", "code": "slow", "rays": london_rays(3)}))
    worker.start()
    try:
        assert solving.wait(10)
        t0 = time.perf_counter()
        svc.add_point(p.id, {"id": "F", "rays": london_rays(3)})
        svc.update_project(p.id, {"description": "changed meanwhile"})
        waited = time.perf_counter() - t0
    finally:
        worker.join(20)
    assert waited < 1.0, f"a write waited {waited:.2f} s for another point's solve"
    assert {q.id for q in svc.list_points(p.id)} == {"S", "F"}


def test_a_settings_change_during_the_solve_is_measured_into_the_point(svc, monkeypatch):
    p = svc.create_project(name="London", crs="EPSG:32630")
    real = Projects._measure_into
    calls: list[int] = []

    def meanwhile(self, pt, proj, *a, **kw):
        calls.append(proj.settings_rev)
        out = real(self, pt, proj, *a, **kw)
        if len(calls) == 1:  # the solve before the write: another request changes the CRS
            svc.update_project(p.id, {"crs": "EPSG:27700"})
        return out

    monkeypatch.setattr(Projects, "_measure_into", meanwhile)
    stored = svc.add_point(p.id, {"rays": london_rays(3)})
    assert len(calls) == 2 and calls[1] > calls[0]  # measured again, with the new settings
    got = svc.get_point(p.id, stored.id)
    assert got.id == "P1" and got.result is not None and got.result["point_id"] == "P1"
    assert got.record is not None and got.record["crs"] == "EPSG:27700"
    assert got.solved_rev == svc.get_project(p.id).settings_rev
