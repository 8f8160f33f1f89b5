"""Exceptions raised by gsgeo.

Every error a user can cause derives from :class:`GsgeoError` and carries a message that
names the problem in the user's terms; the command line turns it into exit code 2 and the
HTTP API into a 4xx response.

An error about one value of a document or request carries where that value is as data:
``field``, a JSON-path style location such as ``points[0].rays[2].direction``, apart from
``problem``, the message without it. ``str(exc)`` reads ``"field: problem"``. Code that parses
a nested part re-raises with ``exc.within("points[0]")`` instead of building the path into a
message; ``exc.part_of(field, label)`` wraps an error located in something's own terms (a line
of an uploaded file, a point of a session); ``exc.in_source(path)`` names the file the
document came from. The API's 4xx ``field`` and the CLI's message read these attributes.
"""

from __future__ import annotations

import copy
from typing import Any, Self


def join_field(parent: str | None, child: str | None) -> str | None:
    """``parent`` and ``child`` joined as one JSON path: ``points[0]`` + ``rays[1]`` ->
    ``points[0].rays[1]``; ``rays`` + ``[1].origin`` -> ``rays[1].origin``; None is empty."""
    if not parent:
        return child or None
    if not child:
        return parent
    return parent + child if child.startswith("[") else f"{parent}.{child}"


class GsgeoError(Exception):
    """Base class of every error gsgeo raises on purpose.

    ``problem``: what is wrong, in the user's terms; ``field``: the JSON path of the value
    at fault (None when the error is not about one value); ``source``: the file (or other
    document) the field is in, when there is one.
    """

    def __init__(self, problem: str = "", *, field: str | None = None,
                 source: str | None = None) -> None:
        super().__init__(problem)
        self.problem = problem
        self.field = field or None
        self.source = source or None

    def __str__(self) -> str:
        return "".join(f"{p}: " for p in (self.source, self.field) if p) + self.problem

    def __repr__(self) -> str:
        extra = "".join(f", {k}={v!r}" for k, v in (("field", self.field), ("source", self.source))
                        if v is not None)
        return f"{type(self).__name__}({self.problem!r}{extra})"

    def __reduce__(self) -> tuple[Any, ...]:  # pickle and copy keep field and source, not only args
        return (type(self), (self.problem,), self.__dict__.copy())

    def at(self, field: str | None) -> Self:
        """A copy of this error about ``field`` (replacing its own field)."""
        out = copy.copy(self)
        out.field = field or None
        out.__cause__, out.__context__, out.__traceback__ = None, None, None
        out.__suppress_context__ = True
        return out

    def within(self, parent: str) -> Self:
        """A copy of this error whose field lies inside ``parent``: an error about
        ``rays[1].direction`` within ``points[0]`` is about ``points[0].rays[1].direction``."""
        return self.at(join_field(parent, self.field))

    def part_of(self, field: str | None, label: str) -> Self:
        """A copy about ``field`` whose problem is ``label: <this error>``: for an error found
        inside something a request names as one field (a file, a point) and located by this
        error in that thing's own terms (``file``: ``'cp.csv': line 3, column x: missing``)."""
        out = self.at(field)
        out.problem = f"{label}: {self}"
        return out

    def in_source(self, source: str) -> Self:
        """A copy of this error naming the file (or document) ``source`` it was found in."""
        out = self.at(self.field)
        out.source = source or None
        return out


class InputError(GsgeoError, ValueError):
    """The input (rays, a session file, a parameter) is malformed or out of range."""


class GeometryError(InputError):
    """The rays cannot be intersected: too few, (near-)parallel, or the point lies behind a camera."""


class CRSError(GsgeoError, ValueError):
    """A coordinate reference system is unknown, of the wrong kind, or cannot be used."""


class DatumError(CRSError):
    """A vertical datum cannot be honoured, e.g. its geoid grid is missing."""
