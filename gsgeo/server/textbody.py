"""JSON request bodies held to the one rule for text (gsgeo.limits.text_problem).

Python's JSON decoder turns the escape ``"\\ud800"`` into an unpaired surrogate and
``"\\u0000"`` into a NUL character; neither is text a store, PROJ, GDAL or a file format can
keep, and a body typed loosely (a session document, a building's attributes) would carry
them to one of those and fail there with a 500. Every JSON body of the API is therefore
checked where it is parsed, before any route sees it: such text anywhere in it is 422 naming
its JSON path (``points[0].description``). The bytes are screened first, so an ordinary body
costs one regular-expression scan.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Coroutine
from typing import Any

from fastapi.routing import APIRoute
from starlette.requests import Request
from starlette.responses import Response

from gsgeo.limits import check_json_text, json_text_may_be_bad


class TextCheckedRequest(Request):
    """A request whose ``json()`` refuses (InputError) text that no field may hold."""

    async def json(self) -> Any:
        if not hasattr(self, "_json"):
            body = await self.body()
            doc = json.loads(body)
            if json_text_may_be_bad(body):
                check_json_text(doc)
            self._json = doc
        return self._json


class TextCheckedRoute(APIRoute):
    """An API route whose JSON body is parsed by :class:`TextCheckedRequest`. FastAPI wraps
    the InputError in its 400 "error parsing the body"; the app's handler answers 422 with the
    InputError's field and message (its ``__cause__``)."""

    def get_route_handler(self) -> Callable[[Request], Coroutine[Any, Any, Response]]:
        handler = super().get_route_handler()

        async def checked(request: Request) -> Response:
            return await handler(TextCheckedRequest(request.scope, request.receive))

        return checked
