"""Rendered views as the viewer sends them: base64 PNG or JPEG (a "data:" URL prefix allowed)
decoded by OpenCV into grey images (float32, 0..255, rows = y down)."""

from __future__ import annotations

import base64
import binascii
import os
import re

# OpenCV reads its decoder's pixel limit once; keep a view's size sane before it loads.
os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(1 << 25))
# A malformed upload is answered with a message; OpenCV's own log lines would only add noise.
os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")

import cv2  # noqa: E402
import numpy as np  # noqa: E402

from gsgeo.errors import InputError  # noqa: E402

#: The largest view accepted, pixels (a 4K canvas and then some).
MAX_PIXELS = 1 << 25
DATA_URL = re.compile(r"^data:image/[A-Za-z0-9.+-]+;base64,", re.ASCII)


def decode_image(text: str, field: str) -> np.ndarray:
    """A grey image (H, W) float32 of a base64 PNG or JPEG; InputError naming ``field``."""
    body = DATA_URL.sub("", text.strip(), count=1)
    try:
        raw = base64.b64decode(body, validate=True)
    except (binascii.Error, ValueError):
        raise InputError("is not base64 (PNG or JPEG bytes, a data: URL prefix allowed)",
                         field=field) from None
    if len(raw) < 8 or not (raw.startswith(b"\x89PNG") or raw.startswith(b"\xff\xd8")):
        raise InputError("is not a PNG or JPEG image", field=field)
    try:
        img = cv2.imdecode(np.frombuffer(raw, dtype=np.uint8), cv2.IMREAD_GRAYSCALE)
    except cv2.error:
        img = None
    if img is None or img.ndim != 2 or img.size == 0:
        raise InputError("cannot be decoded as a PNG or JPEG image (truncated or too large?)",
                         field=field)
    if img.size > MAX_PIXELS:
        raise InputError(f"has {img.size} pixels, more than the {MAX_PIXELS} accepted",
                         field=field)
    scale = 1.0 / 257.0 if img.dtype == np.uint16 else 1.0
    return (img.astype(np.float32) * np.float32(scale))


def encode_png(img: np.ndarray) -> str:
    """Base64 PNG of a grey or BGR image (uint8, or float clipped to 0..255)."""
    a = np.clip(np.asarray(img), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".png", a)
    if not ok:
        raise InputError("the image cannot be encoded as PNG")
    return base64.b64encode(buf.tobytes()).decode("ascii")
