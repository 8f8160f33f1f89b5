"""Checks on ids and settings shared by the store's service and the HTTP layer."""

from __future__ import annotations

import math
import re
from typing import Any

from gsgeo.errors import InputError

#: Project and scene ids: safe in URLs and file names.
SLUG = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]{0,63}$")
#: Point, line, polygon and check point ids: any printable text without '/' or '\'.
MAX_ID_LEN = 100
_BAD_ID_CHARS = re.compile(r"[/\\\x00-\x1f\x7f]")


def slug(value: Any, where: str) -> str:
    if not isinstance(value, str) or not SLUG.match(value):
        raise InputError(f"{where}: must be 1-64 characters of letters, digits, '_', '.', '-' "
                         f"starting with a letter or digit, got {str(value)[:70]!r}")
    return value


def item_id(value: Any, where: str) -> str:
    if isinstance(value, bool) or not isinstance(value, (str, int)):
        raise InputError(f"{where}: expected text")
    v = str(value).strip()
    if not v:
        raise InputError(f"{where}: must not be empty")
    if len(v) > MAX_ID_LEN:
        raise InputError(f"{where}: longer than {MAX_ID_LEN} characters")
    if _BAD_ID_CHARS.search(v) or v in (".", ".."):
        raise InputError(f"{where}: must not contain '/', '\\' or control characters")
    return v


def positive(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        raise InputError(f"{where}: expected a finite number")
    if value <= 0:
        raise InputError(f"{where}: must be positive")
    return float(value)
