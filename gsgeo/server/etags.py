"""Entity tags of stored items (optimistic concurrency, RFC 9110 sections 8.8.3 and 13.1.1).

A point, line, polygon or building answers ``ETag: "<version>"`` (strong: the stored
version, +1 on every change of it, a re-measure included). PATCH and DELETE with
``If-Match`` go ahead only while the stored version is one the header names; ``*``, or no
header, puts no condition on it. A stale one is answered 412 with the current ETag.
"""

from __future__ import annotations

import re
from typing import Annotated

from fastapi import Header, Request, Response
from fastapi.responses import JSONResponse

from gsgeo.errors import InputError
from gsgeo.service import PreconditionFailed

#: One element of an If-Match list: an optionally weak, quoted entity tag, then a comma or
#: the end (optional whitespace around it).
_TAG = re.compile(r'[ \t]*(W/)?"([\x21\x23-\x7e\x80-\xff]*)"[ \t]*(?:,|$)')
_VERSION = re.compile(r"[1-9][0-9]{0,17}")

IfMatch = Annotated[str | None, Header(
    max_length=4000,
    description='PATCH/DELETE only if the item is still at this version: its ETag as GET '
                'gave it, e.g. "3" (quotes included), or * for any; a stale one is answered '
                '412. Absent: no condition.')]


def etag(version: int) -> str:
    """The strong entity tag of an item version: ``"3"``, quotes included."""
    return f'"{version}"'


def if_match_versions(header: str | None) -> list[int] | None:
    """The item versions an If-Match header accepts: None for no condition (absent or
    ``*``), else the versions of its strong tags (weak tags never match: the comparison is
    strong; a tag not of ours matches nothing). InputError naming If-Match when it is not a
    list of entity tags."""
    if header is None or header.strip() == "*":
        return None
    out: list[int] = []
    pos, end = 0, len(header.rstrip(" \t"))
    while pos < end:
        m = _TAG.match(header, pos, end)
        if m is None:
            raise InputError('expected * or entity tags as ETag gives them, e.g. "3" '
                             "(quotes included)", field="If-Match")
        if m.group(1) is None and _VERSION.fullmatch(m.group(2)):
            out.append(int(m.group(2)))
        pos = m.end()
    if pos == 0:
        raise InputError("is empty: give * or an entity tag such as \"3\"", field="If-Match")
    return out


def with_etag(response: Response, version: object) -> Response:
    """``response`` with the ETag of ``version`` (an item's ``version``; anything but an
    integer, e.g. from an answer of another shape, sets none)."""
    if isinstance(version, int) and not isinstance(version, bool):
        response.headers["ETag"] = etag(version)
    return response


async def precondition_failed(_req: Request, exc: Exception) -> Response:
    """412 for a stale If-Match, with the item's current ETag when known."""
    field = exc.field if isinstance(exc, PreconditionFailed) else None
    resp = JSONResponse({"detail": str(exc), "message": str(exc), "field": field},
                        status_code=412)
    if isinstance(exc, PreconditionFailed) and exc.current is not None:
        with_etag(resp, exc.current)
    return resp
