"""GET /api/projects/{pid}/report: the project's survey report as PDF or HTML.

The same document as `gsgeo report` (gsgeo.service.reporting gathers it, gsgeo.report
renders it). The HTML answer carries a Content-Security-Policy that allows nothing but its
own inline style and data-URI images: the document needs nothing else, and project text in
it is escaped.

A report costs seconds of CPU and a few hundred megabytes while it is laid out, so:
- reports run in the server's pool of report jobs (gsgeo.server.jobs: one at a time, a few
  queued, 503 with Retry-After beyond);
- a report is made once per project version (``report_version``: the store's revision and the
  scene's tileset): a request for one being made waits for it, and one made already is
  answered from memory (the last REPORTS_KEPT), with an ETag of that version, so
  If-None-Match gets 304;
- after each report the memory it took is given back (``jobs.release_memory``).
"""

from __future__ import annotations

import asyncio
import hashlib
from collections import OrderedDict
from collections.abc import Awaitable, Callable
from typing import Annotated, Literal

from fastapi import APIRouter, Header, Query, Request, Response
from starlette.concurrency import run_in_threadpool

from gsgeo.server.api import PID, ErrorBody, svc
from gsgeo.server.jobs import JobPool, release_memory
from gsgeo.server.textbody import TextCheckedRoute
from gsgeo.service import Projects

router = APIRouter(prefix="/api", route_class=TextCheckedRoute, responses={
    404: {"model": ErrorBody, "description": "no such project"},
    422: {"model": ErrorBody, "description": "malformed request; message names the field"},
    503: {"model": ErrorBody, "description": "the project store is busy or unavailable, or "
                                             "too many reports are being made (Retry-After)"},
})

HTML_CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"
#: Reports kept in memory for reuse, the newest (a report of 5 000 points: ~3 MB of PDF).
REPORTS_KEPT = 4


class Reports:
    """Reports being made and made (per app): one job per (project, format, version)."""

    def __init__(self) -> None:
        self.making: dict[tuple[str, str, str], asyncio.Future[bytes]] = {}
        self.made: OrderedDict[tuple[str, str, str], bytes] = OrderedDict()

    async def get(self, key: tuple[str, str, str] | None,
                  make: Callable[[], Awaitable[bytes]]) -> bytes:
        """The report of ``key``: kept, being made (waited for), or made now by ``make``.
        ``key`` None: made now, shared with nobody."""
        if key is None:
            return await make()
        if key in self.made:
            self.made.move_to_end(key)
            return self.made[key]
        job = self.making.get(key)
        if job is None:
            job = asyncio.ensure_future(make())
            self.making[key] = job
            job.add_done_callback(lambda f: self._done(key, f))
        # shielded: a client that goes away does not cancel the report the others wait for
        return await asyncio.shield(job)

    def _done(self, key: tuple[str, str, str], job: asyncio.Future[bytes]) -> None:
        self.making.pop(key, None)
        if not job.cancelled() and job.exception() is None:
            self.made[key] = job.result()
            while len(self.made) > REPORTS_KEPT:
                self.made.popitem(last=False)


def reports_of(request: Request) -> Reports:
    state = request.app.state
    if getattr(state, "reports", None) is None:
        state.reports = Reports()
    reports: Reports = state.reports
    return reports


def make_report(projects: Projects, pid: str, fmt: str) -> bytes:
    """The report of project ``pid`` in ``fmt`` (a job of the report pool), its memory given
    back after it."""
    from gsgeo.report import render
    from gsgeo.service.reporting import report_data

    try:
        return render(report_data(projects, pid), fmt)
    finally:
        release_memory()


@router.get("/projects/{pid}/report", summary="The project's survey report (PDF or HTML)",
            response_class=Response,
            responses={200: {"content": {"application/pdf": {}, "text/html": {}},
                             "description": "the report as one self-contained file"},
                       304: {"description": "If-None-Match names this version's report"}})
async def report(pid: PID, request: Request,
                 format: Annotated[Literal["pdf", "html"],
                                   Query(description="pdf (default) or html")] = "pdf",
                 if_none_match: Annotated[str | None, Header(max_length=4000)] = None
                 ) -> Response:
    from gsgeo.report import MEDIA_TYPES
    from gsgeo.service.reporting import report_version

    projects = svc(request)
    version = await run_in_threadpool(report_version, projects, pid)  # 404 before any job
    key = None if version is None else (pid, format, version)
    etag = None if key is None else \
        '"' + hashlib.sha256("\0".join(key).encode()).hexdigest()[:32] + '"'
    headers = {"Content-Disposition": f'attachment; filename="{pid}-report.{format}"'}
    if etag is not None:
        headers["ETag"] = etag
        if if_none_match is not None and etag in [t.strip() for t in if_none_match.split(",")]:
            return Response(status_code=304, headers={"ETag": etag})
    pool: JobPool = request.app.state.report_jobs
    body = await reports_of(request).get(key, lambda: pool.run(make_report, projects, pid, format))
    if format == "html":
        headers["Content-Security-Policy"] = HTML_CSP
    return Response(body, media_type=MEDIA_TYPES[format], headers=headers)
