"""A project's OGC API - Features collections as QGIS layers (the OAPIF provider), and their
refresh.

Each layer remembers its server collection in the custom properties ``gsgeo/collection``
and ``gsgeo/project`` (kept in saved QGIS projects), which is how refresh and "send as
check points" find gsgeo layers. QGIS 3.22 reads the collections in CRS84 (lon, lat,
WGS 84 ellipsoidal height); QGIS versions implementing OGC API - Features Part 2 read them
in the storage CRS the server announces (the project's grid). QGIS reprojects either.
"""

from __future__ import annotations

from typing import Any

from qgis.core import QgsDataSourceUri, QgsLayerTreeGroup, QgsProject, QgsVectorLayer

from .client import Connection
from .styles import apply_style

PROVIDER = "OAPIF"
PROP_COLLECTION = "gsgeo/collection"
PROP_PROJECT = "gsgeo/project"
#: Drawing order, bottom first; kinds not listed go below these.
ORDER = ("polygons", "buildings", "lines", "rays", "check_points", "points")
#: Kinds added but not shown at first (many features, little to see at map scale).
HIDDEN = frozenset({"rays"})


def oapif_uri(connection: Connection, collection_id: str) -> str:
    """The OAPIF provider's data source for one collection of the server at ``connection``.

    ``restrictToRequestBBOX`` makes QGIS fetch only what the map shows (with ``bbox``); the
    token is added to the requests by BearerToken, not written here."""
    uri = QgsDataSourceUri()
    uri.setParam("url", connection.base + "/ogc")
    uri.setParam("typename", collection_id)
    uri.setParam("restrictToRequestBBOX", "1")
    return uri.uri(False)


def project_collections(collections: list[dict[str, Any]], pid: str) -> list[tuple[str, str, str]]:
    """(collection id, kind, title) of project ``pid``'s collections, in drawing order."""
    out = []
    for c in collections:
        cid = str(c.get("id", ""))
        if cid.startswith(pid + ".") and len(cid) > len(pid) + 1:
            out.append((cid, cid[len(pid) + 1:], str(c.get("title") or cid)))
    rank = {k: i for i, k in enumerate(ORDER)}
    return sorted(out, key=lambda t: rank.get(t[1], -1))


def gsgeo_layers(project: QgsProject, pid: str | None = None) -> list[QgsVectorLayer]:
    """The gsgeo layers in ``project`` (of project ``pid`` when given)."""
    out = []
    for layer in project.mapLayers().values():
        if not isinstance(layer, QgsVectorLayer) or not layer.customProperty(PROP_COLLECTION):
            continue
        if pid is None or layer.customProperty(PROP_PROJECT) == pid:
            out.append(layer)
    return out


def layer_kind(layer: QgsVectorLayer) -> str:
    """The collection kind of a gsgeo layer ('points', 'lines', ...; '' for other layers)."""
    cid = str(layer.customProperty(PROP_COLLECTION) or "")
    pid = str(layer.customProperty(PROP_PROJECT) or "")
    return cid[len(pid) + 1:] if pid and cid.startswith(pid + ".") else ""


def project_group(project: QgsProject, title: str) -> QgsLayerTreeGroup:
    """The layer tree group named ``title``, made at the top when missing."""
    root = project.layerTreeRoot()
    group = root.findGroup(title)
    return group if group is not None else root.insertGroup(0, title)


def add_project_layers(connection: Connection, collections: list[dict[str, Any]], pid: str,
                       title: str, project: QgsProject | None = None) -> list[QgsVectorLayer]:
    """Add (or, when already there, reload) project ``pid``'s collections as styled layers in
    a group ``title``; returns the layers, invalid ones included (the caller reports them)."""
    project = project or QgsProject.instance()
    have = {str(lyr.customProperty(PROP_COLLECTION)): lyr for lyr in gsgeo_layers(project, pid)}
    group = project_group(project, title)
    out = []
    for cid, kind, name in project_collections(collections, pid):
        if cid in have:
            refresh_layer(have[cid])
            out.append(have[cid])
            continue
        layer = QgsVectorLayer(oapif_uri(connection, cid), name, PROVIDER)
        layer.setCustomProperty(PROP_COLLECTION, cid)
        layer.setCustomProperty(PROP_PROJECT, pid)
        if layer.isValid():
            apply_style(layer, kind)
        project.addMapLayer(layer, False)
        node = group.insertLayer(0, layer)
        if kind in HIDDEN:
            node.setItemVisibilityChecked(False)
        out.append(layer)
    return out


def refresh_layer(layer: QgsVectorLayer) -> None:
    """Drop what the provider has cached and draw again: the next read is the server's now.

    QGIS 3.22's OAPIF provider learns a layer's fields from its first features, so a layer
    added while its collection was empty has none; such a layer, and one that could not be
    opened (the server was down), is opened afresh (same source, name and place) and styled
    with the fields it has now."""
    if not layer.isValid() or layer.fields().count() == 0:
        layer.setDataSource(layer.source(), layer.name(), layer.providerType())
        if layer.isValid() and layer.fields().count():
            apply_style(layer, layer_kind(layer))
        return
    layer.dataProvider().reloadData()
    layer.triggerRepaint()


def refresh_layers(project: QgsProject | None = None) -> int:
    """Reload every gsgeo layer of ``project``; returns how many."""
    layers = gsgeo_layers(project or QgsProject.instance())
    for layer in layers:
        refresh_layer(layer)
    return len(layers)
