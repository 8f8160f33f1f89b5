"""The survey report (`gsgeo report`, GET /api/projects/{pid}/report): ASPRS Edition 2 figures
against a hand computation, a self-contained HTML with its tables and figures, a real PDF read
back by pypdf, and clear refusals of bad input."""

from __future__ import annotations

import base64
import io
import math
import re
import warnings
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pypdf
import pyproj
import pytest
from servertools import ecef_of, rays_at

with warnings.catch_warnings():
    warnings.simplefilter("ignore")
    from fastapi.testclient import TestClient

from gsgeo.cli import main
from gsgeo.measure.accuracy import accuracy_report, asprs_accuracy
from gsgeo.report import render
from gsgeo.report.content import fmt_m, fmt_mm
from gsgeo.server.app import ServerConfig, create_app
from gsgeo.service import open_projects
from gsgeo.service.checkpoints import CheckPointRow
from gsgeo.service.reporting import frame_precision, report_data

CRS = "EPSG:32630"
TO_UTM = pyproj.Transformer.from_crs("EPSG:4979", CRS, always_xy=True)
NAME = "Thames <Wharf> & Co"
#: (id, lon, lat, h) of the measured targets; the check points are these plus OFFSETS.
TARGETS = [(f"C{i}", -0.1276 + 0.0004 * (i % 4), 51.5072 + 0.0003 * (i // 4), 50.0 + 0.5 * i)
           for i in range(8)]
#: check point minus truth (metres, E N H); None: the check point has no height.
OFFSETS = [(0.012, -0.008, 0.020), (-0.015, 0.004, -0.011), (0.006, 0.019, 0.004),
           (-0.021, -0.013, 0.016), (0.009, 0.002, None), (0.003, -0.017, -0.025),
           (-0.007, 0.011, 0.008), (0.018, 0.006, -0.003)]
SIGMA_H = [0.005, 0.005, 0.004, None, 0.006, 0.005, 0.005, 0.004]  # stated survey sigmas (m)
SIGMA_V = [0.008, None, 0.010, 0.009, 0.008, 0.007, 0.010, 0.009]

GEOREF = {  # a GeorefResult shaped as the interface contract states it
    "kind": "similarity", "scale": 1.0002, "scale_sigma": 1e-5, "scale_ppm": 200.0,
    "rotation": [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
    "rotation_sigma_deg": [1e-4, 2e-4, 3e-4],
    "translation": [1.5, -2.5, 0.75], "translation_sigma": [0.004, 0.005, 0.006],
    "matrix": [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 1.5, -2.5, 0.75, 1],
    "sigma0": 0.9, "dof": 11, "global_test_p": 0.4,
    "control": [{"id": f"GCP{k}", "used": k != 4, "excluded": False, "outlier": k == 4,
                 "dE": 0.004 * k, "dN": -0.003 * k, "dH": 0.002, "w": 1.2 * k, "p": 0.7 / k,
                 "sigma_h": 0.01, "sigma_v": 0.02, "easting": 699000.0 + 30 * k,
                 "northing": 5710000.0 + 20 * (k % 3), "height": 50.0} for k in range(1, 6)],
    "check": [{"id": "CHK1", "dE": 0.01, "dN": 0.0, "dH": -0.01, "easting": 699050.0,
               "northing": 5710030.0, "height": 50.0}],
    "rmse_control": {"e": 0.011, "n": 0.009, "h": 0.002, "horizontal": 0.0142, "3d": 0.0144,
                     "count": 5},
    "rmse_check": {"e": 0.01, "n": 0.0, "h": 0.01, "horizontal": 0.01, "3d": 0.0141,
                   "count": 1},
    "outliers": ["GCP4"],
    "without_outliers": {"scale": 1.00019, "rotation": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                         "translation": [1.5, -2.5, 0.75],
                         "rmse_control": {"horizontal": 0.006, "3d": 0.007},
                         "rmse_check": {"3d": 0.012}, "excluded": ["GCP4"]},
    "frame_covariance": {"centre_ecef": [1, 2, 3], "covariance": np.eye(7).tolist(),
                         "parameters": ["tx", "ty", "tz", "rx", "ry", "rz", "ds"]},
    "grid_crs": CRS, "warnings": ["GCP4: residual 25 mm is significant"],
    "applied": True, "scene": None,
}
STATUS = {"scene": "site", "version": 2, "georeferenced": True,
          "history": [{"version": 0, "kind": "tiles", "root_transform": [0] * 16, "at": "t0",
                       "parent": None, "summary": None},
                      {"version": 2, "kind": "control", "root_transform": [0] * 16, "at": "t2",
                       "parent": 0, "summary": GEOREF}],
          "control": [], "current": GEOREF}


@pytest.fixture
def data_dir(tmp_path):
    """A data directory whose store holds project 'wharf': 8 measured targets, 8 check
    points near them (stated sigmas on most) and 2 control points."""
    svc = open_projects(tmp_path)
    try:
        p = svc.create_project(name=NAME, id="wharf", crs=CRS, description="<script>x</script>")
        for pid, lon, lat, h in TARGETS:
            svc.add_point(p.id, {"id": pid, "code": "target",
                                 "rays": rays_at(ecef_of(lon, lat, h), 4, ifov=0.0005)})
        rows = []
        for (pid, lon, lat, h), off, sh, sv in zip(TARGETS, OFFSETS, SIGMA_H, SIGMA_V,
                                                   strict=True):
            e, n, hh = TO_UTM.transform(lon, lat, h)
            rows.append(CheckPointRow(pid, e + off[0], n + off[1],
                                      None if off[2] is None else hh + off[2], sh, sv))
        svc.add_check_points(p.id, rows, CRS)
        svc.add_check_points(p.id, [CheckPointRow("GCP1", 699000.0, 5710000.0, 50.0, 0.01, 0.02),
                                    CheckPointRow("GCP2", 699030.0, 5710020.0, 50.0)],
                             CRS, role="control")
    finally:
        svc.store.close()
    return tmp_path


@pytest.fixture
def svc(data_dir, monkeypatch):
    s = open_projects(data_dir)
    yield s
    s.store.close()


def expected_differences(svc) -> tuple[list[str], np.ndarray]:
    """measured minus check (E, N, H), computed here from the records and the check points'
    own numbers (all in the project's grid, heights as given)."""
    recs = {q.id: q.record for q in svc.list_points("wharf")}
    cps = {c.id: c for c in svc.list_check_points("wharf") if c.role == "check"}
    ids = sorted(cps)
    d = np.array([[recs[i]["easting"] - cps[i].x, recs[i]["northing"] - cps[i].y,
                   math.nan if cps[i].z is None else recs[i]["height"] - cps[i].z]
                  for i in ids])
    return ids, d


def hand_asprs(d: np.ndarray) -> dict[str, float]:
    """ASPRS Edition 2 by hand: the survey sigmas add in quadrature (sqrt(2) per axis
    horizontally), over the points that state them."""
    v = d[np.isfinite(d[:, 2]), 2]
    sh = np.array([s for s in SIGMA_H if s is not None])
    sv = np.array([s for s, off in zip(SIGMA_V, OFFSETS, strict=True)
                   if s is not None and off[2] is not None])
    rmse_e, rmse_n = np.sqrt(np.mean(d[:, 0] ** 2)), np.sqrt(np.mean(d[:, 1] ** 2))
    h1 = np.sqrt(rmse_e**2 + rmse_n**2)
    h2 = np.sqrt(np.mean(2 * sh**2))
    v1, v2 = np.sqrt(np.mean(v**2)), np.sqrt(np.mean(sv**2))
    rmse_h, rmse_v = np.hypot(h1, h2), np.hypot(v1, v2)
    return {"RMSE_E": rmse_e, "RMSE_N": rmse_n, "RMSE_H1": h1, "RMSE_H2": h2, "RMSE_H": rmse_h,
            "RMSE_V1": v1, "RMSE_V2": v2, "RMSE_V": rmse_v,
            "RMSE_3D": np.sqrt(rmse_h**2 + rmse_v**2),
            "ME_E": d[:, 0].mean(), "ME_N": d[:, 1].mean(), "ME_V": v.mean(),
            "SD_E": d[:, 0].std(ddof=1), "SD_N": d[:, 1].std(ddof=1), "SD_V": v.std(ddof=1),
            "ACC_H95": 1.7308 * rmse_h, "ACC_V95": 1.96 * rmse_v}


# the statistics -------------------------------------------------------------------------------
def test_asprs_figures_equal_a_hand_computation(svc, monkeypatch):
    monkeypatch.setattr(svc, "georeference_status", lambda pid: STATUS, raising=False)
    data = report_data(svc, "wharf")
    ids, d = expected_differences(svc)
    want = hand_asprs(d)
    stats = data["accuracy"]["asprs"]["statistics"]
    assert stats["n_horizontal"] == 8 and stats["n_vertical"] == 7
    assert stats["n_survey_horizontal"] == 7 and stats["n_survey_vertical"] == 6
    for key, value in want.items():
        assert stats[key] == pytest.approx(value, rel=1e-9, abs=1e-12), key
    # the differences are the offsets back (noise-free rays): the test data are what they say
    assert np.allclose(-d[:, 0], [o[0] for o in OFFSETS], atol=1e-4)
    remarks = " ".join(data["accuracy"]["asprs"]["remarks"])
    assert "at least 30 checkpoints" in remarks and "8 checkpoints" in remarks
    assert "not stated for 1 of 8" in remarks


def test_survey_accuracy_enters_only_when_stated():
    d = np.array([[0.01, -0.02, 0.03], [-0.01, 0.0, 0.01], [0.02, 0.01, np.nan]])
    bare = asprs_accuracy(d)["statistics"]
    assert bare["RMSE_H"] == bare["RMSE_H1"] and bare["RMSE_H2"] is None
    assert bare["RMSE_V"] == bare["RMSE_V1"] == pytest.approx(math.sqrt((0.03**2 + 0.01**2) / 2))
    with_survey = asprs_accuracy(d, [0.01, 0.01, 0.01], [0.02, 0.02, 0.02])["statistics"]
    assert with_survey["RMSE_H"] == pytest.approx(math.hypot(bare["RMSE_H1"], 0.01 * math.sqrt(2)))
    assert with_survey["RMSE_V"] == pytest.approx(math.hypot(bare["RMSE_V1"], 0.02))
    # the existing report keeps its shape and numbers
    old = accuracy_report(["a", "b", "c"], d, np.zeros((3, 3)))["statistics"]
    assert old["RMSE_H"] == pytest.approx(bare["RMSE_H1"])


def test_an_elongated_horizontal_error_is_remarked():
    d = np.array([[0.05, 0.001, 0.0], [-0.05, -0.001, 0.0]])
    remarks = " ".join(asprs_accuracy(d)["remarks"])
    assert "only indicative" in remarks


def test_frame_precision_reads_the_covariance_in_east_north_up():
    """A frame covariance stated in ECEF comes back as the east/north/up sigmas it was made of."""
    lon, lat, h = 10.0, 50.0, 200.0
    centre = pyproj.Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(
        lon, lat, h)
    lam, phi = np.radians(lon), np.radians(lat)
    r = np.array([[-np.sin(lam), np.cos(lam), 0.0],
                  [-np.sin(phi) * np.cos(lam), -np.sin(phi) * np.sin(lam), np.cos(phi)],
                  [np.cos(phi) * np.cos(lam), np.cos(phi) * np.sin(lam), np.sin(phi)]])
    c = np.zeros((7, 7))
    c[:3, :3] = r.T @ np.diag([0.01, 0.02, 0.03]) ** 2 @ r
    c[3:6, 3:6] = r.T @ np.diag(np.radians([1.0, 2.0, 3.0]) / 3600) ** 2 @ r
    c[6, 6] = 5e-6**2
    got = frame_precision({"centre_ecef": list(centre), "covariance": c.tolist()})
    assert got["shift_enu_m"] == pytest.approx([0.01, 0.02, 0.03], rel=1e-9)
    assert got["rotation_enu_arcsec"] == pytest.approx([1.0, 2.0, 3.0], rel=1e-9)
    assert got["scale_ppm"] == pytest.approx(5.0)
    assert (got["centre"]["lon"], got["centre"]["lat"]) == pytest.approx((lon, lat))
    assert frame_precision(None) is None and frame_precision({"covariance": [[1]]}) is None


# the documents ----------------------------------------------------------------------------------
def decoded_images(html: str) -> list[bytes]:
    return [base64.b64decode(m) for m in
            re.findall(r'src="data:image/png;base64,([A-Za-z0-9+/=]+)"', html)]


def test_html_is_self_contained_with_tables_figures_and_escaped_text(svc, monkeypatch):
    monkeypatch.setattr(svc, "georeference_status", lambda pid: STATUS, raising=False)
    data = report_data(svc, "wharf")
    html = render(data, "html").decode("utf-8")
    images = decoded_images(html)
    # control residual plan, check residual plan, dH bars, points plan
    assert len(images) == 4 and all(img.startswith(b"\x89PNG\r\n\x1a\n") for img in images)
    assert html.count("<table") >= 10
    for needed in ("Control residuals", "Measured points (8)", "RMSE_3D", "OUTLIER",
                   "at the control centroid",
                   "1.7308", "1.96", "GCP4", "Sign-off", "EPSG:32630"):
        assert needed in html, needed
    assert re.search(r'<tr class="outlier"><td>GCP4</td>', html)
    assert "Thames &lt;Wharf&gt; &amp; Co" in html and "<script>" not in html
    assert not re.search(r'(src|href)="(?!data:)', html) and "<link" not in html
    stats = data["accuracy"]["asprs"]["statistics"]
    assert fmt_mm(stats["RMSE_H"]) in html and fmt_mm(stats["RMSE_3D"]) in html


def test_reports_drawn_at_once_in_threads_equal_one_drawn_alone(svc, monkeypatch):
    """A server draws reports in parallel threads: each comes out as if drawn alone (the
    figures' settings are matplotlib's global state while a figure is drawn)."""
    monkeypatch.setattr(svc, "georeference_status", lambda pid: STATUS, raising=False)
    data = report_data(svc, "wharf", generated_at="2026-01-01T00:00:00Z")
    alone = render(data, "html")
    with ThreadPoolExecutor(3) as pool:
        together = list(pool.map(lambda _: render(data, "html"), range(3)))
    assert all(t == alone for t in together)


def test_pdf_is_read_back_with_project_name_and_rmse(svc, monkeypatch):
    monkeypatch.setattr(svc, "georeference_status", lambda pid: STATUS, raising=False)
    data = report_data(svc, "wharf")
    pdf = render(data, "pdf")
    assert pdf.startswith(b"%PDF-")
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    text = " ".join(p.extract_text() for p in reader.pages)
    flat = re.sub(r"\s+", " ", text)
    assert NAME in flat
    stats = data["accuracy"]["asprs"]["statistics"]
    for key in ("RMSE_H", "RMSE_V", "RMSE_3D", "ACC_H95"):
        assert fmt_mm(stats[key]) in flat, key
    assert "GCP4" in flat and "page 1 of" in flat


def test_a_project_without_grid_georeference_or_check_points_still_reports(tmp_path):
    svc = open_projects(tmp_path)
    try:
        p = svc.create_project(name="Local", id="local")
        svc.add_point(p.id, {"id": "A", "rays": rays_at(ecef_of(0.0, 0.0, 0.0), 3)})
        data = report_data(svc, p.id)
        html = render(data, "html").decode()
    finally:
        svc.store.close()
    assert data["accuracy"]["asprs"] is None and "no check points" in data["accuracy"]["note"]
    assert "not tested against check points" in html and "Measured points (1)" in html
    (row,) = data["ecef_points"]
    assert row["point_id"] == "A" and data["points"] == [] and data["failed_points"] == []
    assert np.allclose([row["x"], row["y"], row["z"]], ecef_of(0.0, 0.0, 0.0), atol=1e-6)
    assert fmt_m(row["x"]) in html


def test_an_unapplied_fit_is_reported_as_proposed(svc):
    fit = GEOREF | {"applied": False}
    data = report_data(svc, "wharf", georeference=fit)
    html = render(data, "html").decode()
    assert "no (a proposed fit)" in html and "Control residuals" in html


def test_a_scale_only_fit_shows_its_distances_and_no_rotation(svc):
    fit = {"kind": "scale", "scale": 2.5, "scale_sigma": 0.0005, "scale_ppm": 1.5e6,
           "rotation": np.eye(3).tolist(), "translation": [1.0, 2.0, 3.0], "sigma0": 0.8,
           "dof": 1, "distances": [{"from": "A", "to": "B", "distance": 12.3, "measured": 4.92,
                                    "sigma": 0.002, "scaled": 12.3012, "residual": 0.0012}],
           "control": [], "check": [], "rmse_control": None, "rmse_check": None,
           "outliers": [], "without_outliers": None, "grid_crs": None, "warnings": [],
           "applied": True}
    html = render(report_data(svc, "wharf", georeference=fit), "html").decode()
    assert "Scale only" in html and "Known distances" in html and "+1.2" in html
    assert "rotation matrix" not in html and "translation X" not in html


# the command line -------------------------------------------------------------------------------
def test_cli_writes_the_pdf_and_html(data_dir, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    assert main(["report", "wharf", "--data", str(data_dir), "-o", str(out / "r.pdf")]) == 0
    assert (out / "r.pdf").read_bytes().startswith(b"%PDF-")
    assert main(["report", "wharf", "--data", str(data_dir), "-o", str(out / "r.HTML")]) == 0
    assert "Thames &lt;Wharf&gt;" in (out / "r.HTML").read_text()


@pytest.mark.parametrize("case", ["unknown project", "no directory", "a directory",
                                  "unknown suffix", "no store"])
def test_cli_refuses_bad_input_with_exit_2(case, data_dir, tmp_path, capsys):
    keep = tmp_path / "keep.pdf"
    keep.write_bytes(b"earlier report")
    (tmp_path / "dir.pdf").mkdir()
    args = {"unknown project": ["nope", "-o", str(keep)],
            "no directory": ["wharf", "-o", str(tmp_path / "missing" / "r.pdf")],
            "a directory": ["wharf", "-o", str(tmp_path / "dir.pdf")],
            "unknown suffix": ["wharf", "-o", str(tmp_path / "r.docx")],
            "no store": ["wharf", "-o", str(keep), "--data", str(tmp_path / "empty")]}[case]
    if "--data" not in args:
        args += ["--data", str(data_dir)]
    assert main(["report", *args]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("gsgeo report: error:") and "\n" not in err and "Traceback" not in err
    assert {"unknown project": "project 'nope' does not exist",
            "no directory": "does not exist", "a directory": "is a directory",
            "unknown suffix": "unknown report format '.docx'",
            "no store": "no project store"}[case] in err
    assert keep.read_bytes() == b"earlier report"
    assert not (tmp_path / "empty").exists()


# the API ----------------------------------------------------------------------------------------
def test_api_serves_both_formats_and_404s_an_unknown_project(data_dir):
    with TestClient(create_app(ServerConfig(data_dir=data_dir, allowed_hosts={"testserver"}))) as client:
        r = client.get("/api/projects/wharf/report?format=html")
        assert r.status_code == 200 and r.headers["content-type"].startswith("text/html")
        assert "default-src 'none'" in r.headers["content-security-policy"]
        assert "RMSE_3D" in r.text and len(decoded_images(r.text)) == 3
        r = client.get("/api/projects/wharf/report")
        assert r.status_code == 200 and r.headers["content-type"] == "application/pdf"
        assert r.content.startswith(b"%PDF-") and "wharf-report.pdf" in \
            r.headers["content-disposition"]
        r = client.get("/api/projects/nope/report")
        assert r.status_code == 404 and "nope" in r.json()["message"]
        r = client.get("/api/projects/wharf/report?format=docx")
        assert r.status_code == 422 and r.json()["field"] == "format"


def test_lines_and_polygons_are_reported_with_grid_measures(svc, monkeypatch):
    """A line and a polygon of measured targets: their lengths, area and perimeter (against a
    hand computation from the points' grid E, N, H) are in the PDF, said to be grid values."""
    monkeypatch.setattr(svc, "georeference_status", lambda pid: STATUS, raising=False)
    svc.add_feature("wharf", "line", {"id": "L1", "code": "kerb", "points": ["C0", "C1", "C2"]})
    svc.add_feature("wharf", "polygon", {"id": "A1", "points": ["C0", "C1", "C5", "C4"]})
    data = report_data(svc, "wharf")
    rec = {q.id: q.record for q in svc.list_points("wharf")}
    enh = {k: np.array([rec[k]["easting"], rec[k]["northing"], rec[k]["height"]]) for k in rec}
    line = [enh[k] for k in ("C0", "C1", "C2")]
    l2 = sum(np.hypot(*(b - a)[:2]) for a, b in zip(line, line[1:], strict=False))
    l3 = sum(np.linalg.norm(b - a) for a, b in zip(line, line[1:], strict=False))
    ring = np.array([enh[k][:2] for k in ("C0", "C1", "C5", "C4")])
    x, y = (ring - ring.mean(axis=0)).T  # centred: the shoelace on 10^6 m coordinates loses mm
    area = 0.5 * abs(np.dot(x, np.roll(y, -1)) - np.dot(y, np.roll(x, -1)))
    perimeter = np.sum(np.hypot(*(np.roll(ring, -1, axis=0) - ring).T))
    (got_line,) = data["lines"]
    (got_poly,) = data["polygons"]
    assert got_line["length_2d"] == pytest.approx(l2, abs=1e-6)
    assert got_line["length_3d"] == pytest.approx(l3, abs=1e-6)
    assert got_poly["area_2d"] == pytest.approx(area, rel=1e-9)
    assert got_poly["perimeter_2d"] == pytest.approx(perimeter, abs=1e-6)
    flat = re.sub(r"\s+", " ", " ".join(
        p.extract_text() for p in pypdf.PdfReader(io.BytesIO(render(data, "pdf"))).pages))
    assert "Lines and polygons (1 / 1)" in flat
    assert "L1" in flat and "kerb" in flat and "C0, C1, C2" in flat
    assert fmt_m(l2) in flat and fmt_m(l3) in flat and fmt_m(perimeter) in flat
    assert "length 2-D, grid" in flat and "length 2-D, ground" in flat
    # ground = grid / (k R / (R + h)) at the mean position, by hand from PROJ's factors
    llh = np.array([[rec[k]["lon"], rec[k]["lat"], rec[k]["h_wgs84"]] for k in ("C0", "C1", "C2")])
    lon, lat, h = llh.mean(axis=0)
    k = pyproj.Proj(CRS).get_factors(lon, lat).meridional_scale
    a, e2 = 6378137.0, 0.00669437999014
    m_rad = a * (1 - e2) / (1 - e2 * math.sin(math.radians(lat)) ** 2) ** 1.5
    n_rad = a / math.sqrt(1 - e2 * math.sin(math.radians(lat)) ** 2)
    r = math.sqrt(m_rad * n_rad)
    csf = k * r / (r + h)
    assert got_line["combined_scale_factor"] == pytest.approx(csf, abs=1e-9)
    assert got_line["length_2d_ground"] == pytest.approx(l2 / csf, abs=1e-6)
    assert fmt_m(l2 / csf) in flat and f"{csf:.8f}" in flat
    assert got_poly["area_2d_ground"] == pytest.approx(
        area / got_poly["combined_scale_factor"] ** 2, rel=1e-9)
    assert abs(l2 / csf - l2) > 1e-4  # UTM 30N at 0.13 W: k = 0.99987; the two differ


def test_buildings_are_reported_and_long_audit_values_wrap_inside_the_page(tmp_path):
    """The gable house of building_helpers captured as B1: its row in the report (roof type,
    volume within 3σ of the truth, 720 m³, with its σ); an audit entry with a long description
    (a word of 150 characters in its JSON) wraps: WeasyPrint lays every box out inside the
    page."""
    from building_helpers import CRS as HOUSE_CRS
    from building_helpers import GROUND, ROOFS, VOLUME, house_points

    svc = open_projects(tmp_path)
    try:
        svc.create_project(name="House", id="house", crs=HOUSE_CRS)
        for q in house_points():
            svc.add_point("house", q | {"description": "a long description " + "x" * 150
                                        if q["id"] == "E1" else ""})
        svc.add_building("house", {"id": "B1", "roofs": ROOFS, "ground": GROUND})
        data = report_data(svc, "house")
    finally:
        svc.store.close()
    (b,) = data["buildings"]
    ms = b["measures"]
    assert ms["roof_type"] == "gable"
    assert abs(ms["volume"] - VOLUME) < 3 * ms["sigma_volume"]
    pdf = render(data, "pdf")
    reader = pypdf.PdfReader(io.BytesIO(pdf))
    flat = re.sub(r"\s+", " ", " ".join(p.extract_text() for p in reader.pages))
    assert "Buildings (1)" in flat and "gable" in flat
    assert f"{ms['volume']:.6g} ± {ms['sigma_volume']:.3g}" in flat
    # laid out by WeasyPrint (the PDF's engine): no box reaches past its page's right edge
    import weasyprint

    from gsgeo.report.content import build_report
    from gsgeo.report.html import render_html

    doc = weasyprint.HTML(string=render_html(build_report(data))).render()
    for page in doc.pages:
        box = page._page_box
        right = box.margin_width()
        over = [(type(b).__name__, round(b.position_x + b.margin_width(), 1))
                for b in box.descendants() if b.position_x + b.margin_width() > right + 0.5]
        assert not over, over[:5]
