"""Writing RGB or grey images (channels last, RGB order) with OpenCV."""

from __future__ import annotations

import numpy as np

__all__ = ["to_code_values", "write_image"]


def to_code_values(image, *, bit_depth=8):
    """Float image in [0, 1] → uint8 / uint16 code values (clipped, rounded); ints unchanged.

    Examples
    --------
    >>> to_code_values(np.array([0.0, 0.5, 1.2])).tolist()
    [0, 128, 255]
    """
    img = np.asarray(image)
    if img.dtype.kind in "ui":
        return img
    if bit_depth not in (8, 16):
        raise ValueError(f"bit_depth: must be 8 or 16, got {bit_depth!r}")
    top, dtype = (255, np.uint8) if bit_depth == 8 else (65535, np.uint16)
    return np.round(np.clip(np.nan_to_num(img, nan=0.0), 0, 1) * top).astype(dtype)


def write_image(path, image, *, bit_depth=8, params=()):
    """Write an (H, W) grey or (H, W, 3) RGB image; floats are [0, 1] encoded values.

    Raises
    ------
    OSError
        Naming the path, if OpenCV cannot write it.
    """
    import cv2

    img = to_code_values(image, bit_depth=bit_depth)
    if img.ndim == 3:
        img = img[..., ::-1]  # OpenCV writes BGR
    if not cv2.imwrite(str(path), np.ascontiguousarray(img), list(params)):
        raise OSError(f"cannot write {path}")
