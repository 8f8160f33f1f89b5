"""mypy checks gsgeo/ with the [tool.mypy] settings of pyproject.toml (py.typed ships).

The whole package is checked in one run; the modules listed in CLEAN must report no error.
The list grows until it is the whole package (then the test asserts mypy's exit code 0).
"""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

# Modules (paths below gsgeo/) that type-check cleanly today.
CLEAN = [
    "__init__.py", "cli.py", "errors.py", "limits.py",
    "commands/crs.py", "commands/serve.py", "commands/tiles.py",
    "commands/demo.py",
    "crs/__init__.py", "crs/confidence.py", "crs/discovery.py", "crs/ellipsoid.py", "crs/frames.py",
    "crs/geoid.py", "crs/grid.py", "crs/modelmatrix.py", "crs/resolve.py", "crs/transformers.py",
    "solve/core.py", "solve/intersection.py", "solve/linalg.py", "solve/outliers.py", "solve/simulate.py",
    "solve/stats.py",
    "tiles/georef.py", "tiles/gltf.py", "tiles/gridplacement.py", "tiles/lod.py", "tiles/outdir.py",
    "tiles/placement.py",
    "tiles/reader.py", "tiles/splats.py", "tiles/spz.py", "tiles/swap.py", "tiles/workers.py",
    "demo/build.py", "demo/place.py", "demo/project.py", "demo/scene.py", "demo/splats.py",
    "tiles/__init__.py", "tiles/build.py", "tiles/ply.py", "tiles/source.py", "tiles/tileset.py",
    "demo/__init__.py", "pointschema.py",
    "jsontypes.py", "session.py", "commands/solve.py",
    "measure/__init__.py", "measure/accuracy.py", "measure/checkpoints.py", "measure/features.py",
    "measure/point.py", "measure/rays.py", "measure/schema.py",
    "service/__init__.py", "service/checkpoints.py", "service/exporting.py", "service/measuring.py",
    "service/points.py", "service/projects.py", "service/validate.py",
    "store/__init__.py", "store/base.py", "store/migrations.py", "store/records.py", "store/sqlite.py",
    "server/__init__.py", "server/api.py", "server/app.py", "server/faults.py", "server/files.py",
    "server/guard.py", "server/hosts.py", "server/intersect_pool.py", "server/models.py",
    "server/routing.py", "server/scenes.py",
    "export/__init__.py", "export/arrow.py", "export/atomic.py", "export/csvfile.py", "export/geojson.py",
    "export/gpkg.py", "export/tables.py", "export/wkb.py", "export/writer.py",
]

ERROR = re.compile(r"^gsgeo/(?P<path>[^:]+):(?P<line>\d+): error: (?P<message>.*)$", re.M)


@pytest.fixture(scope="module")
def mypy_output(tmp_path_factory: pytest.TempPathFactory) -> str:
    pytest.importorskip("mypy")
    cache = tmp_path_factory.mktemp("mypy-cache")
    run = subprocess.run(
        [sys.executable, "-m", "mypy", "--cache-dir", str(cache)],
        cwd=ROOT, capture_output=True, text=True, timeout=300,
    )
    assert "error: " in run.stdout or run.returncode == 0, run.stdout + run.stderr
    return run.stdout


def test_mypy_runs_with_the_project_config(mypy_output: str) -> None:
    # A broken config or plugin shows as a line without a file position.
    assert "Success" in mypy_output or re.search(r"Found \d+ errors? in \d+ files?", mypy_output), mypy_output


@pytest.mark.parametrize("path", CLEAN)
def test_module_type_checks(mypy_output: str, path: str) -> None:
    assert (ROOT / "gsgeo" / path).is_file(), path
    errors = [m.group(0) for m in ERROR.finditer(mypy_output) if m.group("path") == path]
    assert not errors, "\n".join(errors)
