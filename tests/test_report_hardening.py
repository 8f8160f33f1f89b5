"""The survey report against hostile project text and resources: ids that matplotlib would
read as mathtext, documents that reference files or URLs (WeasyPrint must fetch nothing),
and the PDF's cost (one report per project at a time, its answer reused)."""

from __future__ import annotations

import base64
import http.server
import io
import re
import threading
import warnings

import cv2
import numpy as np
import pypdf
import pytest
from servertools import ecef_of, rays_at

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.cli import main
from gsgeo.report import render
from gsgeo.report.pdf import html_to_pdf
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import open_projects
from gsgeo.service.checkpoints import CheckPointRow
from gsgeo.service.reporting import report_data

CRS = "EPSG:32630"
#: Ids matplotlib's mathtext refuses (or would typeset) when it parses them.
MATH_IDS = ["$a_$", "$^{$", "x$^$y", "$$", "50$ & 60$"]


@pytest.fixture
def math_dir(tmp_path):
    """A project whose points, check points and code carry dollar signs."""
    svc = open_projects(tmp_path)
    try:
        p = svc.create_project(name="Cost $x_$ site", id="money", crs=CRS,
                               description="$\\alpha$ and $b_$")
        for k, pid in enumerate(MATH_IDS):
            svc.add_point(p.id, {"id": pid, "code": "$c_$",
                                 "rays": rays_at(ecef_of(-0.1276 + 1e-4 * k, 51.5072, 50.0), 3,
                                                 ifov=0.0005)})
        recs = {q.id: q.record for q in svc.list_points(p.id)}
        svc.add_check_points(p.id, [CheckPointRow(i, recs[i]["easting"] + 0.01,
                                                  recs[i]["northing"] - 0.01,
                                                  recs[i]["height"] + 0.02)
                                    for i in MATH_IDS], CRS)
    finally:
        svc.store.close()
    return tmp_path


def test_ids_with_dollar_signs_are_drawn_as_text_in_html_pdf_api_and_cli(math_dir, tmp_path):
    out = tmp_path / "r.html"
    assert main(["report", "money", "--data", str(math_dir), "-o", str(out)]) == 0
    html = out.read_text()
    # the plans (points, check residuals) and the dH bars are there: no figure was dropped
    assert html.count("data:image/png;base64,") == 3
    for pid in MATH_IDS:
        assert f"<td>{pid.replace('&', '&amp;')}</td>" in html, pid
    with TestClient(create_app(ServerConfig(data_dir=math_dir,
                                            allowed_hosts={"testserver"}))) as client:
        r = client.get("/api/projects/money/report?format=pdf")
        assert r.status_code == 200, r.text[:300]
    text = " ".join(p.extract_text() for p in pypdf.PdfReader(io.BytesIO(r.content)).pages)
    assert "$a_$" in text and "$^{$" in text


def test_plot_labels_keep_the_ids_literally(monkeypatch):
    """The labels on the plans are the ids themselves, not typeset formulas."""
    from matplotlib.figure import Figure

    from gsgeo.report import plots

    seen: list[str] = []
    real = Figure.savefig

    def capture(fig, *args, **kwargs):
        seen.extend(t.get_text() for t in fig.findobj(lambda a: hasattr(a, "get_text")))
        return real(fig, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", capture)
    assert plots.points_plan(MATH_IDS, [0, 1, 2, 3, 4], [0, 1, 0, 1, 0],
                             [0.01] * 5, [0.01] * 5, "t") is not None
    assert plots.height_residuals(MATH_IDS, [0.01, -0.01, 0.0, 0.02, 0.01],
                                  ["check"] * 5, "t") is not None
    for pid in MATH_IDS:
        assert pid in seen


# WeasyPrint fetches nothing --------------------------------------------------------------------
class _Recorder(http.server.BaseHTTPRequestHandler):
    hits: list[str] = []

    def do_GET(self) -> None:  # noqa: N802 (the stdlib's name)
        type(self).hits.append(self.path)
        body = PNG
        self.send_response(200)
        self.send_header("Content-Type", "image/png")
        self.send_header("Content-Length", str(len(body)))
        self.end_headers()
        self.wfile.write(body)

    def log_message(self, *args: object) -> None:
        pass


PNG = cv2.imencode(".png", np.full((8, 8), 128, np.uint8))[1].tobytes()


@pytest.fixture
def recorder():
    _Recorder.hits = []
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), _Recorder)
    t = threading.Thread(target=server.serve_forever, daemon=True)
    t.start()
    yield server.server_address[1]
    server.shutdown()
    server.server_close()


def pdf_images(pdf: bytes) -> int:
    return sum(len(p.images) for p in pypdf.PdfReader(io.BytesIO(pdf)).pages)


def test_weasyprint_fetches_no_url_and_no_file(recorder, tmp_path):
    local = tmp_path / "local.png"
    local.write_bytes(PNG)
    url = f"http://127.0.0.1:{recorder}"
    html = f"""<!doctype html><html><head>
<link rel="stylesheet" href="{url}/style.css">
<style>@import url("{url}/import.css"); body {{ background: url("{url}/bg.png"); }}
@font-face {{ font-family: x; src: url("{url}/font.woff"); }}</style></head>
<body style="font-family: x">
<img src="{url}/img.png"><img src="file://{local}"><img src="file:///etc/passwd">
<object data="{url}/object"></object><p>text</p></body></html>"""
    pdf = html_to_pdf(html)
    assert pdf.startswith(b"%PDF-")
    assert _Recorder.hits == []
    assert pdf_images(pdf) == 0  # neither the loopback image nor the local file came in


def test_weasyprint_still_embeds_data_uris():
    uri = "data:image/png;base64," + base64.b64encode(PNG).decode()
    pdf = html_to_pdf(f'<!doctype html><html><body><img src="{uri}"></body></html>')
    assert pdf_images(pdf) == 1


# a long report: cheap markup, every point listed; one report per project version ------------
def many_points(data: dict, n: int) -> dict:
    """``data`` with ``n`` measured points spread over 1 km (ids P1..Pn)."""
    row = dict(data["points"][0])
    rng = np.random.default_rng(5)
    pts = []
    for i in range(n):
        pts.append(row | {"point_id": f"P{i + 1}", "easting": row["easting"] + rng.uniform(0, 1000),
                          "northing": row["northing"] + rng.uniform(0, 1000)})
    return data | {"points": pts}


def test_a_long_points_table_is_a_listing_with_every_point(math_dir):
    svc = open_projects(math_dir)
    try:
        data = many_points(report_data(svc, "money"), 250)
    finally:
        svc.store.close()
    html = render(data, "html").decode()
    # the long table is not laid out as 250 x 14 cells (WeasyPrint's cost), the short ones are
    assert html.count("<td") < 300
    assert "Check points: measured minus check." in html
    listed = re.findall(r"^(P\d+) ", html, flags=re.M)
    assert listed == [f"P{i + 1}" for i in range(250)]
    from gsgeo.report.content import fmt_m
    for r in data["points"][::37]:  # the numbers as the table would give them
        line = re.search(rf"^{r['point_id']} .*$", html, flags=re.M).group()
        assert fmt_m(r["easting"]) in line and fmt_m(r["northing"]) in line
    pdf = render(data, "pdf")
    text = " ".join(p.extract_text() for p in pypdf.PdfReader(io.BytesIO(pdf)).pages)
    assert set(re.findall(r"\bP\d+\b", text)) >= {f"P{i + 1}" for i in range(250)}


def listing_lines(pdf: bytes) -> dict[str, tuple[int, float, float]]:
    """Each listed point's line in ``pdf`` (by id): its page and the left end of its baseline
    in PDF points, as pypdf reads them (through form XObjects too)."""
    lines: dict[str, tuple[int, float, float]] = {}
    for i, page in enumerate(pypdf.PdfReader(io.BytesIO(pdf)).pages):
        def seen(text, cm, tm, font, size, i=i):
            if m := re.match(r"(P\d+) ", text.strip()):
                x, y = pypdf.mult(tm, cm)[4:]
                lines.setdefault(m.group(1), (i, x, y))
        page.extract_text(visitor_text=seen)
    return lines


def test_the_pdf_draws_listings_where_weasyprint_would_have_set_them(math_dir):
    """The listing text is drawn outside WeasyPrint's text layout (its cost): every line on
    the page and at the place WeasyPrint's own text would have it (within 1 pt), searchable."""
    from gsgeo.report.content import build_report
    from gsgeo.report.html import render_html

    svc = open_projects(math_dir)
    try:
        data = many_points(report_data(svc, "money"), 250)
    finally:
        svc.store.close()
    drawn = listing_lines(render(data, "pdf"))
    set_by_weasyprint = listing_lines(html_to_pdf(render_html(build_report(data))))
    assert set(drawn) == set(set_by_weasyprint) == {f"P{i + 1}" for i in range(250)}
    for pid, (page, x, y) in set_by_weasyprint.items():
        assert drawn[pid][0] == page, pid
        assert abs(drawn[pid][1] - x) < 1 and abs(drawn[pid][2] - y) < 1, (pid, drawn[pid], x, y)
    pages = {page for page, _, _ in drawn.values()}
    assert len(pages) == 4  # 80 rows a page


def test_a_listing_the_mono_font_cannot_draw_stays_weasyprint_text(math_dir):
    """Right-to-left or combining text, or a character the listing font lacks, needs shaping:
    such a listing is set by WeasyPrint (Pango), not drawn glyph by glyph."""
    from gsgeo.report.listing_pages import drawable

    assert drawable("P1 kerb 530012.688 Ünïcödé Ωμέγα Жук ±σ—\nP2")
    for text in ("P1 شجرة", "P1 עץ", "P1 e\u0301", "P1 樹", "P1\tkerb"):
        assert not drawable(text), text
    svc = open_projects(math_dir)
    try:
        data = many_points(report_data(svc, "money"), 250)
    finally:
        svc.store.close()
    data["points"] = [r | {"code": "شجرة"} for r in data["points"]]
    html = render(data, "html").decode()
    assert html.count("شجرة") == 250
    text = " ".join(p.extract_text() for p in pypdf.PdfReader(io.BytesIO(render(data, "pdf"))).pages)
    assert set(re.findall(r"\bP\d+\b", text)) >= {f"P{i + 1}" for i in range(250)}


def test_one_report_per_project_version_reused_with_an_etag(math_dir, monkeypatch):
    """Two requests at once make one report; a later one (nothing changed) reuses it and
    If-None-Match gets 304; a change to the project makes a new one."""
    import gsgeo.report

    made: list[str] = []
    started, release = threading.Event(), threading.Event()

    def slow_render(data, fmt):
        made.append(fmt)
        started.set()
        assert release.wait(10)
        return f"report {len(made)}".encode()

    monkeypatch.setattr(gsgeo.report, "render", slow_render)
    with TestClient(create_app(ServerConfig(data_dir=math_dir,
                                            allowed_hosts={"testserver"}))) as client:
        url = "/api/projects/money/report?format=html"
        got: list = []
        threads = [threading.Thread(target=lambda: got.append(client.get(url)))
                   for _ in range(2)]
        threads[0].start()
        assert started.wait(10)
        threads[1].start()
        release.set()
        for t in threads:
            t.join(10)
        assert [r.status_code for r in got] == [200, 200] and made == ["html"]
        assert got[0].content == got[1].content == b"report 1"
        tag = got[0].headers["etag"]
        again = client.get(url)
        assert again.content == b"report 1" and again.headers["etag"] == tag and made == ["html"]
        assert client.get(url, headers={"If-None-Match": tag}).status_code == 304
        assert client.patch("/api/projects/money", json={"description": "x"}).status_code == 200
        changed = client.get(url, headers={"If-None-Match": tag})
        assert changed.status_code == 200 and changed.content == b"report 2"
        assert changed.headers["etag"] != tag
