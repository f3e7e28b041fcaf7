"""Microscope vendors' z-stack files: Zeiss ZEN ``.czi``, Nikon NIS ``.nd2`` and Leica LAS X
``.lif`` (optional extra ``microscopes``).

Each file is read as a stack of the Z planes of one series (``series``, default 0), one plane
decoded at a time while the file is kept open; a value given by ``stack.json`` or the command
line wins over the file's pixel size and z step, as for TIFF metadata.

``.czi``
    Through ``pylibCZIrw``, Zeiss' own reader (LGPL-3): channel 0, time 0; a series is a scene.
    Pixel size and z step from ``Scaling/Items/Distance`` (metres); ``Bgr24``/``Bgr48`` are
    turned into RGB, ``Gray8``/``Gray16`` are grey.
``.nd2``
    Through ``nd2`` (BSD-3): channel 0, time 0; a series is an XY position (the ``P`` loop).
    Pixel size from the picture calibration (µm; square), z step from the Z loop's step;
    three components per channel are RGB in the order NIS stores them.
``.lif``
    Through ``liffile`` (BSD-3): a series is an image with Z, Y and X dimensions, in file
    order; pixel size and z step from its ``DimensionDescription`` (metres); RGB as liffile
    returns it (Leica stores BGR: liffile reverses it).

Examples
--------
>>> is_vendor("stack.ND2"), is_vendor("stack.tif")
(True, False)
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
nd2 = load("nd2")

__all__ = ["VENDOR_SUFFIXES", "VendorPlanes", "is_vendor", "vendor_headers", "vendor_planes",
           "vendor_scale"]

#: File suffixes read by this module.
VENDOR_SUFFIXES = (".czi", ".lif", ".nd2")
#: pylibCZIrw's pixel types: numpy dtype and channels (BGR types are reversed to RGB).
_PIXEL_TYPES = {"Gray8": (np.uint8, 1), "Gray16": (np.uint16, 1), "Bgr24": (np.uint8, 3),
                "Bgr48": (np.uint16, 3)}
_GREY_OR_RGB = (np.dtype(np.uint8), np.dtype(np.uint16))


def is_vendor(path) -> bool:
    """True for a vendor z-stack file name (``.czi``, ``.lif``, ``.nd2``; any case)."""
    return Path(path).suffix.lower() in VENDOR_SUFFIXES


@dataclass(frozen=True)
class _Layout:
    """One series: its number of Z planes, the plane's header, and the format's own address
    of the series (a CZI region, a LIF image, ND2 frame numbers)."""

    n_planes: int
    info: ImageInfo
    address: object


class _Opened:
    """An opened vendor file and its series' layout; ``plane(k)`` decodes Z plane ``k``."""

    kind = ""

    def __init__(self, path: Path, series: int, where: str):
        self.path, self.where = path, f"{where} ({one_line(path.name)})"
        self.handle = self._open()
        try:
            self.layout = self._layout(series)
        except BaseException:
            self.close()
            raise

    def fail(self, what: str, *, param: str | None = None) -> InputError:
        return InputError(f"{self.where}: {what}", param=param)

    def series_error(self, series: int, n: int, unit: str) -> InputError:
        return self.fail(f"series {series} does not exist: the file holds {n} z-stack "
                         f"{unit}{'s' if n != 1 else ''} (series 0 to {n - 1})", param="series")

    def _open(self):
        raise NotImplementedError

    def _layout(self, series: int) -> _Layout:
        raise NotImplementedError

    def scale_um(self) -> dict:
        """``{"Z": step, "Y": size, "X": size}`` in µm, only those the file gives."""
        raise NotImplementedError

    def plane(self, index: int, channels: int) -> np.ndarray:
        raise NotImplementedError

    def close(self):
        raise NotImplementedError


class _Czi(_Opened):
    kind = "CZI"

    def _open(self):
        self._cm = pyczi.open_czi(str(self.path))
        return self._cm.__enter__()

    def _layout(self, series):
        r = self.handle
        kinds = set(r.pixel_types.values())
        kind = next(iter(kinds)) if len(kinds) == 1 else None
        if kind not in _PIXEL_TYPES:
            raise self.fail(f"CZI pixel type {sorted(kinds)} is not supported (Gray8/16, "
                            "Bgr24/48)")
        scenes = dict(r.scenes_bounding_rectangle or {})
        bbox = r.total_bounding_box
        if scenes:
            keys = sorted(scenes)
            if not 0 <= series < len(keys):
                raise self.series_error(series, len(keys), "scene")
            rect = scenes[keys[series]]
            box = (rect.x, rect.y, rect.w, rect.h)
        elif series != 0:
            raise self.series_error(series, 1, "scene")
        else:
            box = (bbox["X"][0], bbox["Y"][0], bbox["X"][1] - bbox["X"][0],
                   bbox["Y"][1] - bbox["Y"][0])
        z0, z1 = bbox.get("Z", (0, 1))
        dtype, channels = _PIXEL_TYPES[kind]
        return _Layout(int(z1 - z0), ImageInfo((int(box[3]), int(box[2])), np.dtype(dtype),
                                               channels), box)

    def scale_um(self):
        try:
            items = self.handle.metadata["ImageDocument"]["Metadata"]["Scaling"]["Items"]
            items = items["Distance"]
            items = items if isinstance(items, list) else [items]
            return {d["@Id"]: float(d["Value"]) * 1e6 for d in items}
        except (KeyError, TypeError, ValueError):
            return {}

    def plane(self, index, channels):
        img = np.asarray(self.handle.read(plane={"Z": int(index), "C": 0, "T": 0},
                                          roi=self.layout.address))
        if img.ndim == 3 and img.shape[-1] == 3 and channels == 3:
            return img[..., ::-1]                       # BGR → RGB
        return img[..., 0] if img.ndim == 3 else img    # a grey plane's one sample

    def close(self):
        self._cm.__exit__(None, None, None)


class _Lif(_Opened):
    kind = "LIF"

    def _open(self):
        return liffile.LifFile(str(self.path))

    def _layout(self, series):
        stacks = [i for i in self.handle.images if {"Z", "Y", "X"} <= set(i.dims)]
        if not stacks:
            raise self.fail("no image with Z, Y and X dimensions (a z-stack) in the file")
        if not 0 <= series < len(stacks):
            raise self.series_error(series, len(stacks), "image")
        im = stacks[series]
        extra = [d for d in im.dims if d not in ("Z", "Y", "X", "S")]
        if extra or np.dtype(im.dtype) not in _GREY_OR_RGB:
            raise self.fail(f"LIF image {im.name!r} of dimensions {''.join(im.dims)} and "
                            f"{im.dtype} is not a single-channel 8- or 16-bit grey or RGB "
                            "z-stack")
        channels = 3 if im.sizes.get("S", 1) == 3 else 1
        return _Layout(int(im.sizes["Z"]), ImageInfo((int(im.sizes["Y"]), int(im.sizes["X"])),
                                                     np.dtype(im.dtype), channels), im)

    def scale_um(self):
        step = {}
        for d in "ZYX":
            c = np.asarray(self.layout.address.coords.get(d, ()), dtype=np.float64)
            if c.size >= 2 and np.isfinite(c[1] - c[0]) and c[1] != c[0]:
                step[d] = abs(float(c[1] - c[0])) * 1e6
        return step

    def plane(self, index, channels):
        img = np.asarray(self.layout.address.frame(Z=int(index)))
        return img[..., 0] if channels == 1 and img.ndim == 3 else img

    def close(self):
        self.handle.close()


class _Nd2(_Opened):
    kind = "ND2"

    def _open(self):
        return nd2.ND2File(str(self.path))

    def _layout(self, series):
        f = self.handle
        sizes = dict(f.sizes)
        if "Z" not in sizes:
            raise self.fail(f"no Z loop (a z-stack) in the file (axes {''.join(sizes)})")
        n_series = sizes.get("P", 1)
        if not 0 <= series < n_series:
            raise self.series_error(series, n_series, "XY position")
        comps = f.components_per_channel
        if np.dtype(f.dtype) not in _GREY_OR_RGB or comps not in (1, 3):
            raise self.fail(f"ND2 of {f.dtype} with {comps} components per channel is not an "
                            "8- or 16-bit grey or RGB z-stack")
        frames = {}
        for seq, idx in enumerate(f.loop_indices):
            if idx.get("P", 0) == series and all(v == 0 for k, v in idx.items()
                                                 if k not in ("Z", "P")):
                frames.setdefault(idx["Z"], seq)
        order = [frames[z] for z in range(sizes["Z"]) if z in frames]
        return _Layout(len(order), ImageInfo((int(sizes["Y"]), int(sizes["X"])),
                                             np.dtype(f.dtype), comps), tuple(order))

    def scale_um(self):
        meta = self.handle.metadata
        vol = meta.channels[0].volume if meta and meta.channels else None
        if vol is None:
            return {}
        return {axis: float(v) for axis, v, ok in zip("XYZ", vol.axesCalibration,
                                                      vol.axesCalibrated) if ok}

    def plane(self, index, channels):
        img = np.asarray(self.handle.read_frame(self.layout.address[int(index)]))
        want = 3 if channels == 3 else 2
        while img.ndim > want:                          # (C, Y, X[, S]): channel 0
            img = img[0]
        return img

    def close(self):
        self.handle.close()


_KINDS = {".czi": _Czi, ".lif": _Lif, ".nd2": _Nd2}


def _open(path, where: str, series: int = 0) -> _Opened:
    """The opened file; InputError naming it (a missing extra, damage, no such series)."""
    path = Path(path)
    kind = _KINDS[path.suffix.lower()]
    try:
        return kind(path, int(series), where)
    except InputError:
        raise
    except ModuleNotFoundError:
        raise InputError(f"{where} ({one_line(path.name)}): reading {path.suffix.lower()} "
                         'needs the extra "microscopes": pip install '
                         '"microfacet[microscopes]"') from None
    except Exception as exc:
        raise InputError(f"{where} ({one_line(path.name)}): unreadable {kind.kind} "
                         f"({one_line(str(exc))})") from None


def vendor_headers(path: Path, where: str, add, series: int = 0) -> bool:
    """``add(name, where, info)`` for every Z plane of the series (cf. the multi-page TIFF's
    :func:`~microfacet.io.images.read_tiff_headers`); True (every plane is alike)."""
    f = _open(path, where, series)
    try:
        lay = f.layout
    finally:
        f.close()
    for k in range(lay.n_planes):
        add(f"{one_line(path)} plane {k}", f"{where} ({one_line(Path(path).name)} plane {k})",
            lay.info)
    return True


def vendor_scale(path: Path, where: str, series: int = 0) -> TiffScale:
    """Pixel size and z step from the file (µm): the CZI's ``Scaling``, the ND2's
    calibration and Z loop, the LIF image's dimension coordinates."""
    f = _open(path, where, series)
    try:
        step = f.scale_um()
    finally:
        f.close()
    ok = {k: v for k, v in step.items() if np.isfinite(v) and v > 0}
    yx = (ok.get("Y", ok["X"]), ok["X"]) if "X" in ok else None
    return TiffScale(yx, ok.get("Z"), f"{f.kind} metadata of {one_line(Path(path).name)}")


class VendorPlanes:
    """One vendor file kept open while the Z planes of one series are read (thread-safe);
    the interface of :class:`~microfacet.io.images.MultiPageTiff`."""

    def __init__(self, path: Path, uniform: bool = True, series: int = 0):
        self.path, self.series = Path(path), int(series)
        self._file = None
        self._lock = threading.Lock()

    def read(self, index: int, where: str, channels: int) -> np.ndarray:
        with self._lock:
            if self._file is None:
                self._file = _open(self.path, where, self.series)
            try:
                img = self._file.plane(int(index), channels)
            except Exception as exc:
                raise InputError(f"{where}: cannot decode {self._file.kind} plane "
                                 f"({one_line(str(exc))})") from None
        return np.ascontiguousarray(img)

    def close(self):
        with self._lock:
            if self._file is not None:
                self._file.close()
                self._file = None

    def __del__(self):  # pragma: no cover - best effort
        with contextlib.suppress(Exception):
            self.close()


def vendor_planes(path, uniform: bool = True, series: int = 0) -> VendorPlanes:
    """The plane reader of a vendor file."""
    return VendorPlanes(path, uniform, series)
