"""Scenes whose tiles lie on a static host or object store (``gsgeo serve --scenes URL``).

The scene's ``tileset.json`` stays in ``DATA/scenes/<name>/`` and gsgeo serves it: it holds the
georeference, which the server reads to measure and writes when a georeference is applied, so
the viewer draws the scene in exactly the frame the server measures in (a copy on the static
host would go stale on the first Apply, silently shifting every new measurement). Only the
tiles it names (glTF/GLB content, external tilesets, implicit-tiling subtrees) come from the
static host: gsgeo serves ``tileset.json`` with each relative URI made absolute against the
scene's folder there, ``<URL><name>/`` (or the folder given for that one scene), so the browser
fetches them from that host, which must allow the viewer's origin (CORS).

URLs are checked when the server starts (``scene_hosts``); nothing here opens a connection.
"""

from __future__ import annotations

import hashlib
import json
import os
import stat
import threading
from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any
from urllib.parse import urljoin, urlsplit

from starlette.requests import Request
from starlette.responses import JSONResponse, Response

from gsgeo.errors import InputError
from gsgeo.server.files import safe_path
from gsgeo.service.validate import SLUG

#: Keys whose string values are URI references relative to the tileset (3D Tiles 1.0 and 1.1:
#: content ``uri``, the pre-1.0 ``url``, implicit tiling's subtree ``uri`` template, the
#: metadata ``schemaUri``). ``extras`` are the application's own and are left as they are.
URI_KEYS = ("uri", "url", "schemaUri")


def folder_url(text: str, what: str) -> str:
    """``text`` checked as the http(s) URL of a folder, ending with '/'.

    Refused (InputError naming ``what``): another scheme, no host, user name or password in
    the URL (browsers refuse them on the requests of a page), a query or fragment (the scene's
    files are joined onto the path), a bad port, spaces or control characters."""
    raw = text.strip()
    if not raw:
        raise InputError(f"{what}: is empty; give the http:// or https:// URL of the folder")
    if any(c.isspace() or ord(c) < 32 or ord(c) == 127 for c in raw):
        raise InputError(f"{what} {raw!r}: contains a space or control character")
    parts = urlsplit(raw)
    if parts.scheme.lower() not in ("http", "https"):
        got = f"scheme '{parts.scheme}'" if parts.scheme else "no scheme"
        raise InputError(f"{what} {raw!r}: must be an http:// or https:// URL, got {got}")
    if not parts.hostname:
        raise InputError(f"{what} {raw!r}: names no host")
    if parts.username is not None or parts.password is not None:
        raise InputError(f"{what} {raw!r}: must not carry a user name or password (browsers "
                         "refuse them; let the host allow the viewer's origin instead)")
    try:
        parts.port  # noqa: B018 - raises ValueError on a port that is not a number or too big
    except ValueError:
        raise InputError(f"{what} {raw!r}: has a port that is not a number from 0 to "
                         "65535") from None
    if parts.query or parts.fragment or raw.endswith(("?", "#")):
        raise InputError(f"{what} {raw!r}: must not have a query or fragment (each scene's "
                         "files are joined onto its path)")
    return raw if raw.endswith("/") else raw + "/"


@dataclass(frozen=True)
class SceneHosts:
    """Where the tiles of each scene come from: ``base`` (``<base><name>/``) and folders for
    single scenes in ``folders`` (name -> folder URL); neither: from this server."""

    base: str | None = None
    folders: Mapping[str, str] = field(default_factory=dict)

    def folder(self, name: str) -> str | None:
        """The folder URL (ending with '/') holding scene ``name``'s tiles, or None when this
        server serves them (/scenes/<name>/)."""
        if name in self.folders:
            return self.folders[name]
        return f"{self.base}{name}/" if self.base is not None else None


def scene_hosts(base: str | None, per_scene: Mapping[str, str] | None = None) -> SceneHosts:
    """The checked ``SceneHosts`` of ``gsgeo serve --scenes URL`` and ``--scene-url NAME=URL``
    (InputError naming the option on a bad URL or scene name)."""
    folders = {}
    for name, url in (per_scene or {}).items():
        if not SLUG.match(name):
            raise InputError(f"--scene-url {name}={url}: '{name}' is not a scene name (letters, "
                             "digits, '.', '_' and '-', starting with a letter or digit)")
        folders[name] = folder_url(url, f"--scene-url {name}=")
    return SceneHosts(None if base is None else folder_url(base, "--scenes"), folders)


def parse_scene_url(text: str) -> tuple[str, str]:
    """``NAME=URL`` of ``--scene-url`` split (InputError when there is no '=')."""
    name, sep, url = text.partition("=")
    if not sep or not name.strip():
        raise InputError(f"--scene-url {text!r}: give NAME=URL (the scene's name in "
                         "DATA/scenes and the URL of the folder holding its tiles)")
    return name.strip(), url


def absolute_uris(doc: Any, folder: str) -> Any:
    """A copy of the tileset JSON ``doc`` whose relative URI references (``URI_KEYS``, outside
    ``extras``) are resolved against ``folder`` (the URL of the folder of tileset.json).
    Absolute and ``data:`` URIs stay as they are."""
    if isinstance(doc, list):
        return [absolute_uris(v, folder) for v in doc]
    if not isinstance(doc, dict):
        return doc
    out: dict[str, Any] = {}
    for key, value in doc.items():
        if key == "extras":
            out[key] = value
        elif key in URI_KEYS and isinstance(value, str):
            out[key] = urljoin(folder, value)
        else:
            out[key] = absolute_uris(value, folder)
    return out


_cache: dict[tuple[Path, str], tuple[tuple[int, int, int], bytes, str]] = {}
_cache_lock = threading.Lock()


def hosted_tileset(path: Path, folder: str) -> tuple[bytes, str]:
    """(body, strong ETag) of the tileset.json file at ``path`` with its URIs resolved against
    ``folder``; cached while the file's size, mtime and inode stay the same.

    Raises OSError when it cannot be read, ValueError when it is not a JSON object and
    RecursionError when it is nested beyond reason."""
    with open(path, "rb") as f:
        st = os.fstat(f.fileno())
        key = (st.st_mtime_ns, st.st_size, st.st_ino)
        with _cache_lock:
            hit = _cache.get((path, folder))
        if hit is not None and hit[0] == key:
            return hit[1], hit[2]
        raw = f.read()
    doc = json.loads(raw)
    if not isinstance(doc, dict):
        raise ValueError("tileset.json is not a JSON object")
    body = json.dumps(absolute_uris(doc, folder), separators=(",", ":")).encode()
    etag = '"' + hashlib.blake2b(body, digest_size=12).hexdigest() + '"'
    with _cache_lock:
        _cache[(path, folder)] = (key, body, etag)
    return body, etag


def hosted_tileset_response(request: Request, folder: Path, tiles_url: str, cache_control: str,
                            refuse: Collection[tuple[int, int]] = ()) -> Response:
    """GET/HEAD of ``folder/tileset.json`` with its URIs resolved against ``tiles_url``: 404
    when absent or refused (the store's files), 422 naming the problem when it is not a
    tileset's JSON, 304 for a matching ``If-None-Match``."""
    path = safe_path(folder, "tileset.json")
    try:
        st = os.stat(path) if path is not None else None
    except OSError:
        st = None
    if path is None or st is None or not stat.S_ISREG(st.st_mode) \
            or (st.st_dev, st.st_ino) in refuse:
        return Response("not found", status_code=404, media_type="text/plain")
    try:
        body, etag = hosted_tileset(path, tiles_url)
    except OSError:
        return Response("not found", status_code=404, media_type="text/plain")
    except (ValueError, RecursionError) as exc:
        msg = f"tileset.json of this scene cannot be read: {str(exc)[:200]}"
        return JSONResponse({"detail": msg, "message": msg, "field": None}, status_code=422)
    headers = {"ETag": etag, "Cache-Control": cache_control, "X-Content-Type-Options": "nosniff"}
    inm = request.headers.get("if-none-match")
    if inm is not None and ({t.strip().removeprefix("W/") for t in inm.split(",")} & {"*", etag}):
        return Response(status_code=304, headers=headers)
    if request.method == "HEAD":
        headers["Content-Length"] = str(len(body))
        return Response(b"", headers=headers, media_type="application/json")
    return Response(body, headers=headers, media_type="application/json")
