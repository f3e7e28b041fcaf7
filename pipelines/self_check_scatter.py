"""The self-check's own random error: on each stack, the analysis once, then its NDF self-check
(``analysis.self_check``) again under ``draws`` seeds (each draw: fresh slice noise and a fresh
bootstrap segmentation for the injected cells, as the analysis' seed would give), and how
often the NDF would be identified (both transfers inside ``fits.self_check_range``; the other
checks as the analysis found them).

    python -m pipelines.self_check_scatter STACK [STACK ...] [--draws N]

Prints one JSON line per stack: the transfers' mean and SD over the draws, the share of draws
inside the range, and whether the analysis (seed 0) identified the NDF. Used for the
self-check's scatter in docs/accuracy.md (issue 22) and to tell a change of the self-check's
random draws (issue 26: its runs on separate threads, each with its own streams) from a
change of what it measures.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
from pathlib import Path

import numpy as np

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis import pipeline as _pipeline
from microfacet.analysis.joint import bootstrap_labels


def _segmentation_capture():
    """Wrap the pipeline's facet segmentation so that the last one is kept (the self-check's
    bootstrap re-segments as it did)."""
    kept = {}
    inner = _pipeline.facet_labels

    def facet_labels(*args, **kwargs):
        kept["seg"] = inner(*args, **kwargs)
        return kept["seg"]

    _pipeline.facet_labels = facet_labels
    return kept


def scatter(stack: Path, draws: int, kept) -> dict:
    r = analyse_stack(stack, AnalysisOptions())
    low, high = r.options.fits.self_check_range
    t, w = [], []
    for k in range(draws):
        scene = dataclasses.replace(r.scene, seed=k)

        def cells(crop, scene=scene):
            return bootstrap_labels(r.colour, kept["seg"], scene, r.options.joint,
                                    rng=np.random.default_rng([scene.seed, 22]), crop=crop)

        chk = _pipeline._self_check(r.stack, r.focus, r.joint, scene, r.options, cells=cells)
        if chk is None:
            return {"stack": stack.name, "self_check": None}
        t.append(chk.transfer)
        w.append(chk.width_transfer)
    t, w = np.array(t), np.array(w)
    inside = (low <= t) & (t <= high) & (low <= w) & (w <= high)
    return {"stack": stack.name, "transfer_mean": round(float(np.mean(t)), 3),
            "transfer_sd": round(float(np.std(t, ddof=1)), 3),
            "width_mean": round(float(np.mean(w)), 3),
            "width_sd": round(float(np.std(w, ddof=1)), 3),
            "inside_range_share": round(float(np.mean(inside)), 3),
            "identified": bool(r.distributions.ndf_judgement.identified),
            "reason_code": getattr(r.distributions.ndf_judgement.reason, "code", None)}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("stacks", nargs="+", type=Path)
    ap.add_argument("--draws", type=int, default=6)
    a = ap.parse_args(argv)
    kept = _segmentation_capture()
    for s in a.stacks:
        print(json.dumps(scatter(s, max(2, a.draws), kept)), flush=True)


if __name__ == "__main__":
    main()
