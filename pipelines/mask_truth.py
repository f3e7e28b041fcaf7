"""The colour mask's dark classes against the synth's truth (issue 22, "dark is not steep";
docs/accuracy.md): per truth class of pixel — film not past the acceptance, facets truly
past it, pits/scratches/dust/stains, grooves between facets — the share the mask takes as
steep (censored by the NDF) and as masked (steep or dark feature), with the options given
and with one threshold (``mask.steep_core_ratio`` = ``mask.steep_ratio``: every pixel below
0.3 of the film steep, as before 2026-11-29).

    python -m pipelines.mask_truth WORK_DIR [WORK_DIR ...]

Each WORK_DIR is an ``accuracy-sweep --set work=DIR`` folder: ``stacks/NAME/truth`` and
``results/joint/NAME/all_in_focus.png`` (the analysed image; the mask is recomputed on it,
without the flat field's second pass). Prints a markdown table and the worst scene's share of
film masked.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np

from microfacet.analysis.mask import colour_mask
from microfacet.analysis.options import MaskOptions
from microfacet.io.images import read_png
from pipelines._shared import md_table

CLASSES = ("film, not past the limit", "facets truly past the limit",
           "pits, scratches, dust, stains", "grooves between facets")


def truth_classes(truth: Path) -> list[np.ndarray]:
    """Boolean maps of :data:`CLASSES` from a synth stack's ``truth`` folder."""
    limit = json.loads((truth / "params.json").read_text())["visibility_limit_deg"]
    feature = np.load(truth / "feature.npy") != 0
    groove = np.load(truth / "groove.npy") != 0
    past = (np.load(truth / "tilt_deg.npy") > limit) & ~feature & ~groove
    return [~feature & ~groove & ~past, past, feature & ~groove, groove]


def scene_counts(image_path: Path, truth: Path, options: dict) -> dict:
    """Pixels per class, and per rule set (``options``: name → MaskOptions) those steep and
    those masked as steep or dark feature."""
    img = read_png(image_path)
    classes = truth_classes(truth)
    if classes[0].shape != img.shape[:2]:
        return {}
    out = {"n": [int(c.sum()) for c in classes]}
    for name, opts in options.items():
        m = colour_mask(img, opts)
        out[name] = [(int((m.steep & c).sum()), int(((m.steep | m.dark_feature) & c).sum()))
                     for c in classes]
    return out


def main(folders) -> None:
    rules = {"one threshold": MaskOptions(steep_core_ratio=MaskOptions().steep_ratio),
             "now": MaskOptions()}
    total, worst = None, {k: 0.0 for k in rules}
    for work in map(Path, folders):
        for res in sorted((work / "results" / "joint").glob("*/all_in_focus.png")):
            c = scene_counts(res, work / "stacks" / res.parent.name / "truth", rules)
            if not c:
                continue
            for k in rules:
                worst[k] = max(worst[k], c[k][0][1] / max(c["n"][0], 1))
            if total is None:
                total = c
                continue
            total["n"] = [a + b for a, b in zip(total["n"], c["n"])]
            for k in rules:
                total[k] = [(a0 + b0, a1 + b1) for (a0, a1), (b0, b1) in zip(total[k], c[k])]
    if total is None:
        sys.exit("mask_truth: no results/joint/*/all_in_focus.png with a truth folder")
    pct = [[100 * total[k][i][j] / max(total["n"][i], 1) for k, j in
            (("one threshold", 1), ("now", 0), ("now", 1))] for i in range(len(CLASSES))]
    print(md_table(["truth", "pixels", "below 0.3: masked and censored before",
                    "censored now (steep)", "masked now (steep or dark feature)"],
                   [[name, f"{total['n'][i]:,}", *(f"{v:.2f} %" for v in pct[i])]
                    for i, name in enumerate(CLASSES)]))
    print("worst scene's film masked: " + ", ".join(f"{k} {100 * v:.1f} %"
                                                    for k, v in worst.items()))


if __name__ == "__main__":
    main(sys.argv[1:])
