"""Checks on ids and settings shared by the store's service and the HTTP layer."""

from __future__ import annotations

import re

from gsgeo import limits
from gsgeo.errors import InputError
from gsgeo.jsontypes import JSON

#: Project and scene ids: safe in URLs and file names.
SLUG = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
#: Point, line, polygon and check point ids: any printable text without '/' or '\'
#: (control characters are refused by gsgeo.limits.id_text, before stripping).
MAX_ID_LEN = 100
_BAD_ID_CHARS = re.compile(r"[/\\]")


def slug(value: JSON, field: str) -> str:
    """A project or scene id (SLUG), or InputError about ``field``."""
    if not isinstance(value, str) or not SLUG.match(value):
        raise InputError("must be 1-64 characters of letters, digits, '_', '.', '-' starting "
                         f"with a letter or digit, got {str(value)[:70]!r}", field=field)
    return value


def item_id(value: JSON, field: str) -> str:
    """A point, line, polygon or check point id, stripped of surrounding blanks; InputError
    for a control character (checked before stripping), '/', '\\', '.', '..', or more than
    MAX_ID_LEN characters."""
    v = limits.id_text(value, field).strip()
    if len(v) > MAX_ID_LEN:
        raise InputError(f"longer than {MAX_ID_LEN} characters", field=field)
    if _BAD_ID_CHARS.search(v) or v in (".", ".."):
        raise InputError("must not contain '/' or '\\' nor be '.' or '..'", field=field)
    return v


def sigma_px(value: JSON, field: str = "sigma_px") -> float:
    """The aiming precision in pixels within gsgeo.limits' range (SIGMA_PX_MIN..SIGMA_PX_MAX)."""
    return limits.sigma_px(value, field)
