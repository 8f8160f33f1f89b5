"""The token on QGIS's own requests to the gsgeo server (the OAPIF provider's downloads).

QGIS 3.22 has neither an "API header" auth method nor the ``http-header:`` data source
prefix, so the plugin adds ``Authorization: Bearer TOKEN`` through a request preprocessor of
QgsNetworkAccessManager (available since QGIS 3.6 and unchanged in current releases). It
touches only requests to the connected server, and the token never enters a layer's source
(so it is not written into project files).
"""

from __future__ import annotations

from qgis.core import QgsNetworkAccessManager
from qgis.PyQt.QtCore import QUrl
from qgis.PyQt.QtNetwork import QNetworkRequest

from .client import Connection


def same_server(url: QUrl, base: QUrl) -> bool:
    """Whether ``url`` is on the server at ``base`` (scheme, host, port and path prefix)."""
    if (url.scheme(), url.host().lower(), url.port(-1)) != (base.scheme(), base.host().lower(),
                                                          base.port(-1)):
        return False
    prefix = base.path().rstrip("/")
    return url.path() == prefix or url.path().startswith(prefix + "/")


class BearerToken:
    """While installed, QGIS's requests to the connection's server carry its token."""

    def __init__(self) -> None:
        self.handle: str | None = None
        self.base = QUrl()
        self.header = b""

    def install(self, connection: Connection) -> None:
        """Send ``connection``'s token from now on (replacing an earlier connection)."""
        self.remove()
        if not connection.token.strip():
            return
        self.base = QUrl(connection.base)
        self.header = connection.headers()["Authorization"].encode()
        self.handle = QgsNetworkAccessManager.setRequestPreprocessor(self.preprocess)

    def preprocess(self, request: QNetworkRequest) -> None:
        """Called by QGIS for every request it makes, on the thread that makes it."""
        if same_server(request.url(), self.base):
            request.setRawHeader(b"Authorization", self.header)

    def remove(self) -> None:
        """Stop adding the token."""
        if self.handle is not None:
            QgsNetworkAccessManager.removeRequestPreprocessor(self.handle)
            self.handle = None
