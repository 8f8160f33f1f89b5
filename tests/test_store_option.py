"""Commands that read a project take ``--store URL`` (or GSGEO_STORE) as gsgeo serve does:
``gsgeo report`` and ``gsgeo georef --project`` read a project kept in PostgreSQL; a bad URL
is one message and exit 2."""

from __future__ import annotations

import pytest
from pgcluster import pg_cluster  # noqa: F401  (the session's PostgreSQL cluster)
from servertools import london_rays

from gsgeo.cli import main
from gsgeo.service import open_projects


@pytest.fixture
def pg_project(request, tmp_path) -> str:
    """The URL of a fresh database holding project 'p' with point 'A'."""
    cluster = request.getfixturevalue("pg_cluster")
    url = cluster.url(cluster.new_database())
    svc = open_projects(tmp_path / "data", url=url)
    try:
        svc.create_project(name="p", id="p", crs="EPSG:27700")
        svc.add_point("p", {"id": "A", "rays": london_rays()})
    finally:
        svc.store.close()
    return url


def test_report_reads_a_project_from_postgresql(pg_project, tmp_path, monkeypatch, capsys):
    out = tmp_path / "r.html"
    data = tmp_path / "nowhere"  # no SQLite store: the project is in PostgreSQL only
    assert main(["report", "p", "-o", str(out), "--data", str(data), "--store", pg_project]) == 0
    assert "Measured points (1)" in out.read_text()
    monkeypatch.setenv("GSGEO_STORE", pg_project)
    out.unlink()
    assert main(["report", "p", "-o", str(out), "--data", str(data)]) == 0 and out.is_file()
    (tmp_path / "data").mkdir(exist_ok=True)
    assert main(["georef", "--project", "zz", "--data", str(tmp_path / "data")]) == 2
    assert "project 'zz' does not exist" in capsys.readouterr().err
    main(["georef", "--project", "p", "--data", str(tmp_path / "data")])  # found: no control
    assert "does not exist" not in capsys.readouterr().err


def test_a_bad_store_url_is_one_message_and_exit_2(tmp_path, capsys):
    assert main(["report", "p", "-o", str(tmp_path / "r.html"), "--store", "ftp://x"]) == 2
    err = capsys.readouterr().err.strip()
    assert "ftp://" in err and "postgresql://" in err and "\n" not in err
    assert not (tmp_path / "r.html").exists()
