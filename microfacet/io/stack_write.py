"""Writing focus stacks in the ``microfacet-stack/1`` format: a ``stack.json`` for the images
in a folder (:func:`write_stack_json`, validated by the same checks as
:func:`microfacet.io.stack.read_stack` before it is put in place), or images and their
``stack.json`` (:func:`write_stack`). Both are also importable from :mod:`microfacet.io.stack`,
which owns reading the format.

Examples
--------
>>> import numpy as np, tempfile, pathlib
>>> d = pathlib.Path(tempfile.mkdtemp())
>>> p = write_stack(d / "s", [np.zeros((4, 5), np.uint8)] * 3, z_step_um=1.0, pixel_size_um=0.5)
>>> p.name, sorted(q.name for q in (d / "s" / "slices").iterdir())
('stack.json', ['000.png', '001.png', '002.png'])
"""

from __future__ import annotations

import json
import os
import tempfile
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..core.errors import InputError, one_line
from ..core.lazy import load
from .images import IMAGE_SUFFIXES, write_image
from .jsonfile import read_json
from .limits import Limits
from .stack_checks import FORMAT, find_images, stack_fields

cv2 = load("cv2")
tifffile = load("tifffile")

__all__ = ["write_stack", "write_stack_json"]


# --------------------------------------------------------------------------------------------
# writing


def write_stack_json(folder, *, pixel_size_um=None, slices: Sequence[str] | None = None,
                     tiff: str | None = None, z_um: Sequence[float] | None = None,
                     z_step_um: float | None = None, validate: bool = True,
                     limits: Limits | None = None, **optional) -> Path:
    """Write ``folder/stack.json`` for images that are already there.

    With ``validate`` (the default) the file is written under a temporary name, read back
    and validated as :func:`read_stack` does, and only then renamed to ``stack.json``: an
    invalid stack.json is never left on disk, and an existing one is replaced only by a
    valid one.

    Parameters
    ----------
    folder : str or Path
        The stack folder (must exist).
    pixel_size_um : float or (float, float), optional
        Lateral pixel size on the sample, µm, or ``(y, x)`` for non-square pixels. Omitted
        from the file when None (then the instrument file or the TIFF metadata gives it).
    slices : sequence of str, optional
        Relative image paths, one per slice, in file order. Give this or ``tiff``; when
        neither (nor an export ``height_um``) is given the folder's images are found by
        :func:`find_images`.
    tiff : str, optional
        Relative path of a multi-page TIFF.
    z_um : sequence of float, optional
        Stage height of each slice, µm. Give this or ``z_step_um``.
    z_step_um : float, optional
        Slice *i* is at ``i * z_step_um``.
    validate : bool
        Validate before the file is put in place (raises on any problem, leaving the folder
        as it was). ``False`` writes the keys as given (tests write invalid files so).
    limits : Limits, optional
        As in :func:`read_stack`.
    **optional
        Further keys written as given (``color_space``, ``illuminant``, ``illumination``,
        ``film``, ``substrate``, ``exposure``, ``height_um``, ``image``, or project keys).

    Returns
    -------
    Path
        The path of the written stack.json.

    Raises
    ------
    InputError
        When the folder holds no images to list, or (with ``validate``) the stack is invalid.
    """
    folder = Path(folder)
    if not folder.is_dir():
        raise InputError(f"{one_line(folder)}: not a folder")
    meta: dict = {"format": FORMAT}
    if pixel_size_um is not None:
        meta["pixel_size_um"] = (float(pixel_size_um) if np.ndim(pixel_size_um) == 0
                                 else [float(v) for v in pixel_size_um])
    if slices is None and tiff is None and "height_um" not in optional:
        found = find_images(folder)
        if not found:
            raise InputError(f"{one_line(folder)}: no images ({', '.join(IMAGE_SUFFIXES)}) "
                             f"in the folder to list in stack.json")
        slices, tiff = found.get("slices"), found.get("tiff")
    if slices is not None:
        meta["slices"] = [str(s) for s in slices]
    if tiff is not None:
        meta["tiff"] = str(tiff)
    if z_um is not None:
        meta["z_um"] = [float(v) for v in z_um]
    if z_step_um is not None:
        meta["z_step_um"] = float(z_step_um)
    meta.update(optional)
    out = folder / "stack.json"
    fd, name = tempfile.mkstemp(prefix=".stack.json.", suffix=".tmp", dir=folder)
    tmp = Path(name)
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            fh.write(json.dumps(meta, indent=2) + "\n")
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        if validate:  # exactly the bytes that will be stack.json, named as stack.json
            stack_fields(folder.resolve(), read_json(tmp), out, limits or Limits())
        os.replace(tmp, out)
    finally:
        tmp.unlink(missing_ok=True)
    return out


def write_stack(folder, images, *, pixel_size_um: float, z_um: Sequence[float] | None = None,
                z_step_um: float | None = None, fmt: str = "png", multipage: bool = False,
                validate: bool = True, **optional) -> Path:
    """Write images as a new stack folder with its stack.json.

    Parameters
    ----------
    folder : str or Path
        Created if absent.
    images : iterable of ndarray
        uint8 or uint16 images, (H, W) grey or (H, W, 3) RGB, one per slice; consumed lazily
        (a generator keeps memory at one image).
    pixel_size_um, z_um, z_step_um, **optional
        As in :func:`write_stack_json`.
    fmt : {"png", "tif", "jpg"}
        Slice file type (``multipage=True`` forces one multi-page ``stack.tif``).
    multipage : bool
        Write one multi-page TIFF instead of a slice folder.

    Returns
    -------
    Path
        The stack.json path.
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    if fmt not in ("png", "tif", "jpg"):
        raise ValueError(f"fmt must be 'png', 'tif' or 'jpg', not {fmt!r}")
    names = []
    if multipage:
        with tifffile.TiffWriter(folder / "stack.tif") as tw:
            for img in images:
                img = np.asarray(img)
                tw.write(img, photometric="rgb" if img.ndim == 3 else "minisblack",
                         contiguous=False)
        kw = {"tiff": "stack.tif"}
    else:
        (folder / "slices").mkdir(exist_ok=True)
        for i, img in enumerate(images):
            img = np.asarray(img)
            name = f"slices/{i:03d}.{fmt}"
            if fmt == "tif":
                        tifffile.imwrite(folder / name, img,
                                 photometric="rgb" if img.ndim == 3 else "minisblack")
            else:
                write_image(folder / name, img,
                            params=[cv2.IMWRITE_JPEG_QUALITY, 95] if fmt == "jpg" else ())
            names.append(name)
        kw = {"slices": names}
    return write_stack_json(folder, pixel_size_um=pixel_size_um, z_um=z_um, z_step_um=z_step_um,
                            validate=validate, **kw, **optional)
