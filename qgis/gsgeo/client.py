"""The gsgeo server's JSON API (/api) and OGC API - Features (/ogc), over plain HTTP.

Standard library only (urllib), so that it runs in any QGIS Python without extra packages.
Every failure (network, HTTP status, a body that is not JSON) is a GsgeoApiError whose
message names the request and, when the server sent one, the server's own message.
"""

from __future__ import annotations

import json
import urllib.error
import urllib.parse
import urllib.request
from dataclasses import dataclass
from typing import Any

#: Seconds to wait for the server on one request.
TIMEOUT_S = 30.0


class GsgeoApiError(Exception):
    """A request to the gsgeo server failed; ``status`` is the HTTP status when there was one."""

    def __init__(self, message: str, status: int | None = None) -> None:
        super().__init__(message)
        self.status = status


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
        """``method`` ``path`` (from the server root, e.g. /api/projects) with a JSON body."""
        url = self.connection.base + path
        data = None if body is None else json.dumps(body).encode()
        headers = {"Accept": "application/json", **self.connection.headers()}
        if data is not None:
            headers["Content-Type"] = "application/json"
        req = urllib.request.Request(url, data=data, method=method, headers=headers)
        try:
            with urllib.request.urlopen(req, timeout=TIMEOUT_S) as resp:
                raw = resp.read()
        except urllib.error.HTTPError as exc:
            raise GsgeoApiError(f"{method} {url}: HTTP {exc.code}: {server_message(exc)}",
                                exc.code) from None
        except (urllib.error.URLError, OSError) as exc:
            reason = getattr(exc, "reason", exc)
            raise GsgeoApiError(f"{method} {url}: the server does not answer ({reason})") from None
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
        """POST check or control points (payload as /api/projects/{pid}/checkpoints takes it)."""
        return dict(self.request("POST", f"/api/projects/{quote(pid)}/checkpoints", payload))


def quote(part: str) -> str:
    """One URL path segment, escaped."""
    return urllib.parse.quote(part, safe="")


def server_message(exc: urllib.error.HTTPError) -> str:
    """The server's ``message`` (or ``detail``) from an error body, else the HTTP reason."""
    try:
        body = json.loads(exc.read() or b"{}")
    except ValueError:
        body = {}
    if isinstance(body, dict):
        msg = body.get("message") or body.get("detail")
        if msg:
            field = body.get("field")
            return f"{msg} ({field})" if field else str(msg)
    return str(exc.reason)
