"""Rendered views as the viewer sends them: base64 PNG or JPEG (a "data:" URL prefix allowed)
decoded by OpenCV into grey images (float32, 0..255, rows = y down).

A view is read in two steps, so that its size is known before any pixel is: ``image_header``
(the bytes and the width and height its PNG or JPEG header states, read by Pillow without
decoding) and ``decode_header`` (OpenCV's decoder, grey). The caller checks the pixel budget
between them: a PNG of a few kilobytes may state 30 000 x 30 000 pixels (a decompression
bomb), and it must be refused without allocating them.
"""

from __future__ import annotations

import base64
import binascii
import io
import os
import re
from dataclasses import dataclass

# OpenCV reads its decoder's pixel limit once; keep a view's size sane before it loads.
os.environ.setdefault("OPENCV_IO_MAX_IMAGE_PIXELS", str(1 << 25))
# A malformed upload is answered with a message; OpenCV's own log lines would only add noise.
os.environ.setdefault("OPENCV_LOG_LEVEL", "OFF")

import cv2  # noqa: E402
import numpy as np  # noqa: E402
import PIL.Image  # noqa: E402

from gsgeo.errors import InputError  # noqa: E402

#: The pixels of the two views of one match together (reference and target). Auto-aim sends a
#: reference crop of at most 512 x 512 about the click and a target crop about the epipolar
#: segment, within the canvas (CSS pixels): a 4K canvas (3840 x 2160) beside a 1024 x 1024
#: reference fits. Decoded, a pixel costs 5 bytes (grey uint8, then float32).
MAX_MATCH_PIXELS = 3840 * 2160 + 1024 * 1024
#: The largest single view accepted anywhere (OpenCV's decoder is held to it too).
MAX_PIXELS = MAX_MATCH_PIXELS
DATA_URL = re.compile(r"^data:image/[A-Za-z0-9.+-]+;base64,", re.ASCII)


@dataclass(frozen=True)
class ImageHeader:
    """A view's encoded bytes and the size its header states (pixels), not yet decoded."""

    raw: bytes
    width: int
    height: int
    field: str

    @property
    def pixels(self) -> int:
        return self.width * self.height


def image_header(text: str, field: str) -> ImageHeader:
    """The bytes of a base64 PNG or JPEG and the width and height its header states, read
    without decoding a pixel; InputError naming ``field`` when it is not base64, not a PNG
    or JPEG, its header is unreadable, or it states more than MAX_PIXELS pixels."""
    body = DATA_URL.sub("", text.strip(), count=1)
    try:
        raw = base64.b64decode(body, validate=True)
    except (binascii.Error, ValueError):
        raise InputError("is not base64 (PNG or JPEG bytes, a data: URL prefix allowed)",
                         field=field) from None
    if len(raw) < 8 or not (raw.startswith(b"\x89PNG") or raw.startswith(b"\xff\xd8")):
        raise InputError("is not a PNG or JPEG image", field=field)
    try:  # Image.open reads the header only; nothing is decoded until .load()
        with PIL.Image.open(io.BytesIO(raw), formats=("PNG", "JPEG")) as im:
            width, height = (int(v) for v in im.size)
    except Exception:  # noqa: BLE001 (any failure of Pillow's parser on untrusted bytes)
        raise InputError("has no readable PNG or JPEG header (truncated?)", field=field
                         ) from None
    head = ImageHeader(raw, width, height, field)
    if width < 1 or height < 1:
        raise InputError(f"is {width}x{height} px: empty", field=field)
    if head.pixels > MAX_PIXELS:
        raise InputError(f"is {width}x{height} px ({head.pixels} pixels), more than the "
                         f"{MAX_PIXELS} accepted; send a crop", field=field)
    return head


def check_budget(heads: list[ImageHeader], budget: int) -> None:
    """InputError naming the view that takes ``heads`` (in order) over ``budget`` pixels
    together."""
    total = 0
    for h in heads:
        total += h.pixels
        if total > budget:
            raise InputError(
                f"is {h.width}x{h.height} px: with the views before it {total} pixels, more "
                f"than the {budget} a request may send (crops: at most 512 x 512 about the "
                "click, and the epipolar segment's box)", field=h.field)


def decode_header(head: ImageHeader, colour: bool = False) -> np.ndarray:
    """The grey image (H, W) float32 of a checked header, or with ``colour`` its BGR image
    (H, W, 3); grey levels 0-255 either way. InputError when the bytes do not decode to the
    size the header states."""
    flag = cv2.IMREAD_COLOR if colour else cv2.IMREAD_GRAYSCALE
    try:
        img = cv2.imdecode(np.frombuffer(head.raw, dtype=np.uint8), flag)
    except cv2.error:
        img = None
    if img is None or img.ndim != (3 if colour else 2) or img.size == 0:
        raise InputError("cannot be decoded as a PNG or JPEG image (truncated?)",
                         field=head.field)
    if img.shape[:2] != (head.height, head.width):
        raise InputError(f"decodes to {img.shape[1]}x{img.shape[0]} px, not the "
                         f"{head.width}x{head.height} of its header", field=head.field)
    scale = 1.0 / 257.0 if img.dtype == np.uint16 else 1.0
    return img.astype(np.float32) * np.float32(scale)


def decode_image(text: str, field: str) -> np.ndarray:
    """A grey image (H, W) float32 of a base64 PNG or JPEG of at most MAX_PIXELS pixels
    (checked on its header first); InputError naming ``field``."""
    return decode_header(image_header(text, field))


def encode_png(img: np.ndarray) -> str:
    """Base64 PNG of a grey or BGR image (uint8, or float clipped to 0..255)."""
    a = np.clip(np.asarray(img), 0, 255).astype(np.uint8)
    ok, buf = cv2.imencode(".png", a)
    if not ok:
        raise InputError("the image cannot be encoded as PNG")
    return base64.b64encode(buf.tobytes()).decode("ascii")
