"""The last line of defence: an unexpected exception becomes a logged 500 that ends the
connection cleanly.

Starlette's own handler for ``Exception`` answers and then re-raises, and uvicorn drops the
keep-alive connection without telling the client, whose next request on it then fails. Here
the exception is logged with its traceback and answered with JSON and
``Connection: close`` (uvicorn closes after the response), so the client opens a fresh
connection and the server goes on serving. Bad input never gets here: it is answered 4xx
where it is found.
"""

from __future__ import annotations

import json
import logging

from starlette.types import ASGIApp, Message, Receive, Scope, Send

log = logging.getLogger("gsgeo.server")



def internal_error_body(exc: BaseException) -> bytes:
    """The JSON of a 500: names the exception type, never its text (it may hold data)."""
    message = f"internal error ({type(exc).__name__}); the server log has details"
    return json.dumps({"detail": message, "message": message, "field": None}).encode()


class CatchAll:
    """ASGI middleware answering any exception from the app with 500 and Connection: close."""

    def __init__(self, app: ASGIApp):
        self.app = app

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        started = False

        async def tracking_send(msg: Message) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, receive, tracking_send)
        except Exception as exc:
            log.exception("unexpected error answering %s %s", scope.get("method"),
                          scope.get("path"))
            if started:
                raise  # half a response is out: only dropping the connection is honest now
            body = internal_error_body(exc)
            await send({"type": "http.response.start", "status": 500,
                        "headers": [(b"content-type", b"application/json"),
                                    (b"content-length", str(len(body)).encode()),
                                    (b"connection", b"close")]})
            await send({"type": "http.response.body", "body": body})
