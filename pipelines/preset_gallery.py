"""Picture of every synthetic preset: all-in-focus truth, one defocused slice, truth maps.

Writes docs/img/presets.jpg (one row per preset: noise-free sharp image, the middle slice,
height, facet tilt and oxide thickness with their ranges printed) and prints the generation
time of each preset.

Run:  python pipelines/preset_gallery.py [--size 192] [--out docs/img/presets.png]
"""

from __future__ import annotations

import tempfile
from pathlib import Path

import cv2
import numpy as np
from _shared import md_header, md_row, parser

from microfacet.forward.synth import PRESETS, generate_stack, preset


def _map(a, lo, hi):
    v = np.clip((a - lo) / max(hi - lo, 1e-9), 0, 1)
    return cv2.applyColorMap((v * 255).astype(np.uint8), cv2.COLORMAP_VIRIDIS)


def _label(img, text):
    img = img.copy()
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (0, 0, 0), 3, cv2.LINE_AA)
    cv2.putText(img, text, (4, 14), cv2.FONT_HERSHEY_SIMPLEX, 0.4, (255, 255, 255), 1, cv2.LINE_AA)
    return img


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", default="docs/img/presets.jpg")
    args = ap.parse_args(argv)
    rows = []
    print(md_header(["preset", "generation (s)", "visible", "clipped", "thickness (nm)",
                     "tilt median (deg)"]))
    with tempfile.TemporaryDirectory() as tmp:
        for name in PRESETS:
            p = preset(name, seed=1, height_px=args.size, width_px=args.size, n_slices=16)
            r = generate_stack(Path(tmp) / name, p)
            t = Path(tmp) / name / "truth"
            h, tilt, d = (np.load(t / f"{f}.npy")
                          for f in ("height_um", "tilt_deg", "thickness_nm"))
            vis, clip = np.load(t / "visible.npy"), np.load(t / "clipped.npy")
            sharp = cv2.imread(str(t / "all_in_focus.png"))
            sl = cv2.imread(str(Path(tmp) / name / "slices" / f"{p.n_slices // 2:03d}.png"),
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
            gap = np.full((args.size, 4, 3), 255, np.uint8)
            rows.append(np.hstack([x for pnl in panels for x in (pnl, gap)][:-1]))
            print(md_row([name, f"{r.timings_s['total']:.2f}", f"{vis.mean():.2f}",
                          f"{clip.mean():.3f}", f"{d.min():.0f}-{d.max():.0f}",
                          f"{np.median(tilt):.1f}"]), flush=True)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    sep = np.full((4, rows[0].shape[1], 3), 255, np.uint8)
    cv2.imwrite(str(out), np.vstack([x for r in rows for x in (r, sep)][:-1]),
                [cv2.IMWRITE_JPEG_QUALITY, 70])
    print(f"\nwrote {out}")


if __name__ == "__main__":
    main()
