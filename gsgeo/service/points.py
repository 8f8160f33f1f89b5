"""A point as a request gives it: typed rays and what describes them.

The HTTP layer builds a :class:`PointInput` from its validated body (the rays straight into
gsgeo.measure.Rays); a mapping in the session-JSON shape goes through :func:`point_input`.
Either way the rays are checked once, by Rays.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON, JSONObject
from gsgeo.measure import Rays
from gsgeo.service.measuring import stored_rays

MAX_RAYS = 1000


@dataclass(frozen=True)
class PointInput:
    """A new point: ``rays`` (rendered ECEF), ``id`` (None: the next free P<n>), ``code``,
    ``description``, ``excluded`` 0-based ray indices left out of the solution and
    ``georef_version``, the scene georeference the rays were taken under (None: the current),
    ``provenance`` each ray's ``auto`` / ``score`` members as given (:func:`ray_provenance`)."""

    rays: Rays
    id: str | None = None
    code: str = ""
    description: str = ""
    excluded: list[int] = field(default_factory=list)
    georef_version: int | None = None
    # per ray, how it was aimed as given ({"auto": bool, "score": float} members, see
    # ray_provenance); empty: every ray clicked
    provenance: list[JSONObject] = field(default_factory=list)


def check_ray_count(n: int, field: str = "rays") -> None:
    """InputError unless 2 <= n <= MAX_RAYS."""
    if n < 2:
        raise InputError(f"a point needs at least two rays, got {n}", field=field)
    if n > MAX_RAYS:
        raise InputError(f"more than {MAX_RAYS} rays", field=field)


def rays_input(rays: JSON, field: str = "rays") -> Rays:
    """Session-JSON ray objects -> Rays (2 to MAX_RAYS of them); errors name ``rays[i]...``."""
    if isinstance(rays, Rays):
        check_ray_count(len(rays), field)
        return rays
    if not isinstance(rays, list):
        raise InputError("expected a list of rays", field=field)
    check_ray_count(len(rays), field)
    return stored_rays(rays)


def ray_provenance(rays: JSON, field: str = "rays") -> list[JSONObject]:
    """How each session-JSON ray was aimed, as given: its ``auto`` (true: matched
    automatically, false: clicked; absent: a click) and ``score`` (the match score, a
    number; absent or null: none) members. InputError names ``rays[i].auto`` / ``.score``."""
    if isinstance(rays, Rays) or not isinstance(rays, list):
        return []
    out: list[JSONObject] = []
    for i, r in enumerate(rays):
        got: JSONObject = {}
        if isinstance(r, dict):
            auto, score = r.get("auto"), r.get("score")
            if auto is not None:
                if not isinstance(auto, bool):
                    raise InputError("expected true (matched automatically) or false (clicked)",
                                     field=f"{field}[{i}].auto")
                got["auto"] = auto
            if score is not None:
                if isinstance(score, bool) or not isinstance(score, (int, float)) or \
                        not math.isfinite(score):
                    raise InputError("expected a finite number (the match score) or null",
                                     field=f"{field}[{i}].score")
                got["score"] = float(score)
        out.append(got)
    return out


def with_provenance(rays: list[JSONObject], provenance: Sequence[JSONObject]) -> list[JSONObject]:
    """Session-JSON rays (Rays.to_json) with each ray's provenance members added back."""
    for ray, extra in zip(rays, provenance, strict=False):
        ray.update(extra)
    return rays


def point_input(doc: Mapping[str, Any]) -> PointInput:
    """{id?, code?, description?, rays, excluded?} in the session-JSON shape -> PointInput."""
    code, description = doc.get("code"), doc.get("description")
    return PointInput(rays=rays_input(doc.get("rays")), id=doc.get("id"),
                      code="" if code is None else code,
                      description="" if description is None else description,
                      excluded=list(doc.get("excluded") or []),
                      georef_version=georef_version(doc.get("georef_version")),
                      provenance=ray_provenance(doc.get("rays")))


def georef_version(value: JSON, field: str = "georef_version") -> int | None:
    """A scene georeference version: None or a non-negative integer."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise InputError("expected a non-negative integer (the tileset's "
                         "extras.gsgeo.georef.version)", field=field)
    return int(value)
