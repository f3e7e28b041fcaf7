"""``batch_summary.csv``: one row per stack with the main numbers, and the results-folder
names of the stacks."""

from __future__ import annotations

import csv
import io
import os
import tempfile
from pathlib import Path

from ..core.errors import InputError
from ..io.lock import current_umask
from ..io.results import Results

__all__ = ["ERRORS_FILE", "SUMMARY_COLUMNS", "SUMMARY_FILE", "result_names", "row_from_results",
           "write_summary"]

SUMMARY_FILE = "batch_summary.csv"
ERRORS_FILE = "batch_errors.log"

#: Fixed columns of ``batch_summary.csv``; the mixture components follow as
#: ``thickness_{k}_weight, thickness_{k}_mean_nm, thickness_{k}_sd_nm`` and
#: ``ndf_{k}_weight, ndf_{k}_sd_deg`` for k = 1 … the most components of any stack.
SUMMARY_COLUMNS = (
    "stack", "results", "status", "reason", "time_s", "worker",
    "height_px", "width_px", "n_slices", "masked_fraction", "exposure",
    "delta_e_mean", "delta_e_median", "thickness_mean_nm", "thickness_sd_nm",
    "thickness_components", "ndf_rms_slope_deg", "ndf_components", "tilt_sigma_deg_median",
)


def result_names(stacks) -> list[str]:
    """Results-folder names for the stack paths: the folder name, made unique by prefixing
    parent folder names (joined by ``_``) where two stacks share a name.

    >>> result_names(["a/s1", "b/s1", "b/s2"])
    ['a_s1', 'b_s1', 's2']
    """
    parts = [Path(os.path.abspath(s)).parts for s in stacks]
    depth = [1] * len(parts)
    while True:
        names = ["_".join(p[-d:]) if len(p) > 1 else "stack" for p, d in zip(parts, depth)]
        seen: dict[str, list[int]] = {}
        for i, n in enumerate(names):
            seen.setdefault(n, []).append(i)
        clash = [i for idx in seen.values() if len(idx) > 1 for i in idx]
        grow = [i for i in clash if depth[i] < len(parts[i]) - 1]
        if not grow:
            if clash:  # the same stack given twice
                dup = sorted({str(stacks[i]) for i in clash})
                raise InputError(f"given more than once: {', '.join(dup)}", param="stacks")
            return names
        for i in grow:
            depth[i] += 1


def row_from_results(res: Results) -> dict:
    """The numbers of one results folder for ``batch_summary.csv``."""
    row = {}
    shape = res.get("inputs", "shape") or [None, None]
    row["height_px"], row["width_px"] = shape[0], shape[1]
    row["n_slices"] = res.get("inputs", "n_slices")
    row["masked_fraction"] = res.get("masked_fraction")
    row["exposure"] = res.get("exposure")
    row["delta_e_mean"] = res.get("delta_e", "mean")
    row["delta_e_median"] = res.get("delta_e", "median")
    mix = res.thickness_mixture()
    comps = mix.components if mix is not None else ()
    row["thickness_components"] = len(comps)
    if mix is not None:
        row["thickness_mean_nm"], row["thickness_sd_nm"] = mix.mean_nm, mix.sd_nm
    for k, (w, m, sd) in enumerate(comps, 1):
        row[f"thickness_{k}_weight"] = w
        row[f"thickness_{k}_mean_nm"] = m
        row[f"thickness_{k}_sd_nm"] = sd
    ndf = res.ndf_mixture()
    lobes = ndf.components if ndf is not None else ()
    row["ndf_components"] = len(lobes)
    if ndf is not None:
        row["ndf_rms_slope_deg"] = ndf.rms_sd_deg
    for k, (w, sd) in enumerate(lobes, 1):
        row[f"ndf_{k}_weight"] = w
        row[f"ndf_{k}_sd_deg"] = sd
    row["tilt_sigma_deg_median"] = res.get("tilt_information", "tilt_sigma_deg_median")
    return row


def write_summary(path: Path, rows: list[dict]) -> None:
    """Write ``batch_summary.csv`` atomically (a temporary sibling renamed over it)."""
    extra = []
    for prefix, fields in (("thickness", ("weight", "mean_nm", "sd_nm")),
                           ("ndf", ("weight", "sd_deg"))):
        k_max = max((int(r.get(f"{prefix}_components") or 0) for r in rows), default=0)
        extra += [f"{prefix}_{k}_{f}" for k in range(1, k_max + 1) for f in fields]
    columns = list(SUMMARY_COLUMNS) + extra
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: _csv_value(r.get(c)) for c in columns})
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=path.parent)
    with os.fdopen(fd, "w", newline="") as fh:
        fh.write(buf.getvalue())
    os.chmod(tmp, 0o666 & ~current_umask())
    os.replace(tmp, path)


def _csv_value(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return f"{v:.6g}"
    return v


