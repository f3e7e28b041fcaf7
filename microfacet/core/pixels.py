"""Pixel sizes: one number for square pixels or a ``(y, x)`` pair for non-square ones.

Instrument height maps often have different sample spacings along rows and columns. Every
stage that turns pixels into micrometres takes ``pixel_size_um`` as either form and reads it
through :func:`pixel_size_yx`.

Examples
--------
>>> pixel_size_yx(0.5), pixel_size_yx([0.25, 0.5]), pixel_area_side(0.5)
((0.5, 0.5), (0.25, 0.5), 0.5)
>>> round(pixel_area_side((0.25, 1.0)), 6)
0.5
>>> pixel_size_yx(-1)
Traceback (most recent call last):
...
ValueError: pixel_size_um must be a finite number > 0 or a [y, x] pair of them, got -1
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["pixel_area_side", "pixel_size_yx", "pixel_size_value"]


def pixel_size_yx(value, *, name: str = "pixel_size_um") -> tuple[float, float]:
    """``(y, x)`` pixel size in µm of one number or a ``[y, x]`` pair.

    Raises
    ------
    ValueError
        Naming ``name`` when the value is not one positive finite number or a pair of them.
    """
    bad = ValueError(f"{name} must be a finite number > 0 or a [y, x] pair of them, "
                     f"got {value!r}")
    if isinstance(value, (bool, np.bool_, str, bytes)):
        raise bad
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise bad from None
    if a.shape == ():
        a = np.array([a, a])
    if a.shape != (2,) or not np.all(np.isfinite(a)) or not np.all(a > 0):
        raise bad
    return float(a[0]), float(a[1])


def pixel_area_side(value, *, name: str = "pixel_size_um") -> float:
    """Side in µm of a square pixel of the same area (the geometric mean of y and x): the
    scale for sizes given as lengths in pixels (facet size, window) on non-square pixels."""
    y, x = pixel_size_yx(value, name=name)
    return math.sqrt(y * x)


def pixel_size_value(value, *, name: str = "pixel_size_um"):
    """The JSON form: one float for square pixels, else ``[y, x]``."""
    y, x = pixel_size_yx(value, name=name)
    return x if y == x else [y, x]
