"""OGC API – Features at /ogc: a thin FastAPI router over gsgeo.service.ogc.

Parameters are read from the query string here (not by pydantic), so that every bad one is
answered 400 with OGC's exception body ``{"code", "description"}``; an unknown collection or
feature is 404 in the same shape. JSON (GeoJSON for features) by default, HTML with ``f=html``
or a browser's ``Accept: text/html``; HEAD answers as GET without the body. Feature answers
carry ``Content-Crs``, ``ETag`` (a hash of the body) and ``Last-Modified``; ``If-None-Match``
with the current ETag gets 304. Numbers are ASCII decimal only (gsgeo.limits.integer_text,
number_text): no Unicode digits, underscores, blanks, nan or inf.
"""

from __future__ import annotations

import hashlib
import threading
from collections.abc import Callable
from dataclasses import dataclass
from datetime import UTC, datetime
from email.utils import format_datetime
from urllib.parse import quote, urlencode

import orjson
from fastapi import APIRouter, Request
from fastapi.responses import HTMLResponse, Response

from gsgeo import __version__
from gsgeo.errors import CRSError, InputError
from gsgeo.jsontypes import JSONObject
from gsgeo.limits import integer_text
from gsgeo.server.ogc import html
from gsgeo.server.ogc.openapi import OPENAPI_MEDIA, openapi_document
from gsgeo.server.ogc.pages import PageCache
from gsgeo.service import NotFoundError
from gsgeo.service.ogc import (
    DEFAULT_LIMIT,
    FILTERS,
    GEOMETRY,
    LAYERS,
    MAX_LIMIT,
    MAX_OFFSET,
    TEMPORAL,
    TITLES,
    Collection,
    FeatureService,
    ItemPage,
    ItemQuery,
    offered_crs,
    parse_bbox,
    parse_datetime,
    storage_crs,
)

router = APIRouter(prefix="/ogc", include_in_schema=False)

GEOJSON = "application/geo+json"
JSON = "application/json"
SCHEMA_JSON = "application/schema+json"
CONFORMANCE = [
    "http://www.opengis.net/spec/ogcapi-features-1/1.0/conf/core",
    "http://www.opengis.net/spec/ogcapi-features-1/1.0/conf/geojson",
    "http://www.opengis.net/spec/ogcapi-features-1/1.0/conf/html",
    "http://www.opengis.net/spec/ogcapi-features-1/1.0/conf/oas30",
    "http://www.opengis.net/spec/ogcapi-features-2/1.0/conf/crs",
]
QUERYABLES_REL = "http://www.opengis.net/def/rel/ogc/1.0/queryables"
#: ``measured_at`` is the datetime filter named by its queryable (GDAL sends a filter on a
#: queryable as ``name=value``).
ITEM_PARAMS = {"f", "limit", "offset", "bbox", "bbox-crs", "datetime", "measured_at", "crs",
               "code"}


class OgcError(Exception):
    """A request the OGC API refuses: HTTP status, OGC exception code, description."""

    def __init__(self, status: int, code: str, description: str):
        super().__init__(description)
        self.status, self.code, self.description = status, code, description


def exception_response(status: int, code: str, description: str) -> Response:
    """OGC's exception body (``code``, ``description``), with gsgeo's ``message`` beside."""
    body = {"code": code, "description": description, "message": description}
    return Response(orjson.dumps(body), status_code=status, media_type=JSON)


def _answer(make: Callable[[], Response]) -> Response:
    """``make()``, its refusals turned into OGC exception answers."""
    try:
        return make()
    except OgcError as exc:
        return exception_response(exc.status, exc.code, exc.description)
    except NotFoundError as exc:
        return exception_response(404, "NotFound", str(exc))
    except (InputError, CRSError) as exc:
        return exception_response(400, "InvalidParameterValue", str(exc))


def _service(request: Request) -> FeatureService:
    return FeatureService(request.app.state.projects)


def _root(request: Request) -> str:
    return str(request.base_url).rstrip("/") + "/ogc"


def _params(request: Request, allowed: set[str]) -> dict[str, str]:
    """The query parameters, each given once and known; OgcError 400 otherwise."""
    out: dict[str, str] = {}
    for key in request.query_params:
        if key not in allowed:
            raise OgcError(400, "InvalidParameterValue", f"unknown parameter '{key}'; this "
                           f"request takes {', '.join(sorted(allowed))}")
        values = request.query_params.getlist(key)
        if len(values) != 1:
            raise OgcError(400, "InvalidParameterValue", f"parameter '{key}' is given "
                           f"{len(values)} times")
        out[key] = values[0]
    return out


def _wants_html(request: Request, params: dict[str, str]) -> bool:
    f = params.get("f")
    if f is not None:
        if f.lower() not in ("json", "html", "geojson"):
            raise OgcError(400, "InvalidParameterValue", f"f must be json or html, not {f!r}")
        return f.lower() == "html"
    accept = request.headers.get("accept", "")
    return "text/html" in accept and "json" not in accept


def _json(doc: JSONObject, media: str = JSON, headers: dict[str, str] | None = None) -> Response:
    return Response(orjson.dumps(doc), media_type=media, headers=headers)


def _link(href: str, rel: str, type_: str, title: str | None = None) -> JSONObject:
    out: JSONObject = {"href": href, "rel": rel, "type": type_}
    if title:
        out["title"] = title
    return out


def _self_links(url: str, as_html: bool, media: str = JSON) -> list[JSONObject]:
    sep = "&" if "?" in url else "?"
    return [_link(f"{url}{sep}f={'html' if as_html else 'json'}", "self",
                  "text/html" if as_html else media, "this document"),
            _link(f"{url}{sep}f={'json' if as_html else 'html'}", "alternate",
                  media if as_html else "text/html", "this document as "
                  + ("JSON" if as_html else "HTML"))]


@router.api_route("", methods=["GET", "HEAD"])
def landing(request: Request) -> Response:
    def make() -> Response:
        as_html = _wants_html(request, _params(request, {"f"}))
        root = _root(request)
        doc = {"title": "gsgeo OGC API – Features",
               "description": "Measured points, lines, polygons, check points and rays of every "
                              "gsgeo project, live (gsgeo " + __version__ + ").",
               "links": [*_self_links(root, as_html),
                         _link(f"{root}/api", "service-desc", OPENAPI_MEDIA,
                               "the API definition (OpenAPI 3.0)"),
                         _link(f"{str(request.base_url).rstrip('/')}/docs", "service-doc",
                               "text/html", "the HTTP API's documentation"),
                         _link(f"{root}/conformance", "conformance", JSON,
                               "conformance classes"),
                         _link(f"{root}/collections", "data", JSON, "collections")]}
        return HTMLResponse(html.landing(doc)) if as_html else _json(doc)

    return _answer(make)


@router.api_route("/api", methods=["GET", "HEAD"])
def api_definition(request: Request) -> Response:
    def make() -> Response:
        _params(request, {"f"})
        return _json(openapi_document(_root(request)), OPENAPI_MEDIA)

    return _answer(make)


@router.api_route("/conformance", methods=["GET", "HEAD"])
def conformance(request: Request) -> Response:
    def make() -> Response:
        as_html = _wants_html(request, _params(request, {"f"}))
        doc = {"conformsTo": CONFORMANCE}
        return HTMLResponse(html.conformance(doc)) if as_html else _json(doc)

    return _answer(make)


def _collection_doc(root: str, c: Collection, as_html: bool = False) -> JSONObject:
    base = f"{root}/collections/{c.id}"
    return {
        "id": c.id,
        "title": f"{c.project.name}: {TITLES[c.layer]}",
        "description": f"project '{c.project.id}', layer {c.layer} ({GEOMETRY[c.layer]}); "
                       "properties as in the GeoPackage export",
        "itemType": "feature",
        "crs": [o.uri for o in offered_crs(c.project)],
        "storageCrs": storage_crs(c.project),
        "links": [*_self_links(base, as_html),
                  _link(f"{base}/items?f=json", "items", GEOJSON, "the features"),
                  _link(f"{base}/items?f=html", "items", "text/html", "the features as HTML"),
                  _link(f"{base}/queryables", QUERYABLES_REL, SCHEMA_JSON, "queryables")],
    }


@router.api_route("/collections", methods=["GET", "HEAD"])
def collections(request: Request) -> Response:
    def make() -> Response:
        as_html = _wants_html(request, _params(request, {"f"}))
        root = _root(request)
        colls = _service(request).collections()
        doc = {"links": _self_links(f"{root}/collections", as_html),
               "collections": [_collection_doc(root, c) for c in colls],
               "crs": sorted({u for c in colls for u in
                              (o.uri for o in offered_crs(c.project))})}
        return HTMLResponse(html.collections(doc)) if as_html else _json(doc)

    return _answer(make)


@router.api_route("/collections/{collection_id}", methods=["GET", "HEAD"])
def collection(request: Request, collection_id: str) -> Response:
    def make() -> Response:
        as_html = _wants_html(request, _params(request, {"f"}))
        c = _service(request).collection(collection_id)
        doc = _collection_doc(_root(request), c, as_html)
        return HTMLResponse(html.collection(doc)) if as_html else _json(doc)

    return _answer(make)


@router.api_route("/collections/{collection_id}/queryables", methods=["GET", "HEAD"])
def queryables(request: Request, collection_id: str) -> Response:
    def make() -> Response:
        as_html = _wants_html(request, _params(request, {"f"}))
        c = _service(request).collection(collection_id)
        types = {"str": {"type": "string"}, "float": {"type": "number"},
                 "int": {"type": "integer"}, "bool": {"type": "boolean"}}
        gtype = GEOMETRY[c.layer].removesuffix("Z")
        props: JSONObject = {"geometry": {
            "$ref": f"https://geojson.org/schema/{gtype}.json"}}
        for name in FILTERS[c.layer]:
            props[name] = types[LAYERS[c.layer][name]]
        if c.layer in TEMPORAL and "measured_at" in LAYERS[c.layer]:
            props["measured_at"] = {"type": "string", "format": "date-time"}
        doc = {"$schema": "https://json-schema.org/draft/2019-09/schema",
               "$id": f"{_root(request)}/collections/{c.id}/queryables",
               "type": "object", "title": f"queryables of {c.id}", "properties": props,
               "additionalProperties": False}
        return HTMLResponse(html.queryables(doc)) if as_html else _json(doc, SCHEMA_JSON)

    return _answer(make)


def _int(params: dict[str, str], name: str, default: int, low: int, high: int | None = None
         ) -> int:
    text = params.get(name)
    if text is None:
        return default
    try:
        v = integer_text(text, name)
    except InputError:
        raise OgcError(400, "InvalidParameterValue", f"{name} must be a whole number written "
                       f"with ASCII digits, not {text[:40]!r}") from None
    if v < low:
        raise OgcError(400, "InvalidParameterValue", f"{name} must be at least {low}")
    if high is not None and v > high:
        raise OgcError(400, "InvalidParameterValue", f"{name} must be at most {high}")
    return v


def _query(params: dict[str, str]) -> ItemQuery:
    start = end = None
    if "datetime" in params and "measured_at" in params:
        raise OgcError(400, "InvalidParameterValue", "give datetime or measured_at, not both")
    for name in ("datetime", "measured_at"):
        if name in params:
            start, end = parse_datetime(params[name], name)
    return ItemQuery(
        limit=min(_int(params, "limit", DEFAULT_LIMIT, 1), MAX_LIMIT),
        offset=_int(params, "offset", 0, 0, MAX_OFFSET),
        crs=params.get("crs"),
        bbox=parse_bbox(params["bbox"]) if "bbox" in params else None,
        bbox_crs=params.get("bbox-crs"),
        start=start, end=end, code=params.get("code"))


def _http_date(iso: str) -> str:
    try:
        t = datetime.fromisoformat(iso)
    except ValueError:
        t = datetime.now(UTC)
    if t.tzinfo is None:
        t = t.replace(tzinfo=UTC)
    return format_datetime(t.astimezone(UTC).replace(microsecond=0), usegmt=True)


@dataclass(frozen=True)
class Rendered:
    """An answer's body with what its headers say, and the query of the page after it."""

    body: bytes
    media: str
    crs_uri: str
    last_modified: str
    next_params: dict[str, str] | None = None


def _rendered(body: bytes, media: str, page: ItemPage,
              next_params: dict[str, str] | None = None) -> Rendered:
    return Rendered(body, media, page.crs.uri, page.last_modified, next_params)


def _cached(request: Request, got: Rendered) -> Response:
    """The answer with Content-Crs, ETag and Last-Modified; 304 when If-None-Match has it."""
    body = got.body
    etag = '"' + hashlib.blake2b(body, digest_size=16).hexdigest() + '"'
    headers = {"ETag": etag, "Last-Modified": _http_date(got.last_modified),
               "Content-Crs": f"<{got.crs_uri}>", "Cache-Control": "no-cache"}
    wanted = request.headers.get("if-none-match")
    if wanted is not None:
        tags = {t.strip().removeprefix("W/") for t in wanted.split(",")}
        if etag in tags or "*" in tags:
            return Response(status_code=304, headers=headers)
    return Response(body, media_type=got.media, headers=headers)


_PAGES_LOCK = threading.Lock()


def _pages(request: Request) -> PageCache[Rendered]:
    """The application's pages made ahead (made at its first items request)."""
    state = request.app.state
    with _PAGES_LOCK:
        cache = getattr(state, "ogc_pages", None)
        if cache is None:
            cache = state.ogc_pages = PageCache(state.projects.store.revision)
    return cache


def _render_items(svc: FeatureService, root: str, collection_id: str, params: dict[str, str],
                  as_html: bool) -> Rendered:
    """A page of items as the answer's body (GeoJSON or HTML), with next/prev links."""
    q = _query(params)
    page = svc.items(collection_id, q)
    base = f"{root}/collections/{collection_id}/items"
    keep = {k: v for k, v in params.items() if k not in ("f", "offset", "limit")}

    def query(offset: int, fmt: str) -> dict[str, str]:
        return {**keep, "f": fmt, "limit": str(q.limit), "offset": str(offset)}

    def url(offset: int, fmt: str) -> str:
        return base + "?" + urlencode(query(offset, fmt))

    media = "text/html" if as_html else GEOJSON
    fmt = "html" if as_html else "json"
    links = [_link(url(q.offset, fmt), "self", media, "this page"),
             _link(url(q.offset, "json" if as_html else "html"), "alternate",
                   GEOJSON if as_html else "text/html", "this page in the other format"),
             _link(f"{root}/collections/{collection_id}", "collection", JSON,
                   "the collection")]
    n = len(page.features)
    after = None
    if q.offset + n < page.number_matched:
        links.append(_link(url(q.offset + n, fmt), "next", media, "next page"))
        after = query(q.offset + n, fmt)
    if q.offset > 0:
        links.append(_link(url(max(0, q.offset - q.limit), fmt), "prev", media,
                           "previous page"))
    # no timeStamp (optional): the body, and so its ETag, changes only when the data does
    doc = {"type": "FeatureCollection", "features": page.features,
           "numberMatched": page.number_matched, "numberReturned": n, "links": links}
    if as_html:
        return _rendered(html.items(doc, f"{collection_id}: features").encode(),
                         "text/html; charset=utf-8", page, after)
    return _rendered(orjson.dumps(doc), GEOJSON, page, after)


@router.api_route("/collections/{collection_id}/items", methods=["GET", "HEAD"])
def items(request: Request, collection_id: str) -> Response:
    def make() -> Response:
        params = _params(request, ITEM_PARAMS)
        as_html = _wants_html(request, params)
        _query(params)  # a bad parameter is refused before anything is read
        svc, root = _service(request), _root(request)
        if as_html:
            return _cached(request, _render_items(svc, root, collection_id, params, True))
        pages = _pages(request)
        got = pages.take((root, collection_id, tuple(sorted(params.items()))))
        if got is None:
            got = _render_items(svc, root, collection_id, params, False)
        nxt = got.next_params
        if nxt is not None:  # made while the client reads this one
            pages.make_ahead((root, collection_id, tuple(sorted(nxt.items()))),
                             lambda: _render_items(svc, root, collection_id, nxt, False))
        return _cached(request, got)

    return _answer(make)


@router.api_route("/collections/{collection_id}/items/{feature_id:path}", methods=["GET", "HEAD"])
def item(request: Request, collection_id: str, feature_id: str) -> Response:
    def make() -> Response:
        params = _params(request, {"f", "crs"})
        as_html = _wants_html(request, params)
        page = _service(request).item(collection_id, feature_id, params.get("crs"))
        root = _root(request)
        base = f"{root}/collections/{collection_id}/items/{quote(feature_id, safe='~')}"
        doc = dict(page.features[0])
        doc["links"] = [*_self_links(base, as_html, GEOJSON),
                        _link(f"{root}/collections/{collection_id}", "collection", JSON,
                              "the collection")]
        if as_html:
            return _cached(request, _rendered(html.feature(doc).encode(),
                                              "text/html; charset=utf-8", page))
        return _cached(request, _rendered(orjson.dumps(doc), GEOJSON, page))

    return _answer(make)
