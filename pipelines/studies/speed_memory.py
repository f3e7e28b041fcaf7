"""Memory of ``analyse_stack`` stage by stage, and the Felzenszwalb tile size against truth.

For a stack (``stack``; default: an nd stack of 992×992 px × 40 slices generated into
``out``, as ``speed-analyze`` uses at 1 MP), tabulates each stage's peak resident memory and
what stays resident after it (Linux: ``VmHWM`` is reset at the start of every stage through
``/proc/self/clear_refs``). With ``tiles`` it also analyses the stack with each Felzenszwalb
tile size (``analysis.segmentation.FELZENSZWALB_TILE_PX``) and scores it against the stack's
``truth/``: facets, thickness MAE, median tilt error, tilt W1, and the analysis' peak
resident memory.
"""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path
from unittest import mock

import numpy as np

from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="speed-memory",
    question="Which stage of the analysis sets its peak memory, and what does the "
             "segmentation's tile size cost in accuracy?",
    doc=None,
    run_time="3 min",
    quick_time="10 s",
    options={"stack": ("", "stack folder with truth/ (default: generate an nd stack in out)"),
             "size": (992, "side of the generated stack, px"),
             "slices": (40, "slices of the generated stack"),
             "tiles": ("1024,512", "Felzenszwalb tile sizes to score (empty: none)")},
)


def _status(key):
    for line in open("/proc/self/status"):
        if line.startswith(key):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def _reset_peak():
    with open("/proc/self/clear_refs", "w") as f:
        f.write("5")


def stage_memory(stack):
    """[(stage, peak MB, resident after MB)] of one analysis."""
    from microfacet.analysis import analyse_stack
    from microfacet.core import timing

    rows = []
    stage = timing.StageTimer.stage

    @contextmanager
    def recording_stage(self, st):
        _reset_peak()
        with stage(self, st):
            yield
        rows.append((st.key, _status("VmHWM"), _status("VmRSS")))

    with mock.patch.object(timing.StageTimer, "stage", recording_stage):
        analyse_stack(stack)
    return rows


def tile_scores(stack, tiles):
    from microfacet.analysis import analyse_stack, segmentation
    from microfacet.core.densities import wasserstein1

    truth = Path(stack) / "truth"
    d_true = np.load(truth / "thickness_nm.npy")
    t_true = np.load(truth / "tilt_deg.npy")
    vis = np.load(truth / "visible.npy")
    for tile in tiles:
        _reset_peak()
        with mock.patch.object(segmentation, "FELZENSZWALB_TILE_PX", tile):
            r = analyse_stack(stack)
        peak = _status("VmHWM")
        d, t = r.pixels.thickness_nm, r.pixels.tilt_deg
        ok = np.isfinite(d)
        okt = np.isfinite(t) & vis
        row = (tile, int(r.joint.facets.max()) + 1,
               float(np.mean(np.abs(d[ok] - d_true[ok]))),
               float(np.median(np.abs(t[okt] - t_true[okt]))),
               wasserstein1(t[okt], t_true[vis]), peak)
        del r, d, t, ok, okt  # the next analysis starts without this one's maps
        yield row


def run(*, quick: bool, out: Path, stack="", size=992, slices=40, tiles="1024,512") -> str:
    if not Path("/proc/self/clear_refs").exists():
        raise SystemExit("speed-memory needs Linux /proc (VmHWM reset)")
    tile_list = [int(t) for t in (tiles or "").split(",") if t]   # `--set tiles=`: None
    if quick:
        size, slices, tile_list = min(size, 128), min(slices, 8), [64]
    if not stack:
        from microfacet.forward.synth import generate_stack, preset

        folder = out / f"nd-{size}x{size}-{slices}"
        if not (folder / "stack.json").is_file():
            generate_stack(folder, preset("nd", seed=3, height_px=size, width_px=size,
                                          n_slices=slices), overwrite=True)
        stack = folder
    note(f"{stack}: memory per stage (MB)")
    text = md_table(["stage", "peak", "resident after"],
                    [[name, f"{peak:.0f}", f"{now:.0f}"]
                     for name, peak, now in stage_memory(stack)])
    if tile_list:
        rows = []
        for tile, n, mae, med, w1, peak in tile_scores(stack, tile_list):
            rows.append([tile, n, f"{mae:.3f}", f"{med:.3f}", f"{w1:.3f}", f"{peak:.0f}"])
            note(" | ".join(map(str, rows[-1])))
        text += "\n\nFelzenszwalb tile size against the truth:\n\n" + md_table(
            ["tile (px)", "facets", "thickness MAE (nm)", "tilt error, median (°)",
             "tilt W1 (°)", "peak of the analysis (MB)"], rows)
    return text
