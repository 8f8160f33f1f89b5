"""What the route table says about a request before or beside routing.

The guard middleware runs before the router, yet its body limit must follow the route the
request will reach (an upload route takes files, every other route small JSON), not a
pattern of the path. A 405 answer must list every method the path is served with, while
Starlette names only the first route whose path matched.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Sequence

from starlette.routing import BaseRoute, Match
from starlette.types import Scope

#: The methods a 405 may list.
METHODS = ("GET", "HEAD", "POST", "PUT", "PATCH", "DELETE", "OPTIONS")


def routed_endpoint(routes: Sequence[BaseRoute], scope: Scope) -> Callable | None:
    """The endpoint the router calls for this request: that of the first route that matches
    path and method, as Starlette routes. ``routes`` are plain routes (each with its own
    ``endpoint``), in routing order. None when none matches."""
    for route in routes:
        if route.matches(scope)[0] is Match.FULL:
            return getattr(route, "endpoint", None)
    return None


def body_limiter(routes: Sequence[BaseRoute], max_body: int, max_upload: int,
                 upload_endpoints: Collection[Callable]) -> Callable[[Scope], int]:
    """A function giving a request's body limit in bytes: ``max_upload`` when the request
    reaches one of ``upload_endpoints`` through ``routes``, ``max_body`` otherwise (unknown
    paths and wrong methods included).

    ``routes`` is read at each call, so routes added after this is made count too."""
    def limit(scope: Scope) -> int:
        return max_upload if routed_endpoint(routes, scope) in upload_endpoints else max_body

    return limit


def allowed_methods(routes: Sequence[BaseRoute], scope: Scope) -> list[str]:
    """Every method (of ``METHODS``) that some route serves the request's path with."""
    return [m for m in METHODS
            if any(r.matches({**scope, "method": m})[0] is Match.FULL for r in routes)]
