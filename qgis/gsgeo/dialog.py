"""The "Connect" dialog: server URL and token, then the project to work on."""

from __future__ import annotations

from typing import Any

from qgis.PyQt.QtWidgets import (
    QComboBox,
    QDialog,
    QDialogButtonBox,
    QFormLayout,
    QLabel,
    QLineEdit,
    QPushButton,
    QWidget,
)

from .client import Connection, GsgeoApiError, GsgeoClient, check_url

# Qt's enums by their scoped names, which PyQt5 (QGIS 3) and PyQt6 both take.
OK = QDialogButtonBox.StandardButton.Ok


class ConnectDialog(QDialog):
    """Asks for the connection, lists the server's projects on "List projects"; after
    ``exec()`` returns true, ``connection`` and ``project_id`` hold the choice."""

    def __init__(self, connection: Connection, project_id: str, parent: QWidget | None = None) -> None:
        super().__init__(parent)
        self.setWindowTitle("gsgeo: connect to a server")
        self.connection = connection
        self.project_id = project_id
        self.projects: list[dict[str, Any]] = []
        self.url = QLineEdit(connection.url)
        self.token = QLineEdit(connection.token)
        self.token.setEchoMode(QLineEdit.EchoMode.Password)
        self.token.setPlaceholderText("none (a server on loopback without GSGEO_TOKEN)")
        self.list_button = QPushButton("List projects")
        self.project = QComboBox()
        self.status = QLabel("")
        self.status.setWordWrap(True)
        self.buttons = QDialogButtonBox(OK | QDialogButtonBox.StandardButton.Cancel)
        self.buttons.button(OK).setEnabled(False)
        form = QFormLayout(self)
        form.addRow("Server URL", self.url)
        form.addRow("Token", self.token)
        form.addRow("", self.list_button)
        form.addRow("Project", self.project)
        form.addRow(self.status)
        form.addRow(self.buttons)
        self.list_button.clicked.connect(self.list_projects)
        self.buttons.accepted.connect(self.accept_choice)
        self.buttons.rejected.connect(self.reject)

    def list_projects(self) -> None:
        """Ask the server for its projects and fill the project list (or say what failed)."""
        try:
            conn = Connection(check_url(self.url.text()), self.token.text().strip())
            self.projects = GsgeoClient(conn).projects()
        except (ValueError, GsgeoApiError) as exc:
            self.status.setText(str(exc))
            return
        self.connection = conn
        self.project.clear()
        for p in self.projects:
            self.project.addItem(f"{p.get('name') or p['id']} ({p['id']})", p["id"])
        idx = self.project.findData(self.project_id)
        if idx >= 0:
            self.project.setCurrentIndex(idx)
        self.status.setText(f"{len(self.projects)} project(s)" if self.projects
                            else "The server has no projects yet.")
        self.buttons.button(OK).setEnabled(bool(self.projects))

    def accept_choice(self) -> None:
        self.project_id = str(self.project.currentData() or "")
        self.accept()
