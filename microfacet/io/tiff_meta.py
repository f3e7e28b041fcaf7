"""Physical size in a TIFF's metadata: the one reader of OME-XML, ImageJ and resolution tags.

Used by :mod:`.stack_checks` (pixel size and z spacing of image stacks) and
:mod:`.instruments` (pixel size of float height maps).

Examples
--------
>>> unit_um("nm"), unit_um("\\u00B5m"), unit_um("inch"), unit_um("pixel")
(0.001, 1.0, 25400.0, None)
"""

from __future__ import annotations

import logging
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError, one_line
from ..core.lazy import load

tifffile = load("tifffile")

__all__ = ["TiffScale", "tiff_scale"]

log = logging.getLogger("microfacet.io.stack")

#: Length units written in OME-XML, ImageJ metadata and by SurfaceTopography, in µm (ImageJ
#: escapes µ as \u00B5).
_UNITS_UM = {"µm": 1.0, "μm": 1.0, "um": 1.0, "micron": 1.0, "microns": 1.0,
             "micrometer": 1.0, "micrometre": 1.0, "nm": 1e-3, "nanometer": 1e-3,
             "mm": 1e3, "millimeter": 1e3, "cm": 1e4, "centimeter": 1e4, "m": 1e6,
             "meter": 1e6, "pm": 1e-6, "å": 1e-4, "a": 1e-4, "angstrom": 1e-4,
             "inch": 25400.0}


def unit_um(unit) -> float | None:
    """µm per ``unit`` (``"um"``, ``"micron"``, ``"nm"``, ``"m"``, ImageJ's ``"\\u00B5m"``),
    None if unknown."""
    if unit is None:
        return None
    return _UNITS_UM.get(str(unit).strip().lower().replace("\\u00b5", "µ"))


@dataclass(frozen=True)
class TiffScale:
    """The pixel size and z spacing a TIFF's metadata gives (None where it gives none).

    Attributes
    ----------
    pixel_size_yx_um : tuple of float or None
        ``(y, x)`` size of one pixel on the sample, µm.
    z_step_um : float or None
        Distance between consecutive slices, µm.
    source : str
        Where they were found, for messages (``"ImageJ metadata of stack.tif"``).
    """

    pixel_size_yx_um: tuple[float, float] | None
    z_step_um: float | None
    source: str


def _length_um(value, unit) -> float | None:
    """``value`` in ``unit`` as µm, or None when either is unusable (not an error)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    factor = unit_um(unit)
    if factor is None or not math.isfinite(v) or v <= 0:
        return None
    return v * factor


def _per_unit(tag) -> float | None:
    """Pixels per unit from an X/YResolution tag (a rational ``(num, den)``), or None."""
    value = getattr(tag, "value", None)
    try:
        num, den = value
        ppu = float(num) / float(den)
    except (TypeError, ValueError, ZeroDivisionError):
        return None
    return ppu if math.isfinite(ppu) and ppu > 0 else None


def _ome_scale(xml: str, source: str) -> TiffScale:
    try:
        root = ET.fromstring(xml)
    except ET.ParseError:
        log.warning("%s: OME-XML unreadable; pixel size and z spacing not taken from it", source)
        return TiffScale(None, None, source)
    px = next((e for e in root.iter() if e.tag.rsplit("}", 1)[-1] == "Pixels"), None)
    if px is None:
        return TiffScale(None, None, source)
    size = {a: _length_um(px.get(f"PhysicalSize{a}"), px.get(f"PhysicalSize{a}Unit", "µm"))
            for a in "XYZ"}
    yx = (size["Y"] or size["X"], size["X"]) if size["X"] else None
    return TiffScale(yx, size["Z"], source)


def tiff_scale(path: Path, where: str) -> TiffScale:
    """Pixel size and z spacing from a TIFF's metadata, reading its first page's tags only.

    OME-TIFF: ``PhysicalSizeX/Y/Z`` of the first ``Pixels`` element (with their units, µm by
    default). ImageJ TIFF: ``XResolution``/``YResolution`` (pixels per ``unit``) and
    ``spacing``. Any other TIFF: the resolution tags when ``ResolutionUnit`` is centimetre;
    inch resolutions (72, 96, 300 dpi) are print sizes, never a size on the sample, and are
    ignored.

    Parameters
    ----------
    path : Path
        A TIFF file.
    where : str
        Names the file and key in messages.

    Returns
    -------
    TiffScale

    Raises
    ------
    InputError
        When the file is not a readable TIFF.
    """
    try:
        with tifffile.TiffFile(path) as tf:
            return scale_of(tf, one_line(Path(path).name))
    except InputError:
        raise
    except Exception as exc:  # tifffile raises assorted errors on corrupt files
        raise InputError(f"{where}: unreadable TIFF ({exc})") from None


def scale_of(tf, name: str) -> TiffScale:
    """:func:`tiff_scale` of an open ``tifffile.TiffFile`` (``name`` for the source text),
    for a caller that reads the pixels from the same open file."""
    if tf.is_ome and tf.ome_metadata:
        return _ome_scale(tf.ome_metadata, f"OME metadata of {name}")
    tags = tf.pages[0].tags
    per_x, per_y = _per_unit(tags.get("XResolution")), _per_unit(tags.get("YResolution"))
    if tf.is_imagej:
        ij = tf.imagej_metadata or {}
        unit = ij.get("unit")
        one = _length_um(1.0, unit) if unit is not None else None
        yx = (one / per_y, one / per_x) if one and per_x and per_y else None
        z = _length_um(ij.get("spacing"), unit) if one else None
        return TiffScale(yx, z, f"ImageJ metadata of {name}")
    unit_tag = tags.get("ResolutionUnit")
    if unit_tag is not None and int(unit_tag.value) == 3 and per_x and per_y:
        return TiffScale((1e4 / per_y, 1e4 / per_x), None, f"TIFF resolution tags of {name}")
    return TiffScale(None, None, f"metadata of {name}")
