"""Plain HTML views of the OGC API's JSON answers: a heading, the links, and the content as
definition lists and tables. Every text is escaped; nothing is fetched by the page."""

from __future__ import annotations

from html import escape
from typing import Any

from gsgeo.jsontypes import JSONObject

PAGE = """<!doctype html><html lang="en"><head><meta charset="utf-8"><title>{title}</title>
<style>body{{font-family:sans-serif;margin:1.5em}}table{{border-collapse:collapse}}
td,th{{border:1px solid #ccc;padding:2px 6px;font-size:90%}}</style></head>
<body><h1>{title}</h1>{body}</body></html>"""

#: Properties shown per feature in an items table (the rest is in the JSON).
TABLE_COLUMNS = 12


def _text(v: Any) -> str:
    return "" if v is None else escape(str(v))


def _links(links: list[JSONObject]) -> str:
    items = "".join(f'<li><a href="{_text(k.get("href"))}">{_text(k.get("title") or k.get("rel"))}'
                    f'</a> ({_text(k.get("rel"))}, {_text(k.get("type"))})</li>' for k in links)
    return f"<h2>Links</h2><ul>{items}</ul>" if items else ""


def _dl(doc: JSONObject, skip: tuple[str, ...] = ()) -> str:
    rows = "".join(f"<dt>{_text(k)}</dt><dd>{_text(v)}</dd>" for k, v in doc.items()
                   if k not in skip and not isinstance(v, (dict, list)))
    return f"<dl>{rows}</dl>"


def page(title: str, body: str) -> str:
    """A whole HTML document."""
    return PAGE.format(title=escape(title), body=body)


def landing(doc: JSONObject) -> str:
    """The landing page."""
    return page(doc.get("title", "OGC API"), f"<p>{_text(doc.get('description'))}</p>"
                + _links(doc.get("links", [])))


def conformance(doc: JSONObject) -> str:
    """The conformance classes."""
    items = "".join(f"<li>{_text(c)}</li>" for c in doc.get("conformsTo", []))
    return page("Conformance", f"<ul>{items}</ul>")


def collections(doc: JSONObject) -> str:
    """The list of collections."""
    rows = "".join(
        f'<tr><td><a href="{_text(_href(c, "self"))}">{_text(c["id"])}</a></td>'
        f'<td>{_text(c.get("title"))}</td><td><a href="{_text(_href(c, "items"))}">items</a>'
        "</td></tr>" for c in doc.get("collections", []))
    return page("Collections", f"<table><tr><th>id</th><th>title</th><th></th></tr>{rows}"
                "</table>" + _links(doc.get("links", [])))


def collection(doc: JSONObject) -> str:
    """One collection's description."""
    crs = "".join(f"<li>{_text(c)}</li>" for c in doc.get("crs", []))
    return page(f"Collection {doc.get('id')}", _dl(doc) + f"<h2>CRS</h2><ul>{crs}</ul>"
                + _links(doc.get("links", [])))


def queryables(doc: JSONObject) -> str:
    """A collection's queryables."""
    rows = "".join(f"<tr><td>{_text(k)}</td><td>{_text(v.get('type') or v.get('format'))}"
                   f"</td></tr>" for k, v in doc.get("properties", {}).items())
    return page(str(doc.get("title", "Queryables")),
                f"<table><tr><th>name</th><th>type</th></tr>{rows}</table>")


def items(doc: JSONObject, title: str) -> str:
    """A page of features as a table (id, coordinates, the first properties)."""
    feats = doc.get("features", [])
    names = list(feats[0]["properties"])[:TABLE_COLUMNS] if feats else []
    head = "".join(f"<th>{_text(n)}</th>" for n in ["id", "coordinates", *names])
    rows = "".join(
        "<tr>" + f'<td>{_text(f.get("id"))}</td><td>{_text(_coords(f))}</td>'
        + "".join(f"<td>{_text(f['properties'].get(n))}</td>" for n in names) + "</tr>"
        for f in feats)
    info = (f"<p>{_text(doc.get('numberReturned'))} of {_text(doc.get('numberMatched'))} "
            "features</p>")
    return page(title, info + f"<table><tr>{head}</tr>{rows}</table>"
                + _links(doc.get("links", [])))


def feature(doc: JSONObject) -> str:
    """One feature: its coordinates and every property."""
    body = f"<p>coordinates: {_text(_coords(doc))}</p>" + _dl(doc.get("properties") or {})
    return page(f"Feature {doc.get('id')}", body + _links(doc.get("links", [])))


def _coords(f: JSONObject) -> Any:
    g = f.get("geometry")
    return None if g is None else g.get("coordinates")


def _href(doc: JSONObject, rel: str) -> str | None:
    return next((k["href"] for k in doc.get("links", []) if k.get("rel") == rel), None)
