"""ASGI middleware guarding the server: body size limits, token, host and origin checks.

- Request bodies over the limit get 413 (checked on Content-Length and while streaming). The
  limit is the one of the route the request reaches (``body_limit``, see
  gsgeo.server.routing), so no path spelling earns a larger one.
- When a token is configured, every /api and /ogc request must carry it
  (``Authorization: Bearer TOKEN`` or ``X-Gsgeo-Token: TOKEN``), and so must every /scenes
  request, where the cookie ``gsgeo-token[-PORT]=TOKEN`` also counts (the viewer sets it
  from ``#token=`` so that Cesium's own tile requests carry it); otherwise 401. The API
  takes no cookie: a browser sends cookies by itself, headers only when a script adds them,
  so no page of another site can make a request count as the user's.
- Accounts (gsgeo.service.accounts): a user's own token counts as the token does; the request
  is then made as that user (the audit trail's "who", set with gsgeo.service.audit.acting_as),
  the server's token as "admin-token", no token on loopback (when none is configured) as
  "local". Off loopback a token is required even when none is configured. A request that
  presents a token (header, or the /scenes cookie) is judged by it everywhere: on loopback too
  a wrong or revoked one gets 401, never the local operator's rights. A ``viewer`` may
  only read: any other method than GET/HEAD/OPTIONS on /api or /ogc (POST /api/intersect,
  which stores nothing, aside) gets 403 naming the role. Only an ``admin`` may delete a whole
  project (``DELETE /api/projects/{pid}``: it takes every point, line, building, check point
  of it along); a surveyor gets 403 naming the role. The request's user and role are in
  ``scope["state"]`` (``gsgeo_user``, ``gsgeo_role``) for the routes (``GET /api/info``).
- The Host header must be one the server answers to (defeats DNS rebinding on loopback).
- An /api or /ogc request from a browser page of another origin (``Origin`` header not matching the
  Host) gets 403: CORS is closed, and this also stops cross-site form posts.
"""

from __future__ import annotations

import json
import re
import secrets
from collections.abc import Callable
from urllib.parse import unquote

import anyio.to_thread
from starlette.requests import cookie_parser
from starlette.types import ASGIApp, Message, Receive, Scope, Send

from gsgeo.server.hosts import is_loopback
from gsgeo.service.accounts import authenticate
from gsgeo.service.audit import LOCAL, acting_as

MiB = 1024 * 1024

#: Paths guarded as the API: token off loopback, closed CORS (the JSON API and the OGC API).
GUARDED = ("/api", "/ogc")

#: Name (or name prefix, ``gsgeo-token-PORT``) of the cookie that carries the token to /scenes.
TOKEN_COOKIE = "gsgeo-token"

#: Who a request made with the server's own token (--token, GSGEO_TOKEN) is recorded as.
ADMIN_TOKEN_ACTOR = "admin-token"
#: Methods a viewer may use; and the one POST that stores nothing.
READ_METHODS = ("GET", "HEAD", "OPTIONS")
READ_POSTS = ("/api/intersect",)
#: At most this many presented tokens are looked up (a request offers one or two).
MAX_TOKENS = 4
#: What only an admin may do: (method, path pattern, what it does).
ADMIN_ONLY = (("DELETE", re.compile(r"/api/projects/[^/]+/?"), "deletes a whole project"),)


class BodyTooLarge(Exception):
    """Raised while reading a body over the limit; the app turns it into 413."""

    def __init__(self, limit: int):
        super().__init__(f"request body exceeds the limit of {limit} bytes")
        self.limit = limit


async def _send_json(send: Send, status: int, message: str, field: str | None = None,
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


def presented_tokens(headers: dict[str, str], with_cookie: bool) -> list[str]:
    """The tokens a request offers: X-Gsgeo-Token, a Bearer Authorization and, when
    ``with_cookie``, the values of the ``gsgeo-token`` cookies."""
    out = []
    if "x-gsgeo-token" in headers:
        out.append(headers["x-gsgeo-token"])
    auth = headers.get("authorization", "")
    if auth[:7].lower() == "bearer ":
        out.append(auth[7:].strip())
    if with_cookie and "cookie" in headers:
        for name, value in cookie_parser(headers["cookie"]).items():
            if name == TOKEN_COOKIE or name.startswith(TOKEN_COOKIE + "-"):
                out.append(unquote(value))
    return out


class Guard:
    """The middleware. ``allowed_hosts`` None (or containing "*") accepts any Host;
    ``body_limit(scope)`` is the body limit in bytes of the request's route."""

    def __init__(self, app: ASGIApp, *, token: str | None, allowed_hosts: set[str] | None,
                 body_limit: Callable[[Scope], int]):
        self.app = app
        self.token = token
        self.allowed_hosts = ({h.lower() for h in allowed_hosts}
                              if allowed_hosts and "*" not in allowed_hosts else None)
        self.body_limit = body_limit
        self.loopback: bool | None = None  # the server's bind address is loopback (lazily)

    def _token_ok(self, tokens: list[str]) -> bool:
        if self.token is None:
            return False
        want = self.token.encode()
        # every candidate compared, so the time taken does not tell which one came close
        return any([secrets.compare_digest(t.encode(), want) for t in tokens])

    def _open_on_loopback(self, scope: Scope) -> bool:
        """Whether a request may come without a token: no token is configured and the server
        is bound to loopback (its config, read once from the app)."""
        if self.token is not None:
            return False
        if self.loopback is None:
            config = getattr(getattr(scope.get("app"), "state", None), "config", None)
            host = getattr(config, "host", None)
            self.loopback = host is None or is_loopback(str(host))
        return self.loopback

    async def _identify(self, scope: Scope, tokens: list[str]) -> tuple[str, str] | None:
        """(user name, role) of the request, or None when it must be refused (401).

        A request that presents a token is judged by it, on loopback too: a wrong or revoked
        token is refused, never taken for the local operator. Empty values present nothing.
        """
        tokens = [t for t in tokens if t]
        if self._token_ok(tokens):
            return ADMIN_TOKEN_ACTOR, "admin"
        projects = getattr(getattr(scope.get("app"), "state", None), "projects", None)
        store = getattr(projects, "store", None)
        if store is not None:
            for t in tokens[:MAX_TOKENS]:
                user = await anyio.to_thread.run_sync(authenticate, store, t)
                if user is not None:
                    return user.name, user.role
        if not tokens and self._open_on_loopback(scope):
            return LOCAL, "admin"
        return None

    async def __call__(self, scope: Scope, receive: Receive, send: Send) -> None:
        if scope["type"] != "http":
            await self.app(scope, receive, send)
            return
        headers = {k.decode("latin-1").lower(): v.decode("latin-1") for k, v in scope["headers"]}
        path: str = scope["path"]
        host = headers.get("host", "")
        if self.allowed_hosts is not None and _host_name(host) not in self.allowed_hosts:
            await _send_json(send, 400, f"Host header '{host[:80]}' is not served here", "Host")
            return
        is_api = any(path == p or path.startswith(p + "/") for p in GUARDED)
        if is_api:
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
        is_scene = path == "/scenes" or path.startswith("/scenes/")
        who = (LOCAL, "admin")
        if is_api or is_scene:
            tokens = presented_tokens(headers, with_cookie=is_scene)
            found = await self._identify(scope, tokens)
            if found is None:
                why = "the token presented is not valid (wrong, or its user was removed); " \
                    if any(tokens) else ""
                await _send_json(send, 401, why + "a valid token is required: send "
                                 "'Authorization: Bearer TOKEN' (the server's token, see its "
                                 "start message or GSGEO_TOKEN, or a user's, made with "
                                 "'gsgeo users add'); the viewer takes it from "
                                 "/#token=TOKEN", "Authorization",
                                 [(b"www-authenticate", b"Bearer")])
                return
            who = found
            method = str(scope.get("method", "GET")).upper()
            if is_api and who[1] == "viewer" and method not in READ_METHODS \
                    and not (method == "POST" and path in READ_POSTS):
                await _send_json(send, 403, f"user '{who[0]}' has the role viewer, which may "
                                 f"only read: {method} {path[:120]} changes data (ask an admin "
                                 "for the surveyor role)", "Authorization")
                return
            admin_only = next((what for m, pattern, what in ADMIN_ONLY
                               if m == method and pattern.fullmatch(path)), None)
            if is_api and admin_only is not None and who[1] != "admin":
                await _send_json(send, 403, f"user '{who[0]}' has the role {who[1]}: "
                                 f"{method} {path[:120]} {admin_only}, which only an admin may "
                                 "do", "Authorization")
                return
            scope.setdefault("state", {}).update(gsgeo_user=who[0], gsgeo_role=who[1])
        limit: int | None = None

        def body_limit() -> int:  # looked up only for requests that have a body
            nonlocal limit
            if limit is None:
                limit = self.body_limit(scope)
            return limit

        cl = headers.get("content-length")
        if cl is not None:
            try:
                n = int(cl)
            except ValueError:
                await _send_json(send, 400, "Content-Length is not a number", "Content-Length")
                return
            if n > 0 and n > body_limit():
                await _send_json(send, 413, f"request body of {n} bytes exceeds the limit of "
                                 f"{body_limit()} bytes", "body")
                return
        seen = 0
        started = False

        async def limited_receive() -> Message:
            nonlocal seen
            msg = await receive()
            if msg["type"] == "http.request":
                seen += len(msg.get("body", b""))
                if seen > 0 and seen > body_limit():
                    raise BodyTooLarge(body_limit())
            return msg

        async def tracking_send(msg: Message) -> None:
            nonlocal started
            if msg["type"] == "http.response.start":
                started = True
            await send(msg)

        try:
            with acting_as(who[0]):
                await self.app(scope, limited_receive, tracking_send)
        except BodyTooLarge:
            if not started:
                await _send_json(send, 413, f"request body exceeds the limit of "
                                 f"{body_limit()} bytes", "body")
