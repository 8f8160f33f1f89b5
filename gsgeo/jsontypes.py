"""Type names for decoded JSON documents (session files, API bodies, stored records).

``JSON`` is a value as ``orjson.loads`` returns it: dict, list, str, int, float, bool or None.
It is an alias of ``Any`` rather than a recursive union on purpose: every reader of user JSON
checks the shape at run time (``isinstance``) and reports what is wrong with its field path, so
a static union would only force casts after those checks. The name says what the value is.
"""

from __future__ import annotations

from typing import Any, TypeAlias

#: A decoded JSON value (dict, list, str, int, float, bool or None).
JSON: TypeAlias = Any

#: A decoded JSON object (string keys).
JSONObject: TypeAlias = dict[str, Any]
