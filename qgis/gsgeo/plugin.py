"""The plugin object: actions in a toolbar and the "gsgeo" menu, wired to the modules that do
the work (client, layers, viewer, checkpoints)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from qgis.core import Qgis, QgsProject, QgsVectorLayer
from qgis.PyQt.QtCore import QTimer, QUrl
from qgis.PyQt.QtGui import QDesktopServices
from qgis.PyQt.QtWidgets import QAction, QMessageBox, QToolBar

from .auth import BearerToken
from .checkpoints import layer_payload, replacement_question
from .client import Connection, GsgeoApiError, GsgeoClient
from .dialog import ConnectDialog
from .layers import PROP_PROJECT, add_project_layers, refresh_layers
from .mapframe import frame_map
from .settings import load_connection, load_project, save_connection, save_project
from .viewer import OpenViewerTool, viewer_url

MENU = "&gsgeo"
#: How often "Live" reloads the layers, milliseconds.
LIVE_INTERVAL_MS = 5000


def open_in_browser(url: str) -> None:
    QDesktopServices.openUrl(QUrl(url))


class GsgeoPlugin:
    """One per QGIS session. ``open_url`` (the system browser) may be replaced, e.g. in tests."""

    def __init__(self, iface: Any) -> None:
        self.iface = iface
        self.connection: Connection = load_connection()
        self.project_id: str = load_project()
        self.projects: dict[str, dict[str, Any]] = {}
        self.token = BearerToken()
        self.token.install(self.connection)
        self.timer = QTimer()
        self.timer.setInterval(LIVE_INTERVAL_MS)
        self.timer.timeout.connect(self.refresh)
        self.actions: list[QAction] = []
        self.toolbar: QToolBar | None = None
        self.map_tool: OpenViewerTool | None = None
        self.open_url: Callable[[str], None] = open_in_browser
        self.ask: Callable[[str, str], bool] = self.ask_user

    # QGIS's plugin interface -------------------------------------------------------------
    def initGui(self) -> None:  # the name QGIS calls
        self.toolbar = self.iface.addToolBar("gsgeo")
        self.toolbar.setObjectName("gsgeoToolbar")
        self.add_action("Connect…", self.show_connect)
        self.add_action("Add project layers", self.add_layers)
        self.add_action("Refresh layers", self.refresh)
        self.live_action = self.add_action("Live (reload every 5 s)", self.set_live, checkable=True)
        self.viewer_action = self.add_action("Open the measuring view here", self.pick_place,
                                             checkable=True)
        self.add_action("Send selected as check points", lambda: self.send_selected("check"))
        self.add_action("Send selected as control points", lambda: self.send_selected("control"))
        self.map_tool = OpenViewerTool(self.iface.mapCanvas(), self.open_viewer_at)
        self.map_tool.setAction(self.viewer_action)

    def unload(self) -> None:
        self.timer.stop()
        self.token.remove()
        canvas = self.iface.mapCanvas()
        if self.map_tool is not None and canvas.mapTool() is self.map_tool:
            canvas.unsetMapTool(self.map_tool)
        for action in self.actions:
            self.iface.removePluginMenu(MENU, action)
        if self.toolbar is not None:
            self.toolbar.deleteLater()
        self.actions = []

    def add_action(self, text: str, slot: Callable[..., Any], checkable: bool = False) -> QAction:
        action = QAction(text, self.iface.mainWindow())
        action.setCheckable(checkable)
        action.triggered.connect(slot)
        self.iface.addPluginToMenu(MENU, action)
        if self.toolbar is not None:
            self.toolbar.addAction(action)
        self.actions.append(action)
        return action

    # what the actions do -----------------------------------------------------------------
    def say(self, text: str, level: Qgis.MessageLevel = Qgis.MessageLevel.Info) -> None:
        self.iface.messageBar().pushMessage("gsgeo", text, level=level, duration=8)

    def ask_user(self, title: str, text: str) -> bool:
        """A Yes/No question to the user (No by default); whether they said Yes."""
        answer = QMessageBox.question(self.iface.mainWindow(), title, text,
                                      QMessageBox.StandardButton.Yes | QMessageBox.StandardButton.No,
                                      QMessageBox.StandardButton.No)
        return bool(answer == QMessageBox.StandardButton.Yes)

    def client(self) -> GsgeoClient:
        return GsgeoClient(self.connection)

    def connect(self, connection: Connection) -> list[dict[str, Any]]:
        """Use ``connection`` from now on (stored in QgsSettings); returns its projects."""
        projects = GsgeoClient(connection).projects()
        self.connection = connection
        save_connection(connection)
        self.token.install(connection)
        self.projects = {str(p["id"]): p for p in projects}
        return projects

    def choose_project(self, pid: str) -> None:
        self.project_id = pid
        save_project(pid)

    def show_connect(self) -> None:
        dlg = ConnectDialog(self.connection, self.project_id, self.iface.mainWindow())
        if not dlg.exec():
            return
        try:
            self.connect(dlg.connection)
        except GsgeoApiError as exc:
            self.say(str(exc), Qgis.MessageLevel.Critical)
            return
        self.choose_project(dlg.project_id)
        self.add_layers()

    def add_layers(self) -> list[QgsVectorLayer]:
        """Add the chosen project's collections as layers; says which are not valid."""
        if not self.project_id:
            self.say("Connect and choose a project first.", Qgis.MessageLevel.Warning)
            return []
        try:
            info = self.client().project(self.project_id)
            collections = self.client().collections()
        except GsgeoApiError as exc:
            self.say(str(exc), Qgis.MessageLevel.Critical)
            return []
        self.projects[self.project_id] = info
        title = f"gsgeo: {info.get('name') or self.project_id}"
        empty_map = not QgsProject.instance().mapLayers()
        layers = add_project_layers(self.connection, collections, self.project_id, title)
        if empty_map and layers:
            frame_map(self.iface.mapCanvas(), info.get("crs"), layers)
        if not layers:
            self.say(f"The server lists no collections of project '{self.project_id}' "
                     "(is /ogc served?)", Qgis.MessageLevel.Warning)
        bad = [lyr.name() for lyr in layers if not lyr.isValid()]
        if bad:
            self.say(f"QGIS could not open: {', '.join(bad)}", Qgis.MessageLevel.Critical)
        return layers

    def refresh(self) -> int:
        return refresh_layers()

    def set_live(self, on: bool) -> None:
        if on:
            self.refresh()
            self.timer.start()
        else:
            self.timer.stop()

    def pick_place(self, on: bool) -> None:
        canvas = self.iface.mapCanvas()
        if on and self.map_tool is not None:
            canvas.setMapTool(self.map_tool)
        elif self.map_tool is not None and canvas.mapTool() is self.map_tool:
            canvas.unsetMapTool(self.map_tool)

    def open_viewer_at(self, lon: float, lat: float) -> str:
        """Open the viewer on the project's scene looking at lon, lat (degrees); the URL."""
        scene = (self.projects.get(self.project_id) or {}).get("scene")
        url = viewer_url(self.connection, scene, self.project_id, lon, lat)
        self.open_url(url)
        return url

    def send_selected(self, role: str, layer: QgsVectorLayer | None = None) -> dict[str, Any] | None:
        """POST the selected points of ``layer`` (the active layer when None) to the project
        as check or control points; the server's answer, None when nothing was sent."""
        layer = layer or self.iface.activeLayer()
        if not isinstance(layer, QgsVectorLayer):
            self.say("Select point features in a vector layer first.", Qgis.MessageLevel.Warning)
            return None
        body, skipped = layer_payload(layer, role)
        note = f" ({skipped} selected feature(s) not a single point, left out)" if skipped else ""
        if body is None:
            self.say(f"No selected point features in '{layer.name()}'{note}.", Qgis.MessageLevel.Warning)
            return None
        pid = str(layer.customProperty(PROP_PROJECT) or self.project_id)
        if not pid:
            self.say("Connect and choose a project first.", Qgis.MessageLevel.Warning)
            return None
        replaced = ""
        try:
            try:
                answer = self.client().add_check_points(pid, body)
            except GsgeoApiError as exc:
                if exc.status != 409 or not exc.ids:
                    raise
                # ids already stored: replaced only when the user says so, seeing both
                question = replacement_question(body, self.client().check_points(pid), exc.ids)
                if not self.ask("gsgeo: replace stored points?", question):
                    self.say(f"Nothing sent: {', '.join(exc.ids)} already stored in '{pid}' "
                             "and not replaced.", Qgis.MessageLevel.Warning)
                    return None
                answer = self.client().add_check_points(pid, body | {"overwrite": exc.ids})
                replaced = f"; replaced {', '.join(exc.ids)}"
        except GsgeoApiError as exc:
            self.say(str(exc), Qgis.MessageLevel.Critical)
            return None
        self.say(f"Sent {answer.get('imported', 0)} {role} point(s) to '{pid}'{replaced}{note}.")
        refresh_layers(QgsProject.instance())
        return answer
