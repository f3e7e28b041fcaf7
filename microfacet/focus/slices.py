"""The slices a height from focus reads: a :class:`~microfacet.io.stack.Stack`, or a sequence
of images with their heights, behind one loader (decoded one at a time, float32).

Examples
--------
>>> import numpy as np
>>> src = slice_source([np.zeros((4, 5), np.uint8)] * 3, z_um=[0.0, 2.0, 1.0])
>>> src.n, src.shape, src.channels, src.load(1).dtype.name
(3, (4, 5), 1, 'float32')
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from ..core.errors import InputError
from ..io.images import convert_samples
from ..io.stack import Stack

__all__ = ["SliceSource", "slice_source"]


@dataclass(frozen=True)
class SliceSource:
    """Slices in file order: their heights ``z_um`` (float64), number, ``(H, W)``, channels
    (1 or 3) and ``load(file_index)``, the slice as float32 (integers scaled to [0, 1])."""

    z_um: np.ndarray
    n: int
    shape: tuple
    channels: int
    load: Callable[[int], np.ndarray]


def slice_source(source, z_um=None) -> SliceSource:
    """The :class:`SliceSource` of a Stack (``z_um`` not allowed: it has its own) or of a
    sequence of (H, W) or (H, W, 3) images with their heights ``z_um`` (required; finite, no
    duplicates, one per image)."""
    if isinstance(source, Stack):
        return _stack_slices(source, z_um)
    return _image_slices(source, z_um)


def _stack_slices(stack: Stack, z_um) -> SliceSource:
    if not stack.has_slices:
        raise InputError(f"{stack.path / 'stack.json'}: the stack has no slices (export "
                         f"only); height from focus needs slices")
    if z_um is not None:
        raise ValueError("z_um must not be given with a Stack (it has its own)")

    def load(i):
        return stack.read_slice(i, np.float32)

    return SliceSource(np.asarray(stack.z_um, dtype=np.float64), stack.n_slices,
                       tuple(stack.shape), stack.channels, load)


def _image_slices(images, z_um) -> SliceSource:
    if z_um is None:
        raise ValueError("z_um is required when source is a sequence of images")
    z = np.asarray(z_um, dtype=np.float64).ravel()
    if not np.all(np.isfinite(z)):
        raise ValueError("z_um must be finite")
    if np.unique(z).size != z.size:
        raise ValueError("z_um must not hold duplicate heights")
    if len(images) != z.size:
        raise ValueError(f"z_um has {z.size} values but there are {len(images)} images")
    first = np.asarray(images[0])
    if first.ndim not in (2, 3) or (first.ndim == 3 and first.shape[2] != 3):
        raise ValueError(f"images must be (H, W) or (H, W, 3), got {first.shape}")

    def load(i):
        img = np.asarray(images[i])
        if img.shape != first.shape:
            raise ValueError(f"image {i} has shape {img.shape}, expected {first.shape}")
        if img.dtype in (np.uint8, np.uint16):
            return convert_samples(img, np.float32)
        return img.astype(np.float32, copy=False)

    return SliceSource(z, z.size, first.shape[:2], (3 if first.ndim == 3 else 1), load)
