"""Microscope vendors' z-stack files: Zeiss ZEN ``.czi`` (optional extra ``microscopes``).

A ``.czi`` file is read as a stack of its Z planes (channel 0, time 0, scene 0 unless
``series`` names another scene) through ``pylibCZIrw``, Zeiss' own reader (LGPL-3, on PyPI):
the pixel size and the z step come from the file's ``Scaling/Items/Distance`` (metres), the
channel order from its pixel type (``Bgr24``/``Bgr48`` are turned into RGB, ``Gray8``/``Gray16``
are grey), the bit depth likewise. A value given by ``stack.json`` or the command line wins
over the file's, as for TIFF metadata.

The reader keeps the file open while the planes are read (one plane decoded at a time).
"""

from __future__ import annotations

import contextlib
import threading
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from .images import ImageInfo
from .tiff_meta import TiffScale

pyczi = load("pylibCZIrw.czi")

__all__ = ["CZI_SUFFIXES", "CziPlanes", "czi_headers", "czi_scale", "is_czi"]

#: File suffixes read by this module.
CZI_SUFFIXES = (".czi",)
#: pylibCZIrw's pixel types: numpy dtype and channels (BGR types are reversed to RGB).
_PIXEL_TYPES = {"Gray8": (np.uint8, 1), "Gray16": (np.uint16, 1), "Bgr24": (np.uint8, 3),
                "Bgr48": (np.uint16, 3)}
_INSTALL = 'reading .czi needs the extra "microscopes": pip install "microfacet[microscopes]"'


def is_czi(path) -> bool:
    """True for a ``.czi`` file name (any case)."""
    return Path(path).suffix.lower() in CZI_SUFFIXES


@dataclass(frozen=True)
class _Layout:
    n_planes: int
    info: ImageInfo
    box: tuple


def _enter(path: Path, where: str):
    """``(context manager, reader)`` of an opened CZI; InputError naming the file."""
    try:
        cm = pyczi.open_czi(str(path))
        return cm, cm.__enter__()
    except ModuleNotFoundError:
        raise InputError(f"{where} ({one_line(path.name)}): {_INSTALL}") from None
    except Exception as exc:
        raise InputError(f"{where} ({one_line(path.name)}): unreadable CZI ({exc})") from None


@contextlib.contextmanager
def _opened(path: Path, where: str):
    cm, reader = _enter(path, where)
    try:
        yield reader
    finally:
        cm.__exit__(None, None, None)


def _layout(reader, path: Path, where: str) -> _Layout:
    bbox = reader.total_bounding_box
    n = bbox.get("Z", (0, 1))[1] - bbox.get("Z", (0, 1))[0]
    kinds = set(reader.pixel_types.values())
    kind = next(iter(kinds)) if len(kinds) == 1 else None
    if kind not in _PIXEL_TYPES:
        raise InputError(f"{where} ({one_line(path.name)}): CZI pixel type "
                         f"{sorted(kinds)} is not supported (Gray8/16, Bgr24/48)")
    dtype, channels = _PIXEL_TYPES[kind]
    h = bbox["Y"][1] - bbox["Y"][0]
    w = bbox["X"][1] - bbox["X"][0]
    return _Layout(int(n), ImageInfo((int(h), int(w)), np.dtype(dtype), channels),
                   (bbox["X"][0], bbox["Y"][0], int(w), int(h)))


def czi_headers(path: Path, where: str, add) -> bool:
    """``add(name, where, info)`` for every Z plane of the CZI (cf. the multi-page TIFF's
    :func:`~microfacet.io.images.read_tiff_headers`); True (every plane is alike)."""
    with _opened(path, where) as r:
        lay = _layout(r, path, where)
    for k in range(lay.n_planes):
        add(f"{one_line(path)} plane {k}", f"{where} ({one_line(path.name)} plane {k})",
            lay.info)
    return True


def czi_scale(path: Path, where: str) -> TiffScale:
    """Pixel size and z step from the CZI's ``Scaling/Items/Distance`` (metres → µm)."""
    with _opened(path, where) as r:
        md = r.metadata
    try:
        items = md["ImageDocument"]["Metadata"]["Scaling"]["Items"]["Distance"]
        items = items if isinstance(items, list) else [items]
        dist = {d["@Id"]: float(d["Value"]) * 1e6 for d in items}
    except (KeyError, TypeError, ValueError):
        dist = {}
    ok = {k: v for k, v in dist.items() if np.isfinite(v) and v > 0}
    yx = (ok.get("Y", ok["X"]), ok["X"]) if "X" in ok else None
    return TiffScale(yx, ok.get("Z"), f"CZI metadata of {one_line(Path(path).name)}")


class CziPlanes:
    """One ``.czi`` kept open while its Z planes are read (thread-safe); the interface of
    :class:`~microfacet.io.images.MultiPageTiff`."""

    def __init__(self, path: Path, uniform: bool = True):
        self.path = Path(path)
        self._cm = self._reader = self._layout = None
        self._lock = threading.Lock()

    def read(self, index: int, where: str, channels: int) -> np.ndarray:
        with self._lock:
            if self._reader is None:
                # the context manager is kept: it closes the file when it is freed
                self._cm, self._reader = _enter(self.path, where)
                self._layout = _layout(self._reader, self.path, where)
            try:
                img = self._reader.read(plane={"Z": int(index), "C": 0, "T": 0},
                                        roi=self._layout.box)
            except Exception as exc:
                raise InputError(f"{where}: cannot decode CZI plane ({exc})") from None
        img = np.asarray(img)
        if img.ndim == 3 and img.shape[-1] == 3:
            img = img[..., ::-1]                        # BGR → RGB
        elif img.ndim == 3:
            img = img[..., 0]
        img = np.ascontiguousarray(img)
        if channels == 1 and img.ndim == 3:
            img = img[..., 1]
        return img

    def close(self):
        with self._lock:
            if self._cm is not None:
                self._cm.__exit__(None, None, None)
                self._cm = self._reader = None
