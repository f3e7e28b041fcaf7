"""Height maps written by surface-metrology instruments, read into one :class:`HeightMap`.

:func:`read_height_map` picks the reader by the file's suffix:

======================  ====================================================================
suffix                  reader
======================  ====================================================================
``.npy``                numpy array, values in µm, no pixel size
``.tif``, ``.tiff``     float TIFF through tifffile; pixel size from OME-XML, ImageJ
                        metadata (``unit`` + resolution) or centimetre resolution tags;
                        values in µm unless ImageJ ``vunit`` names another length unit
``.x3p``                ISO 25178-72, :func:`microfacet.io.x3p.read_x3p` (metres → µm)
anything else           SurfaceTopography's ``read_topography`` (Alicona ``.al3d``,
                        Sensofar ``.plu``/``.plux``, Digital Surf ``.sur``/``.mnt``,
                        Keyence ``.vk3``/``.vk4``/``.vk6``, Bruker/Zygo ``.opd``/``.datx``,
                        Olympus ``.lext``, ...): the optional extra
                        ``pip install "microfacet[instruments]"``
======================  ====================================================================

Units, pixel size and orientation come from the file. Every map comes back in image
orientation, ``[row = y, col = x]`` (SurfaceTopography indexes ``[x, y]``: its heights are
transposed), float32 µm with NaN where the instrument recorded no value. A map that sits far
from zero (an Alicona file measures heights from the instrument's reference, ~76 mm) comes
back minus its median, recorded in ``offset_um``: float32 then keeps its resolution.

Examples
--------
>>> import tempfile, pathlib
>>> p = pathlib.Path(tempfile.mkdtemp()) / "h.npy"
>>> np.save(p, np.array([[1.0, 2.0], [3.0, np.nan]]))
>>> m = read_height_map(p)
>>> m.height_um.dtype, m.height_um.shape, m.pixel_size_um, m.source
(dtype('float32'), (2, 2), None, 'npy (µm)')
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from .tiff_meta import scale_of, unit_um
from .x3p import HeightMap, read_x3p

tifffile = load("tifffile")
SurfaceTopography = load("SurfaceTopography")

__all__ = ["read_height_map"]

#: Suffixes read without SurfaceTopography.
NATIVE_SUFFIXES = (".npy", ".tif", ".tiff", ".x3p")
_EXTRA = 'pip install "microfacet[instruments]"'


def read_height_map(path) -> HeightMap:
    """Read an instrument's height map (see the module's table of formats).

    Parameters
    ----------
    path : path-like

    Returns
    -------
    HeightMap
        ``height_um`` float32 (H, W), image orientation, NaN where undefined;
        ``pixel_size_um`` ``(y, x)`` in µm or None; ``source`` naming format and instrument;
        ``offset_um`` the median removed from a map far from zero (else 0).

    Raises
    ------
    InputError
        One line naming the file: missing, unreadable, not a 2-D height map, of unknown
        units, or of a format that needs SurfaceTopography when it is not installed.
    """
    path = Path(path)
    where = one_line(path)
    if not path.is_file():
        raise InputError(f"{where}: file not found")
    suffix = path.suffix.lower()
    if suffix == ".npy":
        m = _read_npy(path, where)
    elif suffix in (".tif", ".tiff"):
        m = _read_tiff(path, where)
    elif suffix == ".x3p":
        m = read_x3p(path)
    else:
        m = _read_surface_topography(path, where)
    h = np.array(m.height_um, dtype=np.float64)
    if h.ndim != 2 or min(h.shape) < 1:
        raise InputError(f"{where}: expected a 2-D height map, got shape {h.shape}")
    h[~np.isfinite(h)] = np.nan
    offset = 0.0
    if np.isfinite(h).any():
        med = float(np.nanmedian(h))
        if abs(med) > float(np.nanmax(h) - np.nanmin(h)):  # far from zero: float32 would
            offset = med                                   # lose the relief's resolution
            h -= offset
    px = m.pixel_size_um
    if px is not None and not (np.all(np.isfinite(px)) and min(px) > 0):
        raise InputError(f"{where}: the file gives an invalid pixel size {px!r}")
    return HeightMap(height_um=h.astype(np.float32), pixel_size_um=None if px is None else
                     (float(px[0]), float(px[1])), source=m.source, offset_um=offset)


# ------------------------------------------------------------------------------------ formats


def _read_npy(path, where) -> HeightMap:
    try:
        a = np.load(path, allow_pickle=False)
    except (OSError, ValueError) as exc:
        raise InputError(f"{where}: not a readable .npy file ({one_line(exc)})") from None
    if not isinstance(a, np.ndarray) or not (np.issubdtype(a.dtype, np.floating)
                                             or np.issubdtype(a.dtype, np.integer)):
        raise InputError(f"{where}: .npy must hold a numeric height map in µm")
    return HeightMap(a, None, "npy (µm)")


def _read_tiff(path, where) -> HeightMap:
    try:
        with tifffile.TiffFile(path) as tf:
            page = tf.pages[0]
            img = page.asarray()
            pixel = scale_of(tf, one_line(Path(path).name)).pixel_size_yx_um
            meta = (tf.imagej_metadata or {}) if tf.is_imagej else {}
            kind = "OME-TIFF" if tf.is_ome else "ImageJ TIFF" if tf.is_imagej else "TIFF"
    except Exception as exc:  # tifffile raises assorted errors on corrupt files
        raise InputError(f"{where}: unreadable TIFF ({one_line(exc)})") from None
    img = np.squeeze(img)
    if img.ndim != 2:
        raise InputError(f"{where}: TIFF image of shape {img.shape} is not one 2-D map")
    if not np.issubdtype(img.dtype, np.floating):
        raise InputError(f"{where}: TIFF samples are {img.dtype}; a height map must be a "
                         f"floating-point TIFF (values in µm)")
    vunit = meta.get("vunit")
    scale = 1.0 if vunit is None else unit_um(vunit)
    if scale is None:
        raise InputError(f"{where}: ImageJ value unit {one_line(vunit)!r} is not a length")
    h = img.astype(np.float64) * scale if scale != 1.0 else img
    return HeightMap(h, pixel, f"{kind} ({'µm' if vunit is None else one_line(vunit)})")


def _surface_topography_missing(exc) -> bool:
    top = (exc.name or "").split(".")[0]
    return top == SurfaceTopography.__name__.split(".")[0]


def _read_surface_topography(path, where) -> HeightMap:
    try:
        reader = SurfaceTopography.open_topography(str(path))
        topo = reader.topography()
        fmt = reader.format()
    except ModuleNotFoundError as exc:
        if _surface_topography_missing(exc):
            raise InputError(f"{where}: reading {path.suffix or 'this'} files needs "
                             f"SurfaceTopography: {_EXTRA}") from None
        raise InputError(f"{where}: reading it needs the package {exc.name!r}") from None
    except Exception as exc:  # SurfaceTopography raises its own errors per format
        raise InputError(f"{where}: not a height map that microfacet or SurfaceTopography "
                         f"can read ({type(exc).__name__}: {one_line(exc)[:200]})") from None
    if topo.dim != 2 or not topo.is_uniform:
        raise InputError(f"{where}: holds a line scan or a non-uniform grid, not a height map")
    factor = unit_um(topo.unit)
    if factor is None:
        raise InputError(f"{where}: the file records no length unit for its heights "
                         f"({topo.unit!r})")
    h = np.ma.filled(np.ma.asarray(topo.heights(), dtype=np.float64), np.nan).T * factor
    sx, sy = topo.pixel_size
    info = topo.info.get("instrument", {}) if isinstance(topo.info, dict) else {}
    names = [str(info[k]) for k in ("name", "vendor", "software") if info.get(k)]
    source = f"{fmt} ({', '.join(names)})" if names else str(fmt)
    return HeightMap(h, (float(sy) * factor, float(sx) * factor), one_line(source))
