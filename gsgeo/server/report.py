"""GET /api/projects/{pid}/report: the project's survey report as PDF or HTML.

The same document as `gsgeo report` (gsgeo.service.reporting gathers it, gsgeo.report
renders it). The HTML answer carries a Content-Security-Policy that allows nothing but its
own inline style and data-URI images: the document needs nothing else, and project text in
it is escaped.
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Query, Request, Response

from gsgeo.server.api import PID, ErrorBody, svc
from gsgeo.server.textbody import TextCheckedRoute

router = APIRouter(prefix="/api", route_class=TextCheckedRoute, responses={
    404: {"model": ErrorBody, "description": "no such project"},
    422: {"model": ErrorBody, "description": "malformed request; message names the field"},
    503: {"model": ErrorBody, "description": "the project store is busy or unavailable"},
})

HTML_CSP = "default-src 'none'; img-src data:; style-src 'unsafe-inline'"


@router.get("/projects/{pid}/report", summary="The project's survey report (PDF or HTML)",
            response_class=Response,
            responses={200: {"content": {"application/pdf": {}, "text/html": {}},
                             "description": "the report as one self-contained file"}})
def report(pid: PID, request: Request,
           format: Annotated[Literal["pdf", "html"],
                             Query(description="pdf (default) or html")] = "pdf") -> Response:
    from gsgeo.report import MEDIA_TYPES, render
    from gsgeo.service.reporting import report_data

    body = render(report_data(svc(request), pid), format)
    headers = {"Content-Disposition": f'attachment; filename="{pid}-report.{format}"'}
    if format == "html":
        headers["Content-Security-Policy"] = HTML_CSP
    return Response(body, media_type=MEDIA_TYPES[format], headers=headers)
