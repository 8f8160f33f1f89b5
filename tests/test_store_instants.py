"""A time filter over measured_at means the same on both backends: a text without a time zone
(or in another form) names no instant and passes no filter, as in the reference
(PointFilter.matches); zones given as +HH:MM or +HHMM and fractions down to the microsecond
compare exactly. SQLite's own julianday() read a zone-less text as UTC and passed it."""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

from gsgeo.store import PointRecord, Project, open_store
from gsgeo.store.base import PointFilter, instant

T0 = datetime(2026, 5, 1, 12, 0, tzinfo=UTC)
STAMPS = {
    "zulu": "2026-05-01T12:05:00Z",
    "no-zone": "2026-05-01T12:05:00",  # no instant: in no time filter
    "space": "2026-05-01 12:05:00Z",  # not the ISO 8601 'T' form
    "date": "2026-05-01",
    "colon-less": "2026-05-01T14:05:00.000001+0200",  # = 12:05:00.000001Z
    "micro": "2026-05-01T12:04:59.999999Z",
    "nano": "2026-05-01T12:05:00.0000001Z",  # finer than a microsecond: not read
    "month-13": "2026-13-01T12:05:00Z",
}


@pytest.fixture(params=["sqlite", "postgresql"])
def store(request, tmp_path):
    url = None
    if request.param == "postgresql":
        cluster = request.getfixturevalue("pg_cluster")
        url = cluster.url(cluster.new_database())
    with open_store(tmp_path, url) as s:
        with s.transaction() as tx:
            tx.insert_project(Project(id="p", name="p"))
            for pid, stamp in STAMPS.items():
                tx.insert_point(PointRecord(project_id="p", id=pid, rays=london_rays(2),
                                            result={"point_id": pid, "measured_at": stamp}))
        yield s


@pytest.mark.parametrize(("start", "end", "want"), [
    (T0, None, {"zulu", "colon-less", "micro"}),
    (T0 + timedelta(minutes=5), None, {"zulu", "colon-less"}),
    (T0 + timedelta(minutes=5, microseconds=1), None, {"colon-less"}),
    (None, T0 + timedelta(minutes=5), {"zulu", "micro"}),
    (None, T0 + timedelta(minutes=4, seconds=59, microseconds=999998), set()),
])
def test_time_filters_take_only_instants_with_a_zone(store, start, end, want):
    f = PointFilter(measured_from=start, measured_to=end)
    with store.transaction(write=False) as tx:
        got = {r.id for r in tx.page_point_records("p", f)}
        assert tx.count_point_records("p", f) == len(got)
        reference = {p.id for p in tx.list_points("p") if f.matches(p.record)}
    assert got == want == reference


def test_instant_reads_only_iso_instants_with_a_zone():
    assert instant("2026-05-01T12:05:00Z") == T0 + timedelta(minutes=5)
    assert instant("2026-05-01T14:05:00+02:00") == T0 + timedelta(minutes=5)
    assert [instant(STAMPS[k]) for k in ("no-zone", "space", "date", "nano", "month-13")] \
        == [None] * 5
    assert instant(None) is None and instant(20260501) is None


def test_the_postgis_view_reads_measured_at_as_the_filters_do(request, tmp_path):
    cluster = request.getfixturevalue("pg_cluster")
    db = cluster.new_database()
    with open_store(tmp_path, cluster.url(db)) as s, s.transaction() as tx:
        tx.insert_project(Project(id="p", name="p"))
        for pid, stamp in STAMPS.items():
            tx.insert_point(PointRecord(project_id="p", id=pid, rays=london_rays(2),
                                        result={"point_id": pid, "measured_at": stamp}))
    rows = dict(cluster.sql(db, "SELECT point_id, measured_at FROM gsgeo_p_points"))
    assert {k for k, v in rows.items() if v is not None} == {"zulu", "colon-less", "micro"}
    assert rows["colon-less"] == T0 + timedelta(minutes=5, microseconds=1)
