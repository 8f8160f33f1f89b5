"""ASGI middleware guarding the server: body size limits, token, host and origin checks.

- Request bodies over the limit get 413 (checked on Content-Length and while streaming).
- When a token is configured, every /api request must carry it
  (``Authorization: Bearer TOKEN`` or ``X-Gsgeo-Token: TOKEN``); otherwise 401.
- The Host header must be one the server answers to (defeats DNS rebinding on loopback).
- An /api request from a browser page of another origin (``Origin`` header not matching the
  Host) gets 403: CORS is closed, and this also stops cross-site form posts.
"""

from __future__ import annotations

import json
import secrets
from collections.abc import Awaitable, Callable
from typing import Any

Scope = dict[str, Any]
Message = dict[str, Any]
ASGIApp = Callable[[Scope, Callable[[], Awaitable[Message]], Callable[[Message], Awaitable[None]]],
                   Awaitable[None]]

MiB = 1024 * 1024


class BodyTooLarge(Exception):
    """Raised while reading a body over the limit; the app turns it into 413."""

    def __init__(self, limit: int):
        super().__init__(f"request body exceeds the limit of {limit} bytes")
        self.limit = limit


async def _send_json(send, status: int, message: str, field: str | None = None,
                     headers: list[tuple[bytes, bytes]] | None = None) -> None:
    body = json.dumps({"detail": message, "message": message, "field": field}).encode()
    await send({"type": "http.response.start", "status": status,
                "headers": [(b"content-type", b"application/json"),
                            (b"content-length", str(len(body)).encode())] + (headers or [])})
    await send({"type": "http.response.body", "body": body})


def _host_name(host: str) -> str:
    host = host.strip().lower()
    if host.startswith("["):
        return host[: host.find("]") + 1] if "]" in host else host
    return host.rsplit(":", 1)[0] if host.count(":") == 1 else host


class Guard:
    """The middleware. ``allowed_hosts`` None (or containing "*") accepts any Host."""

    def __init__(self, app: ASGIApp, *, token: str | None, allowed_hosts: set[str] | None,
                 max_body: int, max_upload: int, upload_paths: tuple[str, ...] = ("/import",)):
        self.app = app
        self.token = token
        self.allowed_hosts = ({h.lower() for h in allowed_hosts}
                              if allowed_hosts and "*" not in allowed_hosts else None)
        self.max_body = max_body
        self.max_upload = max_upload
        self.upload_paths = upload_paths

    async def __call__(self, scope: Scope, receive, send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        path: str = scope["path"]
        host = headers.get("host", "")
        if self.allowed_hosts is not None and _host_name(host) not in self.allowed_hosts:
            await _send_json(send, 400, f"Host header '{host[:80]}' is not served here", "Host")
            return
        if path == "/api" or path.startswith("/api/"):
            origin = headers.get("origin")
            if origin is not None and origin != "null":
                o = origin.split("://", 1)[-1].rstrip("/").lower()
                if o != host.lower():
                    await _send_json(send, 403, "cross-origin requests to the API are not "
                                     "allowed (CORS is closed)", "Origin")
                    return
            elif origin == "null":
                await _send_json(send, 403, "requests from an opaque origin are not allowed",
                                 "Origin")
                return
            if self.token is not None:
                given = headers.get("x-gsgeo-token")
                auth = headers.get("authorization", "")
                if given is None and auth[:7].lower() == "bearer ":
                    given = auth[7:].strip()
                if given is None or not secrets.compare_digest(given.encode(), self.token.encode()):
                    await _send_json(send, 401, "a valid token is required: send "
                                     "'Authorization: Bearer TOKEN' (see the server's start "
                                     "message or GSGEO_TOKEN)", "Authorization",
                                     [(b"www-authenticate", b"Bearer")])
                    return
        limit = self.max_upload if path.endswith(self.upload_paths) else self.max_body
        cl = headers.get("content-length")
        if cl is not None:
            try:
                n = int(cl)
            except ValueError:
                await _send_json(send, 400, "Content-Length is not a number", "Content-Length")
                return
            if n > limit:
                await _send_json(send, 413, f"request body of {n} bytes exceeds the limit of "
                                 f"{limit} bytes", "body")
                return
        seen = 0
        started = False

        async def limited_receive() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > limit:
                    raise BodyTooLarge(limit)
            return msg

        async def tracking_send(msg: Message) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            await self.app(scope, limited_receive, tracking_send)
        except BodyTooLarge:
            if not started:
                await _send_json(send, 413, f"request body exceeds the limit of {limit} bytes",
                                 "body")
