"""Exceptions raised by gsgeo.

Every error a user can cause derives from :class:`GsgeoError` and carries a message that
names the problem in the user's terms; the command line turns it into exit code 2 and the
HTTP API into a 4xx response.
"""


class GsgeoError(Exception):
    """Base class of every error gsgeo raises on purpose."""


class InputError(GsgeoError, ValueError):
    """The input (rays, a session file, a parameter) is malformed or out of range."""


class GeometryError(InputError):
    """The rays cannot be intersected: too few, (near-)parallel, or the point lies behind a camera."""


class CRSError(GsgeoError, ValueError):
    """A coordinate reference system is unknown, of the wrong kind, or cannot be used."""


class DatumError(CRSError):
    """A vertical datum cannot be honoured, e.g. its geoid grid is missing."""
