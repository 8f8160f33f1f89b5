"""Headless driver of the plugin for tests: QGIS without a display, commands on stdin.

Run with Debian's QGIS Python (``QT_QPA_PLATFORM=offscreen /usr/bin/python3
qgis/harness.py [PLUGINS_DIR]``). It loads the plugin package ``gsgeo`` from this directory
(through ``classFactory``), or, given PLUGINS_DIR (an installed copy, e.g. the zip
extracted), as QGIS starts installed plugins, with a minimal stand-in for QGIS's interface;
then it reads one JSON command per line and answers each with one line ``@@ {json}`` on
stdout (anything else on stdout is QGIS's own chatter). Commands (``cmd``):

- ``connect`` {url, token}: the plugin's connect; answers the project ids.
- ``add_layers`` {project}: choose the project and add its layers; answers ``layers``.
- ``refresh``: reload the gsgeo layers; answers ``layers``.
- ``send`` {collection, ids, role}: select the features of that layer whose point_id is in
  ``ids`` and send them; answers the server's reply and the body the plugin built.
- ``send_memory`` {crs, rows, role}: the same from a memory layer of the user's own.
  Both answer the plugin's questions with ``confirm`` (false when absent) and list them
  (``asked``).
- ``dialog`` {url, token}: the Connect dialog's "List projects"; answers what it shows.
- ``settings``: the connection and project as stored in QgsSettings.
- ``live`` {on}: the Live toggle; answers whether the timer runs.
- ``ellipse`` {major, minor, bearing}: a point with that error ellipse, drawn and measured.
- ``unload``: what QGIS does when the plugin is switched off; answers what is left.
- ``viewer`` {x, y, crs}: the map tool's click at x, y on a map in ``crs``; answers the URL.
- ``quit``.

``layers`` describes every gsgeo layer: name, collection, validity, provider, CRS, the
feature count by reading, and each feature's point_id/id with x, y, z in the layer's CRS and
in ``to_crs`` (EPSG code given with the command) transformed by QGIS.
"""

from __future__ import annotations

import json
import sys
import traceback
from pathlib import Path
from typing import Any

from qgis.core import (
    Qgis,
    QgsApplication,
    QgsCoordinateReferenceSystem,
    QgsCoordinateTransform,
    QgsFeatureRequest,
    QgsPointXY,
    QgsProject,
    QgsVectorLayer,
)
from qgis.gui import QgsMapCanvas
from qgis.PyQt.QtWidgets import QMainWindow, QToolBar


class Iface:
    """The parts of QgisInterface the plugin uses."""

    def __init__(self) -> None:
        self.window = QMainWindow()
        self.canvas = QgsMapCanvas(self.window)
        self.active: QgsVectorLayer | None = None
        self.messages: list[str] = []

    def mainWindow(self) -> QMainWindow:
        return self.window

    def mapCanvas(self) -> QgsMapCanvas:
        return self.canvas

    def messageBar(self) -> Iface:
        return self

    def pushMessage(self, title: str, text: str, level: Any = None, duration: int = 0) -> None:
        self.messages.append(text)

    def addToolBar(self, name: str) -> QToolBar:
        return self.window.addToolBar(name)

    def addPluginToMenu(self, menu: str, action: Any) -> None:
        pass

    def removePluginMenu(self, menu: str, action: Any) -> None:
        pass

    def activeLayer(self) -> QgsVectorLayer | None:
        return self.active


def describe(layer: QgsVectorLayer, to_crs: str | None) -> dict[str, Any]:
    xf = None
    if to_crs:
        xf = QgsCoordinateTransform(layer.crs(), QgsCoordinateReferenceSystem(to_crs),
                                    QgsProject.instance())
    feats = []
    names = layer.fields().names()
    for f in layer.getFeatures(QgsFeatureRequest()):
        g = f.geometry()
        row: dict[str, Any] = {"fid": f.id()}
        for key in ("point_id", "id", "code", "role"):
            if key in names:
                row[key] = f[key]
        if not g.isNull():
            v = next(iter(g.constGet().vertices()))
            row["xyz"] = [v.x(), v.y(), v.z() if v.is3D() else None]
            if xf is not None:
                p = xf.transform(QgsPointXY(v.x(), v.y()))
                row["grid"] = [p.x(), p.y()]
        feats.append(row)
    return {"name": layer.name(), "collection": layer.customProperty("gsgeo/collection"),
            "valid": layer.isValid(), "provider": layer.providerType(),
            "crs": layer.crs().authid(), "fields": names, "count": len(feats),
            "features": feats, "source": layer.source()}


def layers_of(to_crs: str | None) -> list[dict[str, Any]]:
    from gsgeo.layers import gsgeo_layers

    return [describe(lyr, to_crs) for lyr in gsgeo_layers(QgsProject.instance())]


def run(plugin: Any, iface: Iface, cmd: dict[str, Any]) -> dict[str, Any]:
    from gsgeo.client import Connection
    from gsgeo.layers import gsgeo_layers

    name = cmd["cmd"]
    if name == "connect":
        projects = plugin.connect(Connection(cmd["url"], cmd.get("token", "")))
        return {"projects": [p["id"] for p in projects]}
    if name == "add_layers":
        plugin.choose_project(cmd["project"])
        plugin.add_layers()
        return {"layers": layers_of(cmd.get("to_crs")), "messages": iface.messages,
                "project_crs": QgsProject.instance().crs().authid(),
                "map_crs": iface.canvas.mapSettings().destinationCrs().authid(),
                "map_extent": iface.canvas.extent().toRectF().getCoords()}
    if name == "refresh":
        n = plugin.refresh()
        return {"refreshed": n, "layers": layers_of(cmd.get("to_crs"))}
    if name == "send":
        layer = next(lyr for lyr in gsgeo_layers(QgsProject.instance())
                     if lyr.customProperty("gsgeo/collection") == cmd["collection"])
        ids = [f.id() for f in layer.getFeatures() if f["point_id"] in cmd["ids"]]
        layer.selectByIds(ids)
        iface.active = layer
        from gsgeo.checkpoints import layer_payload

        body, _ = layer_payload(layer, cmd["role"])
        asked = answer_questions(plugin, cmd.get("confirm", False))
        answer = plugin.send_selected(cmd["role"])
        return {"answer": answer, "body": body, "selected": len(ids), "messages": iface.messages,
                "asked": asked}
    if name == "send_memory":
        return send_memory(plugin, iface, cmd)
    if name == "dialog":
        from gsgeo.dialog import ConnectDialog

        dlg = ConnectDialog(Connection(cmd["url"], cmd.get("token", "")), "")
        dlg.list_projects()
        return {"status": dlg.status.text(), "items": dlg.project.count(),
                "ok": dlg.buttons.button(dlg.buttons.StandardButton.Ok).isEnabled()}
    if name == "settings":
        from gsgeo.settings import load_connection, load_project

        c = load_connection()
        return {"url": c.url, "token": c.token, "project": load_project()}
    if name == "live":
        plugin.set_live(cmd["on"])
        return {"active": plugin.timer.isActive(), "interval_ms": plugin.timer.interval()}
    if name == "unload":
        plugin.unload()
        return {"actions": len(plugin.actions), "token_hook": plugin.token.handle is not None,
                "live": plugin.timer.isActive()}
    if name == "ellipse":
        return render_ellipse(cmd["major"], cmd["minor"], cmd["bearing"])
    if name == "viewer":
        opened: list[str] = []
        plugin.open_url = opened.append
        iface.canvas.setDestinationCrs(QgsCoordinateReferenceSystem(cmd["crs"]))
        plugin.map_tool.clicked(QgsPointXY(cmd["x"], cmd["y"]), 1)
        return {"opened": opened}
    raise ValueError(f"unknown command {name!r}")


def send_memory(plugin: Any, iface: Iface, cmd: dict[str, Any]) -> dict[str, Any]:
    """A layer of the user's own (memory, ``crs``, a ``name`` field) with ``rows``
    [{name, x, y[, z]}] all selected, sent with the plugin."""
    from qgis.core import QgsFeature, QgsGeometry, QgsPoint

    kind = "PointZ" if any("z" in r for r in cmd["rows"]) else "Point"
    layer = QgsVectorLayer(f"{kind}?crs={cmd['crs']}&field=name:string", "mine", "memory")
    feats = []
    for r in cmd["rows"]:
        f = QgsFeature(layer.fields())
        f["name"] = r.get("name")
        p = QgsPoint(r["x"], r["y"], r["z"]) if "z" in r else QgsPoint(r["x"], r["y"])
        f.setGeometry(QgsGeometry(p))
        feats.append(f)
    layer.dataProvider().addFeatures(feats)
    QgsProject.instance().addMapLayer(layer)
    layer.selectAll()
    iface.active = layer
    asked = answer_questions(plugin, cmd.get("confirm", False))
    answer = plugin.send_selected(cmd["role"])
    QgsProject.instance().removeMapLayer(layer.id())
    return {"answer": answer, "messages": iface.messages, "asked": asked}


def answer_questions(plugin: Any, yes: bool) -> list[str]:
    """Answer the plugin's questions to the user with ``yes``; the questions asked."""
    asked: list[str] = []

    def ask(_title: str, text: str) -> bool:
        asked.append(text)
        return yes

    plugin.ask = ask
    return asked


def render_ellipse(major: float, minor: float, bearing: float) -> dict[str, Any]:
    """Render one point styled as a gsgeo point with that 95 % ellipse (metres, degrees
    clockwise from grid north) on a 0.2 m square map in EPSG:27700 (2000 px per metre) and
    measure the drawn outline: its long axis's bearing and its half-lengths (m)."""
    import numpy as np
    from qgis.core import (
        QgsFeature,
        QgsGeometry,
        QgsMapRendererSequentialJob,
        QgsMapSettings,
        QgsRectangle,
    )
    from qgis.PyQt.QtCore import QSize
    from qgis.PyQt.QtGui import QColor

    from gsgeo.styles import apply_style

    layer = QgsVectorLayer("Point?crs=EPSG:27700&field=point_id:string&field=ellipse_major_95:"
                           "double&field=ellipse_minor_95:double&field=ellipse_bearing_deg:double",
                           "ellipse", "memory")
    f = QgsFeature(layer.fields())
    f.setAttributes(["", major, minor, bearing])
    f.setGeometry(QgsGeometry.fromPointXY(QgsPointXY(500000.0, 200000.0)))
    layer.dataProvider().addFeatures([f])
    apply_style(layer, "points")
    ms = QgsMapSettings()
    ms.setDestinationCrs(layer.crs())
    ms.setLayers([layer])
    ms.setExtent(QgsRectangle(499999.9, 199999.9, 500000.1, 200000.1))
    ms.setOutputSize(QSize(400, 400))
    ms.setBackgroundColor(QColor("white"))
    job = QgsMapRendererSequentialJob(ms)
    job.start()
    job.waitForFinished()
    img = job.renderedImage()
    px = 400 / 0.2
    ys, xs = np.nonzero([[img.pixelColor(x, y).green() < 200 for x in range(400)]
                         for y in range(400)])
    east, north = (xs + 0.5 - 200) / px, (200 - ys - 0.5) / px
    ring = np.hypot(east, north) > 0.004  # the outline, not the dot in the middle
    e, n = east[ring], north[ring]
    w, v = np.linalg.eigh(np.cov(np.vstack([e, n])))
    axis = v[:, 1]
    along = np.abs(e * axis[0] + n * axis[1]).max()
    across = np.abs(-e * axis[1] + n * axis[0]).max()
    return {"bearing": float(np.degrees(np.arctan2(axis[0], axis[1])) % 180.0),
            "major": float(along), "minor": float(across)}


def load_plugin(iface: Iface, plugins_dir: str | None) -> tuple[Any, dict[str, Any]]:
    """The plugin object, started. Without ``plugins_dir`` the package next to this file,
    through its classFactory; with it, the way QGIS starts an installed plugin (qgis.utils
    finds it in that plugins folder, reads metadata.txt, imports it, calls classFactory and
    initGui). Also what was loaded from where."""
    if plugins_dir is None:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        import gsgeo

        plugin = gsgeo.classFactory(iface)
        plugin.initGui()
        return plugin, {"module": gsgeo.__file__}
    import qgis.utils as qu

    qu.iface = iface
    qu.plugin_paths = [plugins_dir]
    sys.path.insert(0, plugins_dir)
    qu.updateAvailablePlugins()
    if "gsgeo" not in qu.available_plugins:
        raise RuntimeError(f"QGIS finds no plugin gsgeo in {plugins_dir}")
    if not qu.loadPlugin("gsgeo") or not qu.startPlugin("gsgeo"):
        raise RuntimeError("QGIS could not load or start the plugin gsgeo")
    return qu.plugins["gsgeo"], {
        "module": sys.modules["gsgeo"].__file__,
        "min_version": qu.pluginMetadata("gsgeo", "qgisMinimumVersion"),
        "name": qu.pluginMetadata("gsgeo", "name")}


def main() -> int:
    app = QgsApplication([], True)
    app.initQgis()
    iface = Iface()
    iface.canvas.setDestinationCrs(QgsCoordinateReferenceSystem("EPSG:4326"))
    plugin, loaded = load_plugin(iface, sys.argv[1] if len(sys.argv) > 1 else None)
    from qgis.core import QgsProviderRegistry

    print("@@ " + json.dumps({"ready": True, "qgis": Qgis.QGIS_VERSION, **loaded,
                              "providers": QgsProviderRegistry.instance().providerList()}),
          flush=True)
    for line in sys.stdin:
        if not line.strip():
            continue
        cmd = json.loads(line)
        if cmd["cmd"] == "quit":
            break
        try:
            out = run(plugin, iface, cmd)
        except Exception as exc:  # the test shows it; the harness goes on
            out = {"error": f"{type(exc).__name__}: {exc}", "trace": traceback.format_exc()}
        print("@@ " + json.dumps(out, default=str), flush=True)
    if plugin.actions:
        plugin.unload()
    QgsProject.instance().clear()
    app.exitQgis()
    return 0


if __name__ == "__main__":
    sys.exit(main())
