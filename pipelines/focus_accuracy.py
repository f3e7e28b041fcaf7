"""Height-from-focus accuracy per operator, window and peak interpolation (docs/height-from-focus.md).

RMSE in slices against the ground truth of the Cou & Guennebaud (2023) stacks 1-3 bundled in
fixtures/focus-stacks/cou2023-synthetic-rough (registration reference[i, j] <-> pixel
(i+20, j+20), depth = -reference), all pixels, no reliability mask.

Run:  python pipelines/focus_accuracy.py
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from microfacet.focus.height import height_from_focus
from microfacet.io.stack import read_stack

COU = Path(__file__).resolve().parent.parent / "fixtures" / "focus-stacks" / "cou2023-synthetic-rough"

# (operator, window, window_px, interpolation, fit_radius)
METHODS = [
    ("sml", "box", 5, "none", None),
    ("sml", "box", 5, "gauss3", None),
    ("glv", "box", 9, "gauss3", None),
    ("tenengrad", "box", 7, "gauss3", None),
    ("tenengrad", "gaussian", 7, "gauss3", None),
    ("sml", "box", 5, "lsq", 2),
    ("sml", "box", 9, "lsq", 2),
    ("sml", "gaussian", 9, "lsq", 3),
    ("glv", "gaussian", 7, "lsq", 2),
    ("glv", "gaussian", 9, "lsq", 2),
    ("tenengrad", "box", 7, "lsq", 2),
    ("tenengrad", "gaussian", 5, "lsq", 2),
    ("tenengrad", "gaussian", 7, "lsq", 2),
    ("tenengrad", "gaussian", 7, "lsq", 3),
    ("tenengrad", "gaussian", 9, "lsq", 2),
    ("tenengrad", "gaussian", 11, "lsq", 2),
]


def rmse(height, stack_no):
    ref = -np.load(COU / f"stack{stack_no}" / "reference.npy")
    d = height[20:20 + ref.shape[0], 20:20 + ref.shape[1]]
    return float(np.sqrt(np.mean((d - ref) ** 2)))


def main():
    stacks = {s: read_stack(COU / f"stack{s}") for s in (1, 2, 3)}
    print("| operator | window | interpolation | stack 1 | stack 2 | stack 3 |")
    print("|---|---|---|---|---|---|")
    for op, win, px, interp, r in METHODS:
        vals = [rmse(height_from_focus(stacks[s], operator=op, window=win, window_px=px,
                                       interpolation=interp, fit_radius=r,
                                       min_reliability_db=-np.inf).height_um, s)
                for s in (1, 2, 3)]
        name = {"none": "arg-max", "gauss3": "Gauss 3-pt", "lsq": f"lsq {r}"}[interp]
        wname = f"{'Gauss' if win == 'gaussian' else 'box'} {px}"
        print(f"| {op} | {wname} | {name} | " + " | ".join(f"{v:.3f}" for v in vals) + " |",
              flush=True)


if __name__ == "__main__":
    main()
