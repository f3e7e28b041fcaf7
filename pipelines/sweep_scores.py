"""The targets of issues 22 and 23 over one or more accuracy-sweep runs, one column per set
of runs (docs/accuracy.md; the closing notes quote it).

    python -m pipelines.sweep_scores OUT:WORK [OUT:WORK ...] [--label=NAME ...]

Each ``OUT:WORK`` is one ``accuracy-sweep --set mode=joint --set work=WORK --out OUT`` run:
``OUT/generalization.csv`` (one row per scene) and ``WORK/results/joint/NAME/summary.json``
(the white balance). Runs given together with ``+`` (``OUT0:WORK0+OUT1:WORK1``) are pooled
into one column, their per-seed numbers listed. Prints a markdown table: the NDF's scores
(identified, off by more than 25 % and within 15 % of the true lobe RMS slope, their W1,
censored against truly past the limit, height 2σ coverage) and the thickness's (true count
of components and of distinct populations, region MAE with and without a white-balance
error, the share of the map read an order off and the true count where it is more than
5 %, scenes read in a wrong order and those not flagged, scenes whose order is said
established, white-balance gains called determined and those within 2 %; a run without
a column scores it "–").
"""

from __future__ import annotations

import csv
import json
import sys
from pathlib import Path

import numpy as np

from pipelines._shared import md_table

#: A determined white-balance gain is right within this relative error (issue 23).
WB_TOLERANCE = 0.02
#: A scene whose thickness map is read an order off (``order_off_fraction``,
#: :func:`pipelines._scoring.order_off_fraction`) over more than this share: the count's
#: misses gather there (docs/accuracy.md, "Facets read an order off").
ORDER_OFF_SHARE = 0.05
#: Columns a run recorded before they existed lacks (read as NaN, scored "–"); any other
#: column missing is an error.
LATER_COLUMNS = ("order_off_fraction",)


class Runs:
    """The joint-mode rows of a set of runs as columns (``col(name)``: a float array; the
    CSV's ``True``/``False`` read as 1/0), with each row's run index and the relative errors
    of the white-balance gains its estimate calls determined."""

    def __init__(self, rows, run, determined):
        self.rows, self.run, self.determined = rows, np.asarray(run), determined

    def col(self, name, where=None) -> np.ndarray:
        later = name in LATER_COLUMNS
        v = np.array([_number(r.get(name, "") if later else r[name]) for r in self.rows])
        return v if where is None else v[where]

    def per_run(self, fn) -> str:
        return " / ".join(f"{fn(self.run == i):.3g}" for i in np.unique(self.run))


def _number(text: str) -> float:
    """A CSV cell as a number: ``True``/``False`` as 1/0, empty as NaN."""
    flags = {"True": 1.0, "False": 0.0}
    return flags[text] if text in flags else float(text or "nan")


def read_runs(spec: str) -> Runs:
    """The runs in ``spec`` (``OUT:WORK`` joined by ``+``) as :class:`Runs`."""
    rows, run, det = [], [], []
    for i, part in enumerate(spec.split("+")):
        out, _, work = part.partition(":")
        with open(Path(out) / "generalization.csv", newline="") as f:
            mine = [r for r in csv.DictReader(f) if r["mode"] == "joint"]
        rows += mine
        run += [i] * len(mine)
        det += [_determined(Path(work), r) for r in mine]
    return Runs(rows, run, det)


def _determined(work: Path, row) -> list:
    """Relative errors of the scene's white-balance gains its estimate calls determined."""
    path = work / "results" / "joint" / row["name"] / "summary.json"
    if not path.is_file():
        return []
    wb = json.loads(path.read_text()).get("white_balance") or {}
    est, det = wb.get("estimate_rgb"), wb.get("determined_rb") or (False, False)
    return [abs(est[k] / float(row[t]) - 1.0) for k, t in ((0, "wb_true_r"), (2, "wb_true_b"))
            if est is not None and det[k // 2]]


def _median(v) -> float:
    """The median over the scenes scored (a failed scene's empty cell is NaN)."""
    v = np.asarray(v, dtype=np.float64)
    return float(np.median(v[np.isfinite(v)])) if np.isfinite(v).any() else float("nan")


def scores(d: Runs) -> dict:
    """The targets' numbers for one pooled set of runs (module notes)."""
    ident = d.col("identified") == 1
    off = np.abs(d.col("lobe_rms_ratio", ident) - 1.0)
    wb = d.col("v_white_balance") == 1
    mae = d.col("region_mae_nm")
    right = d.col("pops_found") == d.col("pops_true")
    distinct = d.col("pops_distinct") == d.col("pops_true")
    wrong = d.col("order_wrong") == 1
    gains = np.array([e for es in d.determined for e in es])
    order_off = d.col("order_off_fraction")
    much = order_off > ORDER_OFF_SHARE
    cens = np.abs(d.col("censored_fraction") - d.col("past_limit_fraction"))
    return {
        "scenes (with focus texture)": f"{len(d.rows)} ({int(d.col('textured').sum())})",
        "NDF identified, textured scenes": f"{int((ident & (d.col('textured') == 1)).sum())}",
        "… off by more than 25 %": f"{int((off > 0.25).sum())}",
        "… within 15 %": f"{int((off <= 0.15).sum())} of {int(ident.sum())}",
        "… W1, median (°)": (f"{_median(d.col('ndf_w1_deg', ident)):.2f}" if ident.any()
                             else "–"),
        "censored − past the limit, median abs per run": d.per_run(
            lambda r: _median(cens[r])),
        "height 2σ coverage, median per run": d.per_run(
            lambda r: _median(d.col("height_coverage", r))),
        "true population count": f"{int(right.sum())}",
        "… counting order aliases with their component": f"{int(distinct.sum())}",
        "region MAE, median (nm)": f"{_median(mae):.3f}",
        "… white-balance scenes / the others": (f"{_median(mae[wb]):.2f} / "
                                               f"{_median(mae[~wb]):.2f}"),
        "map read an order off, median / mean share": (
            f"{_median(order_off):.3f} / {np.nanmean(order_off):.3f}"
            if np.isfinite(order_off).any() else "–"),
        f"… true count where more than {100 * ORDER_OFF_SHARE:.0f} % is": (
            f"{int((right & much).sum())} of {int(much.sum())}"
            if np.isfinite(order_off).any() else "–"),
        "read in a wrong order (not flagged)": (
            f"{int(wrong.sum())} ({int((wrong & (d.col('order_flagged') == 0)).sum())})"),
        "order said established": f"{int((d.col('order_flagged') == 0).sum())}",
        "white-balance gains determined (within 2 %)": (
            f"{gains.size} ({int((gains <= WB_TOLERANCE).sum())})"),
    }


def table(columns: dict) -> str:
    """Markdown: one row per score, one column per label."""
    rows = list(next(iter(columns.values())))
    return md_table(["score", *columns], [[r, *(c[r] for c in columns.values())]
                                          for r in rows])


def main(argv) -> None:
    specs = [a for a in argv if not a.startswith("--label=")]
    labels = [a.split("=", 1)[1] for a in argv if a.startswith("--label=")]
    labels += specs[len(labels):]
    try:
        print(table({lab: scores(read_runs(s)) for lab, s in zip(labels, specs)}))
    except (OSError, KeyError, ValueError) as exc:
        raise SystemExit(f"sweep_scores: {type(exc).__name__}: {exc}") from None


if __name__ == "__main__":
    main(sys.argv[1:])
