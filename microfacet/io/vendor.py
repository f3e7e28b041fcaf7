"""Microscope vendors' z-stack files: Zeiss ZEN ``.czi`` and Leica LAS X ``.lif`` (optional
extra ``microscopes``).

A ``.czi`` file is read as a stack of its Z planes (channel 0, time 0, scene 0 unless
``series`` names another scene) through ``pylibCZIrw``, Zeiss' own reader (LGPL-3, on PyPI):
the pixel size and the z step come from the file's ``Scaling/Items/Distance`` (metres), the
channel order from its pixel type (``Bgr24``/``Bgr48`` are turned into RGB, ``Gray8``/``Gray16``
are grey), the bit depth likewise. A value given by ``stack.json`` or the command line wins
over the file's, as for TIFF metadata.

A ``.lif`` file is read through ``liffile`` (BSD-3): its first image with Z, Y and X
dimensions (its series 0); pixel size and z step from the image's ``DimensionDescription``
coordinates (metres), RGB as liffile returns it (Leica stores BGR: it reverses it).

The readers keep the file open while the planes are read (one plane decoded at a time).
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
liffile = load("liffile")

__all__ = ["VENDOR_SUFFIXES", "is_vendor", "vendor_headers", "vendor_planes", "vendor_scale"]

#: File suffixes read by this module.
VENDOR_SUFFIXES = (".czi", ".lif")
#: pylibCZIrw's pixel types: numpy dtype and channels (BGR types are reversed to RGB).
_PIXEL_TYPES = {"Gray8": (np.uint8, 1), "Gray16": (np.uint16, 1), "Bgr24": (np.uint8, 3),
                "Bgr48": (np.uint16, 3)}
_INSTALL = 'reading .czi needs the extra "microscopes": pip install "microfacet[microscopes]"'


def is_vendor(path) -> bool:
    """True for a vendor z-stack file name (``.czi``, ``.lif``; any case)."""
    return Path(path).suffix.lower() in VENDOR_SUFFIXES


def _is_lif(path) -> bool:
    return Path(path).suffix.lower() == ".lif"


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


def vendor_headers(path: Path, where: str, add) -> bool:
    """``add(name, where, info)`` for every Z plane of the file (cf. the multi-page TIFF's
    :func:`~microfacet.io.images.read_tiff_headers`); True (every plane is alike)."""
    if _is_lif(path):
        with _lif_opened(path, where) as (_, im):
            lay = _lif_layout(im, path, where)
    else:
        with _opened(path, where) as r:
            lay = _layout(r, path, where)
    for k in range(lay.n_planes):
        add(f"{one_line(path)} plane {k}", f"{where} ({one_line(path.name)} plane {k})",
            lay.info)
    return True


def vendor_scale(path: Path, where: str) -> TiffScale:
    """Pixel size and z step from the file: the CZI's ``Scaling/Items/Distance``, the LIF
    image's dimension coordinates (metres → µm)."""
    if _is_lif(path):
        return _lif_scale(path, where)
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
        if img.ndim == 3 and img.shape[-1] == 3 and channels == 3:
            img = img[..., ::-1]                        # BGR → RGB
        elif img.ndim == 3:
            img = img[..., 0]                           # a grey plane's one sample
        return np.ascontiguousarray(img)

    def close(self):
        with self._lock:
            if self._cm is not None:
                self._cm.__exit__(None, None, None)
                self._cm = self._reader = None


# ------------------------------------------------------------------------------ Leica .lif
def _lif_enter(path: Path, where: str):
    try:
        f = liffile.LifFile(str(path))
    except ModuleNotFoundError:
        raise InputError(f"{where} ({one_line(path.name)}): "
                         f"{_INSTALL.replace('.czi', '.lif')}") from None
    except Exception as exc:
        raise InputError(f"{where} ({one_line(path.name)}): unreadable LIF ({exc})") from None
    im = next((i for i in f.images if {"Z", "Y", "X"} <= set(i.dims)), None)
    if im is None:
        f.close()
        raise InputError(f"{where} ({one_line(path.name)}): no image with Z, Y and X "
                         "dimensions (a z-stack) in the file")
    return f, im


@contextlib.contextmanager
def _lif_opened(path: Path, where: str):
    f, im = _lif_enter(path, where)
    try:
        yield f, im
    finally:
        f.close()


def _lif_layout(im, path: Path, where: str) -> _Layout:
    extra = [d for d in im.dims if d not in ("Z", "Y", "X", "S")]
    if extra or np.dtype(im.dtype) not in (np.dtype(np.uint8), np.dtype(np.uint16)):
        raise InputError(f"{where} ({one_line(path.name)}): LIF image {im.name!r} of "
                         f"dimensions {''.join(im.dims)} and {im.dtype} is not a single-channel "
                         "8- or 16-bit grey or RGB z-stack")
    channels = 3 if im.sizes.get("S", 1) == 3 else 1
    return _Layout(int(im.sizes["Z"]), ImageInfo((int(im.sizes["Y"]), int(im.sizes["X"])),
                                                 np.dtype(im.dtype), channels), ())


def _lif_scale(path: Path, where: str) -> TiffScale:
    with _lif_opened(path, where) as (_, im):
        step = {}
        for d in "ZYX":
            c = np.asarray(im.coords.get(d, ()), dtype=np.float64)
            if c.size >= 2 and np.isfinite(c[1] - c[0]) and c[1] != c[0]:
                step[d] = abs(float(c[1] - c[0])) * 1e6
    yx = (step.get("Y", step["X"]), step["X"]) if "X" in step else None
    return TiffScale(yx, step.get("Z"), f"LIF metadata of {one_line(path.name)}")


class LifPlanes:
    """One ``.lif`` kept open while the Z planes of its z-stack are read (thread-safe)."""

    def __init__(self, path: Path, uniform: bool = True):
        self.path = Path(path)
        self._file = self._image = None
        self._lock = threading.Lock()

    def read(self, index: int, where: str, channels: int) -> np.ndarray:
        with self._lock:
            if self._file is None:
                self._file, self._image = _lif_enter(self.path, where)
            try:
                img = np.asarray(self._image.frame(Z=int(index)))
            except Exception as exc:
                raise InputError(f"{where}: cannot decode LIF plane ({exc})") from None
        if channels == 1 and img.ndim == 3:
            img = img[..., 0]
        return np.ascontiguousarray(img)

    def close(self):
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = self._image = None


def vendor_planes(path, uniform: bool = True):
    """The plane reader of a vendor file (:class:`CziPlanes` or :class:`LifPlanes`)."""
    return (LifPlanes if _is_lif(path) else CziPlanes)(path, uniform)
