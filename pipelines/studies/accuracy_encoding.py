"""Does the thickness analysis follow the slices' encoding? The same random scenes saved
lossless and as JPEG of two qualities, analysed and compared.

Each scene is drawn as the generalization sweep draws it (:func:`accuracy_sweep.draw_scene`:
its world, variations and populations; by default seed 1, scenes the analysis was not
developed against) and written three times with the same sensor noise: 8-bit PNG and JPEG
of each quality in ``qualities`` (a scene the sweep drew with JPEG gets its other
encodings too). All copies are analysed in the joint mode and scored against the truth
(:func:`accuracy_sweep.score_scene`). Per encoding: the scenes whose population count is
right, the region MAE, the wrong-order scenes, the colour noise the analysis measured, and
against each scene's own lossless copy: the same count, and every mean within 1 nm (the
issue's criterion for re-encoding at quality ≥ 90). The per-scene rows go to
``encoding.csv`` under ``out``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import fmt, md_table, note, write_csv

STUDY = Study(
    name="accuracy-encoding",
    question="Do the thickness populations follow the slices' JPEG encoding (the same scenes "
             "lossless and re-encoded)?",
    doc=("docs/accuracy.md", "accuracy-encoding"),
    run_time="6 min",
    quick_time="20 s",
    options={"n": (30, "number of scenes"),
             "seed": (1, "seed of the scene draws (the sweep's; 1: not developed against)"),
             "size": ("256x256", "HxW in px"),
             "slices": (16, "slices per stack"),
             "qualities": ("90,75", "JPEG qualities beside the lossless copy"),
             "jobs": (0, "local worker processes (0: the batch's default)"),
             "work": ("", "folder for the stacks and results (default out/work)")},
)


def encodings(qualities: str) -> list:
    """``[(label, jpeg quality or None)]``: the lossless copy first.

    >>> encodings("90,75")
    [('png', None), ('jpeg90', 90), ('jpeg75', 75)]
    """
    return [("png", None)] + [(f"jpeg{int(q)}", int(q)) for q in qualities.split(",") if q]


def write_copies(plan, encs, work: Path) -> list:
    """Every scene in every encoding (same parameters and noise but ``jpeg_quality``, 8-bit);
    returns the stack folders, scene by scene."""
    from microfacet.forward.synth import generate_stack

    folders = []
    for name, p, _ in plan:
        for label, q in encs:
            folder = work / "stacks" / f"{name}-{label}"
            if not (folder / "stack.json").is_file():
                generate_stack(folder, dataclasses.replace(p, jpeg_quality=q, bit_depth=8),
                               overwrite=True)
            folders.append(folder)
    return folders


def _opened(results: Path):
    """The results folder opened once (None where the analysis failed)."""
    from microfacet.io.results import Results

    return Results(results) if (results / "summary.json").is_file() else None


def _means(summary: dict) -> list:
    mix = summary["thickness"]["mixture"]
    return sorted(c["mean_nm"] for c in mix.get("components", []))


def score(plan, encs, work: Path) -> list:
    """One row per scene and encoding: the sweep's scores, the colour noise, and the count
    and means against the scene's lossless copy (each results folder opened once)."""
    from pipelines.studies.accuracy_sweep import score_scene

    rows = []
    for name, _, on in plan:
        ref = _opened(work / "results" / f"{name}-png")
        for label, _ in encs:
            folder = work / "results" / f"{name}-{label}"
            res = ref if label == "png" else _opened(folder)
            row = {"scene": name, "encoding": label, "jpeg_drawn": "jpeg" in on}
            if res is None:
                rows.append({**row, "status": "failed"})
                continue
            row.update(score_scene(folder, work / "stacks" / f"{name}-{label}" / "truth", res),
                       status="done", noise=res.summary["colour_noise_de"])
            if ref is not None:
                a, b = _means(res.summary), _means(ref.summary)
                row["same_count"] = len(a) == len(b)
                row["same_means"] = len(a) == len(b) and bool(
                    np.all(np.abs(np.subtract(a, b)) <= 1.0))
            rows.append(row)
    return rows


#: Columns of ``encoding.csv`` (one row per scene and encoding).
COLUMNS = ["scene", "encoding", "status", "jpeg_drawn", "pops_found", "pops_true",
           "region_mae_nm", "order_wrong", "order_flagged", "de_mean", "de_floor", "noise",
           "same_count", "same_means"]


def table(rows, encs) -> str:
    def frac(sel, key):
        v = [bool(r.get(key)) for r in sel if r.get(key) is not None]
        return f"{100 * np.mean(v):.0f} %" if v else "–"

    body = []
    for label, _ in encs:
        sel = [r for r in rows if r["encoding"] == label and r["status"] == "done"]
        ok = [r for r in sel if r.get("pops_found") is not None]
        wrong = [r for r in sel if r.get("order_wrong")]
        body.append([label, str(len(sel)),
                     f"{100 * np.mean([r['pops_found'] == r['pops_true'] for r in ok]):.0f} %"
                     if ok else "–",
                     fmt(float(np.nanmedian([r["region_mae_nm"] for r in sel])))
                     if sel else "–",
                     f"{len(wrong)} ({sum(1 for r in wrong if not r['order_flagged'])})",
                     fmt(float(np.median([r["noise"] for r in sel]))) if sel else "–",
                     "–" if label == "png" else frac(sel, "same_count"),
                     "–" if label == "png" else frac(sel, "same_means")])
    return md_table(["slices", "scenes", "populations right", "region MAE (nm)",
                     "wrong order (order said established)", "colour noise (ΔE00)",
                     "same count as lossless", "… and every mean within 1 nm"], body)


def run(*, quick: bool, out: Path, n=30, seed=1, size="256x256", slices=16,
        qualities="90,75", jobs=0, work="") -> str:
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.workflow.batch import run_batch
    from pipelines.studies.accuracy_sweep import draw_scene

    hw = tuple(int(v) for v in size.lower().split("x"))
    if quick:
        n, hw, slices, jobs = min(n, 2), (64, 64), min(slices, 6), jobs or 1
    work = Path(work) if work else out / "work"
    encs = encodings(qualities)
    plan = [draw_scene(i, seed=seed, size=hw, slices=slices) for i in range(n)]
    stacks = write_copies(plan, encs, work)
    todo = [s for s in stacks if not (work / "results" / s.name / "summary.json").is_file()]
    if todo:
        run_batch(todo, work / "results", jobs=jobs or None,
                  options=AnalysisOptions(mode="joint"), report=False)
    rows = score(plan, encs, work)
    write_csv(out / "encoding.csv", rows, COLUMNS)
    failed = sum(1 for r in rows if r["status"] != "done")
    note(f"{n} scenes (seed {seed}) × {len(encs)} encodings; {failed} analyses failed")
    head = (f"{n} scenes of the generalization sweep (seed {seed}, {hw[0]}×{hw[1]} px, "
            f"{slices} slices), each as 8-bit PNG and JPEG {qualities.replace(',', ', ')}; "
            f"joint mode; {failed} analyses failed.\n\n")
    return head + table(rows, encs)
