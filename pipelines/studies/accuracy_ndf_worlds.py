"""Is the NDF identified only where it is right, on scenes of the worlds of issue 22?

Draws ``n`` scenes per seed exactly as ``accuracy-sweep`` does (its worlds: faceted, sparse
texture, instrument-measured geometry; stains and the other variations), analyses each in
the joint mode with its self-check and scores it against its truth
(:func:`pipelines.self_check_sweep.scene_record`): whether the NDF is identified and why
not, the lobes' RMS slope and W1 against the true facet tilts, the self-check, the censored
share against the truly-past-limit area and the height's 2σ coverage. The table gives them
per world and seed (docs/accuracy.md quotes it); ``ndf_worlds.jsonl`` holds the scenes.
"""

from __future__ import annotations

import json
from pathlib import Path

from pipelines import Study
from pipelines._shared import note

STUDY = Study(
    name="accuracy-ndf-worlds",
    question="Is the NDF identified only where it is right, on scenes of issue 22's worlds "
             "(faceted, sparse texture, measured geometry), and how often?",
    doc=None,
    run_time="5 min",
    quick_time="20 s",
    options={"n": (30, "scenes per seed"),
             "seeds": ("0,1", "seeds of the scene draws, comma-separated"),
             "work": ("", "folder for the stacks (default out/work); reused")},
)


def run(*, quick: bool, out: Path, n=30, seeds="0,1", work="") -> str:
    from pipelines.self_check_sweep import analysis_options, scene_record, world_table
    from pipelines.studies.accuracy_sweep import draw_scene, generate

    size, slices = ((96, 96), 8) if quick else ((256, 256), 16)
    n = 2 if quick else int(n)
    options = analysis_options()
    tables, rows = [], []
    for seed in [int(s) for s in str(seeds).split(",") if s.strip()]:
        folder = Path(work or out / "work") / f"seed{seed}"
        plan = [draw_scene(i, seed=seed, size=size, slices=slices) for i in range(n)]
        generate(plan, folder, ["joint"])
        mine = []
        for name, _, _ in plan:
            rec = {"seed": seed, **scene_record(folder / "stacks" / name, options)}
            note(f"  seed {seed} {name} ({rec['world']}): identified {rec['identified']} "
                 f"({rec['reason_code']}), lobe RMS ratio {rec.get('lobe_ratio')}")
            mine.append(rec)
        rows += mine
        tables.append(world_table(mine, label=f"seed {seed}"))
    out.mkdir(parents=True, exist_ok=True)
    (out / "ndf_worlds.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    return "\n\n".join(tables)
