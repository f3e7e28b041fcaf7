"""Picture of every synthetic preset: all-in-focus truth, one defocused slice, truth maps.

Writes ``out/presets.jpg`` (one row per preset: noise-free sharp image, the middle slice,
height, facet tilt and oxide thickness with their ranges printed; ``--docs`` copies it to
docs/img/presets.jpg) and tabulates each preset's generation time, visible and clipped
fractions, thickness range and median tilt.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="gallery-presets",
    question="What does each synthetic preset look like, and what does it hold (visible, "
             "clipped, thickness, tilt)?",
    doc=("docs/synthetic-stacks.md", "gallery-presets"),
    run_time="10 s",
    quick_time="7 s",
    options={"size": (256, "image side, px"), "slices": (16, "slices per stack")},
    doc_files={"presets.jpg": "docs/img/presets.jpg"},
)


def _map(a, lo, hi):
    import cv2

    v = np.clip((a - lo) / max(hi - lo, 1e-9), 0, 1)
    return cv2.applyColorMap((v * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)


def _label(img, text):
    import cv2

    img = img.copy()
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def run(*, quick: bool, out: Path, size=256, slices=16) -> str:
    import cv2

    from microfacet.forward.synth import PRESETS, generate_stack, preset

    if quick:
        size, slices = min(size, 64), min(slices, 6)
    rows, table = [], []
    work = out / "stacks"
    for name in PRESETS:
        p = preset(name, seed=1, height_px=size, width_px=size, n_slices=slices)
        r = generate_stack(work / name, p, overwrite=True)
        t = work / name / "truth"
        h, tilt, d = (np.load(t / f"{f}.npy") for f in ("height_um", "tilt_deg", "thickness_nm"))
        vis, clip = np.load(t / "visible.npy"), np.load(t / "clipped.npy")
        sharp = cv2.imread(str(t / "all_in_focus.png"))
        sl = cv2.imread(str(work / name / "slices" / f"{p.n_slices // 2:03d}.png"),
                        cv2.IMREAD_COLOR)
        if sl.dtype != np.uint8:
            sl = (sl / 257).astype(np.uint8)
        panels = [
            _label(sharp, f"{name}: truth image"),
            _label(sl, f"slice {p.n_slices // 2} of {p.n_slices}"),
            _label(_map(h, h.min(), h.max()), f"height {h.min():.1f}..{h.max():.1f} um"),
            _label(_map(tilt, 0, 30), "tilt 0..30 deg"),
            _label(_map(d, d.min(), d.max()), f"thickness {d.min():.0f}..{d.max():.0f} nm"),
        ]
        gap = np.full((size, 4, 3), 255, np.uint8)
        rows.append(np.hstack([x for pnl in panels for x in (pnl, gap)][:-1]))
        table.append([name, f"{r.timings_s['total']:.2f}", f"{vis.mean():.2f}",
                      f"{clip.mean():.3f}", f"{d.min():.0f}-{d.max():.0f}",
                      f"{np.median(tilt):.1f}"])
        note(" | ".join(table[-1]))
    shutil.rmtree(work, ignore_errors=True)
    sep = np.full((4, rows[0].shape[1], 3), 255, np.uint8)
    cv2.imwrite(str(out / "presets.jpg"), np.vstack([x for r in rows for x in (r, sep)][:-1]),
                [cv2.IMWRITE_JPEG_QUALITY, 70])
    note(f"wrote {out / 'presets.jpg'}")
    return md_table(["preset", "generation (s)", "visible", "clipped", "thickness (nm)",
                     "tilt median (deg)"], table)
