"""gsgeo runs with its declared run-time dependencies only: geopandas and matplotlib are test
and benchmark tools (the `test` extra), never imported by the package."""

from __future__ import annotations

import subprocess
import sys
import textwrap

from conftest import REPO

BLOCKED = ("geopandas", "matplotlib")

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


def test_the_package_needs_neither_geopandas_nor_matplotlib():
    script = SCRIPT.format(blocked=set(BLOCKED), session=str(REPO / "examples" / "session.json"))
    run = subprocess.run([sys.executable, "-c", script], cwd=REPO, capture_output=True, text=True,
                         timeout=120)
    assert run.returncode == 0, run.stderr[-3000:]
    assert "check points read back" in run.stdout
