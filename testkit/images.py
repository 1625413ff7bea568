"""Reading the test images: a missing or unreadable file fails loudly instead of giving None."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def read_image(path: str | Path, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """The image at `path` as cv2.imread reads it with `flags`; FileNotFoundError when it cannot be read."""
    img = cv2.imread(str(path), flags)
    if img is None:
        raise FileNotFoundError(f"cannot read an image from {path}")
    return img
