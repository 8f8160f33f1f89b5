"""The connection (server URL and token) kept in QGIS's settings between sessions.

QgsSettings keeps values in the user's QGIS profile (a plain file): the token is stored
there as the user typed it, like QGIS's own service connections without an auth config.
"""

from __future__ import annotations

from qgis.core import QgsSettings

from .client import Connection

KEY_URL = "gsgeo/url"
KEY_TOKEN = "gsgeo/token"
KEY_PROJECT = "gsgeo/project"
DEFAULT_URL = "http://127.0.0.1:8000"


def load_connection() -> Connection:
    """The stored connection, or the default local server without a token."""
    s = QgsSettings()
    return Connection(str(s.value(KEY_URL, DEFAULT_URL) or DEFAULT_URL),
                      str(s.value(KEY_TOKEN, "") or ""))


def save_connection(connection: Connection) -> None:
    """Store the connection for the next session."""
    s = QgsSettings()
    s.setValue(KEY_URL, connection.url)
    s.setValue(KEY_TOKEN, connection.token)


def load_project() -> str:
    """The id of the project picked last ('' when none)."""
    return str(QgsSettings().value(KEY_PROJECT, "") or "")


def save_project(pid: str) -> None:
    """Remember the picked project."""
    QgsSettings().setValue(KEY_PROJECT, pid)
