"""Height-from-focus accuracy per operator, window and peak interpolation.

The table of docs/height-from-focus.md.

RMSE in slices against the ground truth of the Cou & Guennebaud (2023) stacks 1-3 bundled in
fixtures/focus-stacks/cou2023-synthetic-rough (registration reference[i, j] <-> pixel
(i+20, j+20), depth = -reference), all pixels, no reliability mask. The last two rows are the
current default (Lorentz fit, 7 + 15 px windows) and the earlier one (``EARLIER_DEFAULT``),
measured in the same run.

Run:  python pipelines/focus_accuracy.py
"""

from __future__ import annotations

import numpy as np
from _shared import cou_rmse, cou_stack, md_header, md_row

from microfacet.focus.height import height_from_focus
from microfacet.focus.options import EARLIER_DEFAULT, FocusOptions

# (operator, window, window_px, interpolation, fit_radius): one window each (fit_radius None:
# not used by the fit)
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
    ("tenengrad", "gaussian", 7, "lorentz", 2),
]


def main():
    stacks = {s: cou_stack(s) for s in (1, 2, 3)}
    print(md_header(["operator", "window", "interpolation", "stack 1", "stack 2", "stack 3"]))
    for op, win, px, interp, r in METHODS:
        opts = FocusOptions(operator=op, window=win, window_px=px, interpolation=interp,
                            coarse_window_px=0, min_reliability_db=-np.inf,
                            **({} if r is None else {"fit_radius": r}))
        vals = [cou_rmse(height_from_focus(st, opts).height_um, ref)
                for st, ref in stacks.values()]
        name = {"none": "arg-max", "gauss3": "Gauss 3-pt", "lsq": f"lsq {r}",
                "lorentz": f"Lorentz {r}"}[interp]
        wname = f"{'Gauss' if win == 'gaussian' else 'box'} {px}"
        print(md_row([op, wname, name] + [f"{v:.3f}" for v in vals]), flush=True)
    for label, opts in (("default: Lorentz 2, windows 7 + 15", FocusOptions()),
                        ("earlier default: lsq 2, window 7", EARLIER_DEFAULT)):
        opts = opts.replace(min_reliability_db=-np.inf)
        vals = [cou_rmse(height_from_focus(st, opts).height_um, ref)
                for st, ref in stacks.values()]
        print(md_row(["tenengrad", "Gauss 7", label] + [f"{v:.3f}" for v in vals]), flush=True)


if __name__ == "__main__":
    main()
