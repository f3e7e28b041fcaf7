"""The height folder of ``microfacet height`` (format ``microfacet-height/1``): the one module
that writes it.

The folder holds ``height_um.npy`` (float32, NaN where unreliable), ``normals.npy`` (float32
H×W×3, z up), ``reliability_db.npy`` + ``reliability.png``, ``all_in_focus.png``, a
``height.png`` preview and ``height.json`` (inputs, parameters, statistics, timings, the
format and the files, :data:`HEIGHT_FILES`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..core.lazy import load
from .images import write_image

cv2 = load("cv2")

__all__ = ["HEIGHT_FILES", "HeightMaps", "write_height_folder"]

#: ``format`` of ``height.json`` (how :func:`microfacet.io.outdir.output_kind` knows it).
HEIGHT_FORMAT = "microfacet-height/1"
#: The files of a height folder and what they hold (recorded in ``height.json``).
HEIGHT_FILES = {
    "height_um.npy": "float32 HxW height in µm, NaN where unreliable",
    "normals.npy": "float32 HxWx3 unit normals (x right, y up, z up)",
    "all_in_focus.png": "composite of each pixel's sharpest slice",
    "reliability_db.npy": "float32 HxW reliability in dB",
    "reliability.png": "reliability 0..40 dB mapped to 0..255",
    "height.png": "viridis preview of the height (0.5-99.5 percentile), NaN black",
}


@dataclass
class HeightMaps:
    """What a height folder holds besides ``height.json``: the height (µm, NaN where
    unreliable), the normals, the reliability (dB), the all-in-focus image in [0, 1] and the
    bit depth to write it with."""

    height_um: np.ndarray
    normals: np.ndarray
    reliability_db: np.ndarray
    all_in_focus: np.ndarray
    bit_depth: int = 8


def write_height_folder(folder, maps: HeightMaps, summary: dict) -> None:
    """Write the files of :data:`HEIGHT_FILES` and ``height.json`` (``summary`` with the
    ``format`` and ``files`` keys set) into the existing ``folder`` (normally the temporary
    folder of an :class:`~microfacet.io.outdir.OutputFolder`)."""
    folder = Path(folder)
    np.save(folder / "height_um.npy", maps.height_um.astype(np.float32))
    np.save(folder / "normals.npy", maps.normals.astype(np.float32))
    np.save(folder / "reliability_db.npy", maps.reliability_db.astype(np.float32))
    write_image(folder / "all_in_focus.png", maps.all_in_focus, bit_depth=maps.bit_depth)
    rel8 = np.round(np.clip(maps.reliability_db, 0, 40) / 40 * 255).astype(np.uint8)
    write_image(folder / "reliability.png", rel8)
    write_image(folder / "height.png", height_preview(maps.height_um)[..., ::-1])  # BGR → RGB
    text = json.dumps({"format": HEIGHT_FORMAT, **summary, "files": dict(HEIGHT_FILES)},
                      indent=2)
    (folder / "height.json").write_text(text + "\n", encoding="utf-8")


def height_preview(h: np.ndarray) -> np.ndarray:
    """Viridis preview of a height map (0.5-99.5 percentile), NaN black; BGR uint8.

    >>> height_preview(np.array([[0.0, np.nan], [1.0, 2.0]], np.float32))[0, 1].tolist()
    [0, 0, 0]
    """
    ok = np.isfinite(h)
    out = np.zeros(h.shape + (3,), np.uint8)
    if ok.any():
        lo, hi = np.percentile(h[ok], [0.5, 99.5])
        v = np.clip((h - lo) / max(hi - lo, 1e-12), 0, 1)
        v8 = np.where(ok, np.round(v * 255), 0).astype(np.uint8)
        out = cv2.applyColorMap(v8, cv2.COLORMAP_VIRIDIS)
        out[~ok] = 0
    return out
