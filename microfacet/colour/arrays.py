"""Array checks shared by the colour modules: float dtypes kept, channels last."""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = []


def float_array(x: Any, name: str) -> np.ndarray:
    """``x`` as a float array: float32 stays float32, everything else float64.

    >>> float_array([1, 2], "x").dtype
    dtype('float64')
    """
    a = np.asarray(x)
    if a.dtype == np.float32 or a.dtype == np.float64:
        return a
    if a.dtype.kind in "biuf":
        return a.astype(np.float64)
    raise ValueError(f"{name} must be a numeric array, got dtype {a.dtype}")


def channels(x: Any, name: str, n: int = 3) -> np.ndarray:
    """``x`` as a float array of shape ``(..., n)``; a ValueError names ``name``.

    >>> channels([[1.0, 2.0, 3.0]], "lab").shape
    (1, 3)
    """
    a = float_array(x, name)
    if a.ndim == 0 or a.shape[-1] != n:
        raise ValueError(f"{name} must have shape (..., {n}), got {a.shape}")
    return a
