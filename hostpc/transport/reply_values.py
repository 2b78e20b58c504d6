"""Reply payloads to numpy: float vectors and the images of a `capture_done` frame.

Arrays are numpy float64 (n,); images are uint8 (height, width), checked against the
`ImageInfo` header (raw bytes or PNG); a mismatch is a `ProtocolViolation`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from hostpc.errors import ProtocolViolation
from protocol.measurement_messages import ImageInfo


def _array(values: list[float]) -> np.ndarray:
    return np.asarray(values, dtype=float)


def _floats(values: Any) -> list[float]:
    return [float(v) for v in np.asarray(values, dtype=float).reshape(-1)]


def _decode_image(info: ImageInfo, data: bytes | memoryview) -> np.ndarray:
    if info.encoding == "png":
        import cv2

        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise ProtocolViolation(f"{info.camera} image: PNG cannot be decoded")
    else:
        expected = info.width * info.height
        if memoryview(data).nbytes != expected:
            raise ProtocolViolation(
                f"{info.camera} image: {memoryview(data).nbytes} bytes, expected {expected}"
            )
        image = np.frombuffer(data, dtype=np.uint8).reshape(info.height, info.width)
    if image.shape != (info.height, info.width):
        raise ProtocolViolation(
            f"{info.camera} image has shape {image.shape}, header says "
            f"({info.height}, {info.width})"
        )
    return image
