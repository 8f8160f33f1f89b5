"""`gsgeo report PROJECT -o REPORT.pdf|REPORT.html`: a project's survey report.

Reads the project from the store of ``--data``, or the PostgreSQL one of ``--store URL`` (as
`gsgeo serve` does), gathers it through gsgeo.service.reporting and renders it with
gsgeo.report. The format comes from the output suffix; the file is written atomically, so a
failure leaves an earlier report intact.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from gsgeo.commands.argtypes import text as text_arg
from gsgeo.commands.storearg import add_store_argument, require_sqlite_store, store_url


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "report",
        help="write a project's survey report (PDF or HTML)",
        description="Write one self-contained survey report of a project: reference frames "
                    "and datum operation, the scene's georeference with its control "
                    "residuals, accuracy against check points (ASPRS Positional Accuracy "
                    "Standards, Edition 2, 2023) and the measured points with their sigmas.",
    )
    p.add_argument("project", type=text_arg, help="project id (as listed by GET /api/projects)")
    p.add_argument("-o", "--output", required=True, metavar="REPORT.pdf|REPORT.html",
                   help="output file; the format comes from the suffix (.pdf, .html, .htm)")
    p.add_argument("--data", default="gsgeo-data", metavar="DIR",
                   help="data directory with the project store (default: ./gsgeo-data, as "
                        "for gsgeo serve)")
    add_store_argument(p)
    p.set_defaults(run=run)


def run(args: argparse.Namespace) -> int:
    data_dir = Path(args.data)
    url = store_url(args)
    if url is None:
        require_sqlite_store(data_dir)
    from gsgeo.service import open_projects
    from gsgeo.service.reporting import write_report

    t0 = time.perf_counter()
    projects = open_projects(data_dir, url=url)
    try:
        data = write_report(projects, args.project, args.output)
    finally:
        projects.store.close()
    print(f"gsgeo report: wrote {args.output} ({len(data['points'])} points) in "
          f"{time.perf_counter() - t0:.1f} s", file=sys.stderr)
    return 0
