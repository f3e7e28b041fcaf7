"""Throughput of ``microfacet batch``: in-process, local worker processes, Dask LocalCluster.

For each set of stacks (``sets``: ``NxSIZE`` each, e.g. ``6x256`` = 6 stacks of 256×256 px),
generates the stacks once (nd and sd presets alternately), then analyses all of them with
each executor into a fresh output folder and tabulates wall time, stacks per minute and the
speed-up against the in-process run (``jobs=1``) of the same set, measured in the same run.
Reports are off, so the table measures the analysis and the scheduling, not matplotlib. A
quick run leaves the Dask cluster out (its start-up alone is ~20 s).
"""

from __future__ import annotations

import shutil
from pathlib import Path

from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="speed-batch",
    question="When do worker processes or a Dask cluster pay off for `microfacet batch`?",
    doc=("docs/benchmarks.md", "speed-batch"),
    run_time="3 min",
    quick_time="15-25 s",
    options={"sets": ("6x256,8x512", "stack sets NxSIZE, comma-separated"),
             "slices": (16, "slices per stack"),
             "jobs": (2, "workers of the parallel runs")},
)


def _stacks(folder: Path, n: int, size: int, slices: int) -> list:
    from microfacet.forward.synth import generate_stack, preset

    out = []
    for i in range(n):
        p = preset(("nd", "sd")[i % 2], seed=i, height_px=size, width_px=size, n_slices=slices)
        generate_stack(folder / f"s{i}", p, overwrite=True)
        out.append(folder / f"s{i}")
    return out


def run(*, quick: bool, out: Path, sets="6x256,8x512", slices=16, jobs=2) -> str:
    from microfacet.analysis import AnalysisOptions
    from microfacet.workflow.batch import run_batch

    plan = [tuple(int(v) for v in s.lower().split("x")) for s in sets.split(",")]
    if quick:
        plan, slices = [(2, 64)], min(slices, 6)
    runs = [("in-process (`--jobs 1`)", dict(jobs=1)),
            (f"loky processes (`--jobs {jobs}`)", dict(jobs=jobs))]
    if not quick:
        runs.append((f"Dask LocalCluster (`--scheduler local --jobs {jobs}`)",
                     dict(scheduler="local", jobs=jobs)))
    rows = []
    for n, size in plan:
        work = out / f"{n}x{size}"
        shutil.rmtree(work, ignore_errors=True)
        stacks = _stacks(work / "stacks", n, size, slices)
        base = None
        for k, (name, kw) in enumerate(runs):
            dt, res = best_of(lambda k=k, kw=kw: run_batch(
                stacks, work / f"out{k}", options=AnalysisOptions(), report=False, **kw), 1)
            base = base or dt
            rows.append([f"{n} × {size}²", name, f"{dt:.1f}", f"{60 * n / dt:.1f}",
                         f"{base / dt:.2f}×", res.n_failed])
            note(" | ".join(map(str, rows[-1])))
        shutil.rmtree(work, ignore_errors=True)
    note(f"stacks of {slices} slices, no report")
    return md_table(["stacks", "executor", "wall (s)", "stacks/min", "speed-up vs in-process",
                     "failed"], rows)
