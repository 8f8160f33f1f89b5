"""gsgeo runs with its declared run-time dependencies only: geopandas is a test tool (the `test`
extra), never imported by the package; matplotlib, jinja2 and WeasyPrint draw and lay out the
survey report and are run-time dependencies."""

from __future__ import annotations

import re
import subprocess
import sys
import textwrap
import tomllib

from conftest import REPO

BLOCKED = ("geopandas",)

SCRIPT = textwrap.dedent("""
    import importlib, pkgutil, sys, tempfile
    from pathlib import Path

    class Block:
        def find_spec(self, name, path=None, target=None):
            if name.split(".")[0] in {blocked!r}:
                raise ImportError(f"{{name}} is blocked: not a run-time dependency")
            return None

    sys.meta_path.insert(0, Block())

    import gsgeo
    for mod in pkgutil.walk_packages(gsgeo.__path__, "gsgeo."):
        if not mod.name.endswith("__main__"):
            importlib.import_module(mod.name)

    from gsgeo.cli import main
    out = Path(tempfile.mkdtemp()) / "out.gpkg"
    assert main(["solve", {session!r}, "--crs", "EPSG:27700", "-o", str(out)]) == 0
    from gsgeo.service.checkpoints import read_check_points
    rows = read_check_points(out.read_bytes(), "gpkg")
    print(len(rows), "check points read back")
""")


def test_the_package_does_not_need_geopandas():
    script = SCRIPT.format(blocked=set(BLOCKED), session=str(REPO / "examples" / "session.json"))
    run = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "check points read back" in run.stdout


def test_the_report_libraries_are_run_time_dependencies():
    doc = tomllib.loads((REPO / "pyproject.toml").read_text(encoding="utf-8"))
    names = {re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0].lower()
             for d in doc["project"]["dependencies"]}
    extra = {re.split(r"[<>=!~;\[ ]", d, maxsplit=1)[0].lower()
             for d in doc["project"]["optional-dependencies"]["test"]}
    assert {"matplotlib", "jinja2", "weasyprint"} <= names
    assert "matplotlib" not in extra and "geopandas" in extra
