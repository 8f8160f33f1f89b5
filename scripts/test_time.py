"""Where the suite's time goes: pytest's ``--durations=0`` report grouped by cause.

    .venv/bin/python -m pytest --durations=0 > durations.txt
    python scripts/test_time.py durations.txt

Prints a Markdown table (cause, seconds of setup + call + teardown summed over the tests,
share, tests) for tests/README.md. The causes are assigned by test file (the first pattern
that matches): the time of a shared fixture lands on the first test that builds it. With
pytest-xdist the sums are worker-seconds: they add up to about twice the wall time.
"""

from __future__ import annotations

import re
import sys
from collections import defaultdict

#: (cause, regular expression on the test file's path), first match wins.
CAUSES = [
    ("browser frames (software renderer): the demo's 341 816 splats",
     r"e2e/test_(autoaim|building_tool|guide)\.py"),
    ("browser frames (software renderer): box, real and static scenes", r"e2e/|test_qgis_plugin\.py"),
    ("demo builds (341 816 splats sampled, tiled)", r"test_demo_"),
    ("PostgreSQL cluster and its API twins",
     r"postgres|test_store\.py|test_accounts\.py|test_audit|test_ray_provenance\.py|test_postgis"),
    ("Hypothesis and schemathesis fuzzing",
     r"fuzz|test_buildings_spec\.py|test_buildings_topology\.py|test_server_text\.py"),
    ("Monte-Carlo calibration", r"calibration|test_solve_intersect\.py|test_crs_grid\.py"),
    ("real 3DGS scene (../shared/data) decodes", r"test_tiles_real\.py"),
    ("type check, lint, layering (mypy, ruff, imports)",
     r"test_types\.py|test_lint\.py|test_layers\.py|test_crs_layout\.py|test_dependencies\.py"),
    ("servers in subprocesses (gsgeo serve, kill -9)",
     r"test_server_live\.py|test_concurrency\.py|test_serve_|test_server_files\.py|test_scene_hosts\.py"),
    ("survey report (matplotlib, WeasyPrint)", r"test_report"),
    ("OGC API (GDAL, OWSLib readers)", r"test_ogc"),
    ("command line in subprocesses", r"test_cli_|_cli\.py|test_georef_api\.py"),
    ("Node.js (web modules)", r"test_web_"),
    ("everything else (API, exports, maths)", r"."),
]

LINE = re.compile(r"^\s*([\d.]+)s\s+(setup|call|teardown)\s+(\S+?)::")


def main(path: str) -> None:
    seconds: dict[str, float] = defaultdict(float)
    tests: dict[str, set[str]] = defaultdict(set)
    with open(path, encoding="utf-8") as f:
        for line in f:
            m = LINE.match(line)
            if not m:
                continue
            s, _, file = float(m.group(1)), m.group(2), m.group(3)
            cause = next(c for c, pat in CAUSES if re.search(pat, file))
            seconds[cause] += s
            tests[cause].add(line.split()[2])
    total = sum(seconds.values())
    print("| cause | s | share | tests |")
    print("|---|---:|---:|---:|")
    for cause, s in sorted(seconds.items(), key=lambda kv: -kv[1]):
        print(f"| {cause} | {s:.0f} | {100 * s / total:.0f} % | {len(tests[cause])} |")
    print(f"| **total** | **{total:.0f}** | | **{sum(len(t) for t in tests.values())}** |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(sys.argv[1])
