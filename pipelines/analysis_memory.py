"""Memory of `analyze_stack` stage by stage, and the Felzenszwalb tile size against truth.

For a stack (e.g. one that ``pipelines/bench_analyze.py --work DIR`` generated), prints each
stage's peak resident memory and what stays resident after it (Linux: ``VmHWM`` is reset at
every stage through ``/proc/self/clear_refs``). With ``--tiles 1024,512`` it also analyses the
stack with each Felzenszwalb tile size (``analysis.segmentation.FELZENSZWALB_TILE_PX``) and
scores it against the stack's ``truth/``: facets, thickness MAE, median tilt error, tilt W1,
and the analysis' peak resident memory.

Run::

    python pipelines/analysis_memory.py DIR/nd-992x992-40 [--tiles 1024,512,256]
"""

from __future__ import annotations

import sys
from pathlib import Path
from unittest import mock

import numpy as np
from _shared import md_header, md_row, parser

from microfacet.analysis import analyze_stack, segmentation
from microfacet.core import timing
from microfacet.core.densities import wasserstein1


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
    rows = []
    lap = timing.StageTimer.lap

    def recording_lap(self, name, *a, **k):
        rows.append((name, _status("VmHWM"), _status("VmRSS")))
        _reset_peak()
        return lap(self, name, *a, **k)

    _reset_peak()
    with mock.patch.object(timing.StageTimer, "lap", recording_lap):
        analyze_stack(stack)
    return rows


def tile_scores(stack, tiles):
    truth = Path(stack) / "truth"
    d_true = np.load(truth / "thickness_nm.npy")
    t_true = np.load(truth / "tilt_deg.npy")
    vis = np.load(truth / "visible.npy")
    for tile in tiles:
        _reset_peak()
        with mock.patch.object(segmentation, "FELZENSZWALB_TILE_PX", tile):
            r = analyze_stack(stack)
        peak = _status("VmHWM")
        ok = np.isfinite(r.thickness_nm)
        okt = np.isfinite(r.tilt_deg) & vis
        row = (tile, int(r.facets.max()) + 1,
               float(np.mean(np.abs(r.thickness_nm[ok] - d_true[ok]))),
               float(np.median(np.abs(r.tilt_deg[okt] - t_true[okt]))),
               wasserstein1(r.tilt_deg[okt], t_true[vis]), peak)
        del r, ok, okt  # the next analysis starts without this one's maps
        yield row


def main(argv=None):
    ap = parser(__doc__)
    ap.add_argument("stack")
    ap.add_argument("--tiles", default="", help="Felzenszwalb tile sizes to score, e.g. 1024,512")
    args = ap.parse_args(argv)
    if not Path("/proc/self/clear_refs").exists():
        sys.exit("needs Linux /proc (VmHWM reset)")
    print(f"{args.stack}: memory per stage (MB)\n")
    print(md_header(["stage", "peak", "resident after"]))
    for name, peak, now in stage_memory(args.stack):
        print(md_row([name, f"{peak:.0f}", f"{now:.0f}"]))
    tiles = [int(t) for t in args.tiles.split(",") if t]
    if tiles:
        print("\nFelzenszwalb tile size against the truth\n")
        print(md_header(["tile (px)", "facets", "thickness MAE (nm)", "tilt error, median (°)",
                         "tilt W1 (°)", "peak of the analysis (MB)"]))
        for tile, n, mae, med, w1, peak in tile_scores(args.stack, tiles):
            print(md_row([tile, n, f"{mae:.3f}", f"{med:.3f}", f"{w1:.3f}", f"{peak:.0f}"]),
                  flush=True)


if __name__ == "__main__":
    main()
