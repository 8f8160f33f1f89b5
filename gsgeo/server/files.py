"""Serving files from a directory: no path traversal, right content types, validators.

Every file response carries ``ETag`` (from size and mtime), ``Last-Modified`` and
``Cache-Control``; a matching ``If-None-Match`` (or, without it, ``If-Modified-Since``)
gets ``304 Not Modified``.
"""

from __future__ import annotations

import hashlib
import os
import stat
from collections.abc import Collection
from email.utils import formatdate, parsedate_to_datetime
from pathlib import Path

from starlette.requests import Request
from starlette.responses import FileResponse, Response

CONTENT_TYPES = {
    ".json": "application/json",
    ".glb": "model/gltf-binary",
    ".gltf": "model/gltf+json",
    ".bin": "application/octet-stream",
    ".spz": "application/octet-stream",
    ".b3dm": "application/octet-stream",
    ".i3dm": "application/octet-stream",
    ".pnts": "application/octet-stream",
    ".cmpt": "application/octet-stream",
    ".subtree": "application/octet-stream",
    ".ktx2": "image/ktx2",
    ".png": "image/png",
    ".jpg": "image/jpeg",
    ".jpeg": "image/jpeg",
    ".webp": "image/webp",
    ".svg": "image/svg+xml",
    ".gif": "image/gif",
    ".ico": "image/x-icon",
    ".html": "text/html; charset=utf-8",
    ".htm": "text/html; charset=utf-8",
    ".css": "text/css; charset=utf-8",
    ".js": "text/javascript; charset=utf-8",
    ".mjs": "text/javascript; charset=utf-8",
    ".map": "application/json",
    ".wasm": "application/wasm",
    ".txt": "text/plain; charset=utf-8",
    ".xml": "application/xml",
    ".woff": "font/woff",
    ".woff2": "font/woff2",
    ".ttf": "font/ttf",
    ".czml": "application/json",
    ".geojson": "application/geo+json",
    ".terrain": "application/vnd.quantized-mesh",
}


#: Files up to this size are read in one go; larger ones are streamed in chunks.
WHOLE_READ_LIMIT = 16 * 1024 * 1024


def content_type(path: Path) -> str:
    return CONTENT_TYPES.get(path.suffix.lower(), "application/octet-stream")


def safe_path(root: Path, rel: str) -> Path | None:
    """The file ``rel`` inside ``root``, or None when it is not a regular file inside it.

    Rejects '..' segments, absolute paths, backslashes, NUL and symlinks that leave root.
    """
    if not rel or "\x00" in rel or "\\" in rel or rel.startswith("/"):
        return None
    parts = rel.split("/")
    if any(p in ("", ".", "..") for p in parts):
        return None
    root_r = root.resolve()
    try:
        path = (root_r / rel).resolve(strict=True)
    except (OSError, RuntimeError):
        return None
    if not path.is_relative_to(root_r):
        return None
    return path


def etag_of(st: os.stat_result) -> str:
    h = hashlib.blake2b(f"{st.st_size}-{st.st_mtime_ns}-{st.st_ino}".encode(), digest_size=10)
    return f'"{h.hexdigest()}"'


def _not_modified(request: Request, etag: str, mtime: float) -> bool:
    inm = request.headers.get("if-none-match")
    if inm is not None:
        tags = [t.strip().removeprefix("W/") for t in inm.split(",")]
        return "*" in tags or etag in tags
    ims = request.headers.get("if-modified-since")
    if ims:
        try:
            return int(mtime) <= parsedate_to_datetime(ims).timestamp()
        except (TypeError, ValueError, IndexError, OverflowError):
            return False
    return False


def file_response(request: Request, root: Path, rel: str, cache_control: str,
                  refuse: Collection[tuple[int, int]] = ()) -> Response:
    """Serve ``root/rel`` (404 when absent or outside root, or when its (device, inode) is in
    ``refuse``)."""
    path = safe_path(root, rel)
    if path is None:
        return Response("not found", status_code=404, media_type="text/plain")
    try:
        st = path.stat()
    except OSError:
        return Response("not found", status_code=404, media_type="text/plain")
    if not stat.S_ISREG(st.st_mode) or (st.st_dev, st.st_ino) in refuse:
        return Response("not found", status_code=404, media_type="text/plain")
    etag = etag_of(st)
    headers = {"ETag": etag, "Last-Modified": formatdate(st.st_mtime, usegmt=True),
               "Cache-Control": cache_control, "X-Content-Type-Options": "nosniff"}
    if _not_modified(request, etag, st.st_mtime):
        return Response(status_code=304, headers=headers)
    if st.st_size > WHOLE_READ_LIMIT:  # stream big files in chunks
        return FileResponse(path, stat_result=st, headers=headers, media_type=content_type(path))
    # Tiles are a few MiB: one read in this worker thread beats streaming 64 KiB chunks
    # through the event loop.
    if request.method == "HEAD":
        headers["Content-Length"] = str(st.st_size)
        return Response(b"", headers=headers, media_type=content_type(path))
    try:
        with open(path, "rb") as f:
            st2 = os.fstat(f.fileno())
            data = f.read()
    except OSError:
        return Response("not found", status_code=404, media_type="text/plain")
    if (st2.st_dev, st2.st_ino) in refuse:  # swapped for a refused file since the stat
        return Response("not found", status_code=404, media_type="text/plain")
    if (st2.st_mtime_ns, st2.st_size, st2.st_ino) != (st.st_mtime_ns, st.st_size, st.st_ino):
        headers["ETag"] = etag_of(st2)  # replaced between stat and open: describe what is sent
        headers["Last-Modified"] = formatdate(st2.st_mtime, usegmt=True)
    return Response(data, headers=headers, media_type=content_type(path))
