"""`microfacet analyze` against decoding its slices, at 1, 4 and 12 megapixels.

For each size an nd-preset stack of ``slices`` slices is generated (cached in ``work``,
default ``out/stacks``), then, in one run on the same machine:

- **decode**: reading and decoding every slice alone (``Stack.read_slice``), the baseline;
- **analyze**: the whole ``microfacet analyze STACK --out OUT`` command, report included, in
  a fresh process (imports included), its wall time and peak RSS (``os.wait4``), and the
  per-stage ``timings_s`` of its summary.json.

Ratios to the decode time of the same run are what docs/benchmarks.md quotes (this machine is
shared and noisy); ``repeat`` keeps the fastest of several runs. With ``baseline`` (a git
revision, e.g. ``HEAD~1``) the same command of that revision (a temporary worktree) runs
interleaved with this checkout's, round by round, and the table adds its times and the ratio
of this checkout's to them. How the run met the targets of the speed issue is said on
stderr.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import best_of, md_table, note

STUDY = Study(
    name="speed-analyze",
    question="What does `microfacet analyze` cost, stage by stage, against decoding the "
             "slices, at 1, 4 and 12 megapixels?",
    doc=("docs/benchmarks.md", "speed-analyze"),
    run_time="15 min",
    quick_time="13 s",
    options={"sizes": ("1,4,12", "megapixels, comma-separated"),
             "slices": (40, "slices per stack"),
             "work": ("", "cache folder for the stacks (default out/stacks)"),
             "repeat": (1, "runs per size (the fastest is kept)"),
             "baseline": ("", "a git revision to compare with, interleaved (e.g. HEAD~1)")},
)

#: The targets of the speed issue, second round (issue 26; docs/benchmarks.md).
TARGET_STAGES_X = 4.0       # analysis stages together / decode
TARGET_WHOLE_X_1MP = 6.0    # whole analyze, report included / decode, at 1 MP
TARGET_RSS_1MP_MB = 400.0
TARGET_RSS_PER_MP_MB = 120.0
TARGET_12MP_S = 60.0



def stages() -> tuple:
    """The analysis stages' ``timings_s`` keys (without writing and the report)."""
    from microfacet.analysis.stages import Stage

    return tuple(s.value.key for s in Stage if s not in (Stage.WRITE, Stage.REPORT))


def stack_for(work: Path, mp: float, slices: int) -> Path:
    side = int(round(np.sqrt(mp * 1e6) / 16.0)) * 16
    path = work / f"nd-{side}x{side}-{slices}"
    if not (path / "stack.json").is_file():
        # by `microfacet synth` in a child process: Linux carries a parent's high-water RSS
        # into the children it starts, so a stack made here would set the measured peaks
        subprocess.run([sys.executable, "-m", "microfacet", "-q", "synth", "--preset", "nd",
                        "--seed", "3", "--size", f"{side}x{side}", "--slices", str(slices),
                        str(path)], check=True)
    return path


def decode_time(path: Path) -> float:
    from microfacet.io.limits import Limits
    from microfacet.io.stack import read_stack
    st = read_stack(path, limits=Limits(max_megapixels=100, max_stack_megapixels=2000))

    def decode_all():
        for i in range(st.n_slices):
            st.read_slice(i, dtype=np.uint8)
    t, _ = best_of(decode_all, 2)
    return t


def run_analyze(path: Path, out: Path, extra=(), *, checkout: Path | None = None):
    """Wall time (s), peak RSS (MB) and summary of one ``microfacet analyze`` process (of the
    package in ``checkout``, default the one this study imports)."""
    if out.exists():
        shutil.rmtree(out)
    cmd = [sys.executable, "-m", "microfacet", "analyze", str(path), "--out", str(out), "-q",
           "--max-megapixels", "100", "--max-stack-megapixels", "2000", *extra]
    env = cwd = None
    if checkout is not None:    # run from outside any checkout, that one first on the path
        env = dict(os.environ, PYTHONPATH=str(checkout))
        cwd = str(checkout.parent)
    t0 = time.perf_counter()
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, env=env,
                            cwd=cwd)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - t0
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    if status != 0:
        raise SystemExit(f"analyze failed on {path}: {err.strip()}")
    summary = json.loads((out / "summary.json").read_text())
    return wall, usage.ru_maxrss / 1024.0, summary


def baseline_checkout(revision: str, work: Path) -> Path:
    """A worktree of ``revision`` of this repository (detached, in ``work``; made again on
    every run), for the interleaved comparison."""
    repo = Path(__file__).resolve().parents[2]
    where = work / "baseline-checkout"
    _remove_checkout(where)
    subprocess.run(["git", "-C", str(repo), "worktree", "add", "--detach", "-f", str(where),
                    revision], check=True, capture_output=True)
    return where


def _remove_checkout(where: Path) -> None:
    repo = Path(__file__).resolve().parents[2]
    subprocess.run(["git", "-C", str(repo), "worktree", "remove", "--force", str(where)],
                   capture_output=True)
    shutil.rmtree(where, ignore_errors=True)


def _column(mp, dec, res, keys):
    wall, rss, summary = res
    t = summary["timings_s"]
    h, w = summary["inputs"]["shape"]
    return dict(mp=h * w / 1e6, decode=dec, wall=wall, rss=rss, t=t,
                stages=sum(t.get(k, 0.0) for k in keys))


def targets(cols) -> list:
    """One line per target of the speed issue: met or missed."""
    lines = []
    c = list(cols.values())
    for col in c:
        ok = col["stages"] / col["decode"] <= TARGET_STAGES_X
        lines.append(f"{col['mp']:.1f} MP: analysis stages {col['stages'] / col['decode']:.1f}x "
                     f"decode (target <= {TARGET_STAGES_X:g}x) {'met' if ok else 'MISSED'}")
    one = min(c, key=lambda x: abs(x["mp"] - 1.0))
    if abs(one["mp"] - 1.0) < 0.2:
        x = one["wall"] / one["decode"]
        lines.append(f"1 MP: whole command {x:.1f}x decode (target <= {TARGET_WHOLE_X_1MP:g}x) "
                     f"{'met' if x <= TARGET_WHOLE_X_1MP else 'MISSED'}")
        lines.append(f"1 MP: peak RSS {one['rss']:.0f} MB (target <= {TARGET_RSS_1MP_MB:g}) "
                     f"{'met' if one['rss'] <= TARGET_RSS_1MP_MB else 'MISSED'}")
    if len(c) > 1:
        slope = np.polyfit([x["mp"] for x in c], [x["rss"] for x in c], 1)[0]
        lines.append(f"RSS growth {slope:.0f} MB per MP (target <= {TARGET_RSS_PER_MP_MB:g}) "
                     f"{'met' if slope <= TARGET_RSS_PER_MP_MB else 'MISSED'}")
    big = max(c, key=lambda x: x["mp"])
    if big["mp"] > 10:
        ok = big["wall"] < TARGET_12MP_S
        lines.append(f"{big['mp']:.1f} MP: {big['wall']:.0f} s (target < {TARGET_12MP_S:g} s) "
                     f"{'met' if ok else 'MISSED'}")
    return lines


def _measure(path, out, extra, repeat, checkouts):
    """The fastest of ``repeat`` runs of each checkout (None: this one), interleaved."""
    best = {c: None for c in checkouts}
    for _ in range(max(1, repeat)):
        for c in checkouts:
            res = run_analyze(path, out / f"results-{path.name}{'-baseline' if c else ''}",
                              extra, checkout=c)
            if best[c] is None or res[0] < best[c][0]:
                best[c] = res
    return best


def run(*, quick: bool, out: Path, sizes="1,4,12", slices=40, work="", repeat=1,
        baseline="") -> str:
    mps = [float(s) for s in sizes.split(",")]
    if quick:
        mps, slices, repeat = [0.0164], min(slices, 8), 1   # 128 x 128
    work = Path(work) if work else out / "stacks"
    work.mkdir(parents=True, exist_ok=True)
    base = baseline_checkout(baseline, work) if baseline else None
    try:
        cols, base_cols = _sizes(mps, slices, work, out, quick, repeat, base)
    finally:
        if base is not None:
            _remove_checkout(base)
    note(f"nd preset, {slices} slices, `microfacet analyze` in a fresh process "
         f"(python {sys.version.split()[0]}, {os.cpu_count()} cores)"
         + (f"; baseline {baseline} interleaved" if base else ""))
    note("targets:\n  " + "\n  ".join(targets(cols)))
    return _table(cols, base_cols, stages(), baseline)


def _sizes(mps, slices, work, out, quick, repeat, base):
    """Per size: this checkout's column and the baseline's (empty without one)."""
    checkouts = [base, None] if base else [None]
    keys = stages()
    cols, base_cols = {}, {}
    for mp in mps:
        path = stack_for(work, mp, slices)
        dec = decode_time(path)
        best = _measure(path, out, ["--no-report"] if quick else (), repeat, checkouts)
        cols[mp] = _column(mp, dec, best[None], keys)
        if base:
            base_cols[mp] = _column(mp, dec, best[base], keys)
        c = cols[mp]
        note(f"{path.name}: decode {dec:.2f} s, analyze {c['wall']:.1f} s, peak RSS "
             f"{c['rss']:.0f} MB" + (f" (baseline {base_cols[mp]['wall']:.1f} s, "
                                      f"{base_cols[mp]['rss']:.0f} MB)" if base else ""))
    return cols, base_cols


def _table(cols, base_cols, keys, baseline) -> str:
    names = [f"{c['mp']:.1f} MP" if c["mp"] >= 0.1 else f"{c['mp']:.3f} MP"
             for c in cols.values()]
    cs, bs = list(cols.values()), list(base_cols.values())

    def row(label, get, fmt="{:.2f}"):
        vals = [get(c) for c in cs]
        cells = ["" if v is None else fmt.format(v) for v in vals]
        cells += ["" if v is None else f"{v / c['decode']:.2f}" for v, c in zip(vals, cs)]
        if bs:
            old = [get(b) for b in bs]
            cells += ["" if v is None else fmt.format(v) for v in old]
            cells += ["" if (v is None or o is None or o <= 0) else f"{v / o:.2f}"
                      for v, o in zip(vals, old)]
        return [label, *cells]

    rows = [row("decode the slices", lambda c: c["decode"])]
    rows += [row(k, lambda c, k=k: c["t"].get(k)) for k in keys + ("write", "report")]
    rows.append(row("**analysis stages**", lambda c: c["stages"]))
    rows.append(row("**whole command (wall)**", lambda c: c["wall"]))
    rss = row("peak RSS (MB)", lambda c: c["rss"], "{:.0f}")
    rss[1 + len(cs):1 + 2 * len(cs)] = [""] * len(cs)          # no ratio to decode
    rows.append(rss)
    head = ["", *[f"{n} (s)" for n in names], *[f"{n} (× decode)" for n in names]]
    if bs:
        head += [f"{n}, {baseline} (s)" for n in names]
        head += [f"{n}: this / {baseline}" for n in names]
    return md_table(head, rows)
