"""The gsgeo server's JSON API (/api) and OGC API - Features (/ogc), over HTTP.

Requests go through QGIS's own network stack (QgsBlockingNetworkRequest), so QGIS's proxy,
SSL and timeout settings apply as they do to the layers. Every failure (network, HTTP
status, a body that is not JSON) is a GsgeoApiError whose message names the request and,
when the server sent one, the server's own message.
"""

from __future__ import annotations

import json
import urllib.parse
from dataclasses import dataclass
from typing import Any

from qgis.core import QgsBlockingNetworkRequest
from qgis.PyQt.QtCore import QByteArray, QUrl
from qgis.PyQt.QtNetwork import QNetworkRequest


class GsgeoApiError(Exception):
    """A request to the gsgeo server failed; ``status`` is the HTTP status when there was one,
    ``ids`` the stored items a 409 names (e.g. check point ids already stored)."""

    def __init__(self, message: str, status: int | None = None,
                 ids: list[str] | None = None) -> None:
        super().__init__(message)
        self.status = status
        self.ids = list(ids or [])


@dataclass(frozen=True)
class Connection:
    """Where the server is and the token it wants (empty: none, as on loopback)."""

    url: str
    token: str = ""

    @property
    def base(self) -> str:
        """The server's root URL without a trailing slash."""
        return self.url.strip().rstrip("/")

    def headers(self) -> dict[str, str]:
        """The Authorization header when there is a token."""
        return {"Authorization": f"Bearer {self.token.strip()}"} if self.token.strip() else {}


def check_url(url: str) -> str:
    """The URL stripped, or ValueError naming what is wrong with it."""
    u = urllib.parse.urlsplit(url.strip())
    if u.scheme not in ("http", "https") or not u.netloc:
        raise ValueError(f"the server URL must look like http://host:port, got '{url.strip()}'")
    return url.strip().rstrip("/")


class GsgeoClient:
    """The few calls the plugin makes, each returning the decoded JSON."""

    def __init__(self, connection: Connection) -> None:
        self.connection = connection

    def request(self, method: str, path: str, body: Any = None) -> Any:
        """``method`` GET or POST ``path`` (from the server root, e.g. /api/projects) with
        ``body`` as JSON (POST); the decoded JSON answer."""
        if method not in ("GET", "POST"):
            raise ValueError(f"method must be GET or POST, got {method}")
        url = self.connection.base + path
        req = QNetworkRequest(QUrl(url))
        req.setRawHeader(b"Accept", b"application/json")
        for name, value in self.connection.headers().items():
            req.setRawHeader(name.encode(), value.encode())
        net = QgsBlockingNetworkRequest()
        if method == "GET":
            net.get(req, True)  # forceRefresh: never QGIS's cached copy
        else:
            req.setHeader(QNetworkRequest.KnownHeaders.ContentTypeHeader, "application/json")
            net.post(req, QByteArray(json.dumps(body).encode()))
        reply = net.reply()
        status = reply.attribute(QNetworkRequest.Attribute.HttpStatusCodeAttribute)
        raw = bytes(reply.content())
        if status is None:  # no HTTP answer at all
            raise GsgeoApiError(f"{method} {url}: the server does not answer "
                                f"({net.errorMessage() or 'no reply'})")
        if int(status) >= 400:
            raise GsgeoApiError(f"{method} {url}: HTTP {int(status)}: "
                                f"{server_message(raw, net.errorMessage())}", int(status),
                                conflict_ids(raw))
        if not raw:
            return None
        try:
            return json.loads(raw)
        except ValueError:
            raise GsgeoApiError(f"{method} {url}: the answer is not JSON") from None

    def projects(self) -> list[dict[str, Any]]:
        """The server's projects (id, name, scene, crs, ...)."""
        return list(self.request("GET", "/api/projects")["projects"])

    def project(self, pid: str) -> dict[str, Any]:
        """One project with its counts."""
        return dict(self.request("GET", f"/api/projects/{quote(pid)}"))

    def collections(self) -> list[dict[str, Any]]:
        """The OGC API - Features collections (all projects')."""
        return list(self.request("GET", "/ogc/collections")["collections"])

    def add_check_points(self, pid: str, payload: dict[str, Any]) -> dict[str, Any]:
        """POST check or control points (payload as /api/projects/{pid}/checkpoints takes it).
        An id already stored and not in the payload's ``overwrite`` is refused: a
        GsgeoApiError with status 409 and those ``ids``."""
        return dict(self.request("POST", f"/api/projects/{quote(pid)}/checkpoints", payload))

    def check_points(self, pid: str) -> list[dict[str, Any]]:
        """The project's stored check and control points, as given (id, x, y, z, crs, role,
        source, ...)."""
        return list(self.request("GET", f"/api/projects/{quote(pid)}/checkpoints")["check_points"])


def quote(part: str) -> str:
    """One URL path segment, escaped."""
    return urllib.parse.quote(part, safe="")


def conflict_ids(raw: bytes) -> list[str]:
    """The ``ids`` a 409 body names, else none."""
    try:
        body = json.loads(raw or b"{}")
    except ValueError:
        return []
    ids = body.get("ids") if isinstance(body, dict) else None
    return [str(i) for i in ids] if isinstance(ids, list) else []


def server_message(raw: bytes, fallback: str) -> str:
    """The server's ``message`` (or ``detail``) from an error body, else ``fallback``."""
    try:
        body = json.loads(raw or b"{}")
    except ValueError:
        body = {}
    if isinstance(body, dict):
        msg = body.get("message") or body.get("detail")
        if msg:
            field = body.get("field")
            return f"{msg} ({field})" if field else str(msg)
    return fallback
