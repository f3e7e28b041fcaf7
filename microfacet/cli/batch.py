"""``microfacet batch STACK... --out DIR``: many stacks, locally or on a Dask cluster."""

from __future__ import annotations

import sys
from pathlib import Path

from .. import workflow
from ..core.errors import InputError
from ..core.threads import limit_malloc_arenas
from .options import HelpFormatter, add_analysis_options, analysis_options, example_epilog
from .progress import Progress

#: Exit status when the batch ran but at least one stack failed.
EXIT_SOME_FAILED = 1
#: Exit status after Ctrl-C (128 + SIGINT), as for every command.
EXIT_INTERRUPTED = 130


def register(sub):
    p = sub.add_parser(
        "batch",
        help="analyse many stacks in parallel, locally or on a Dask cluster",
        description=(
            "Runs `microfacet analyze` on every STACK and writes DIR/<stack name>/ (the results "
            "folder) for each, plus DIR/batch_summary.csv with one row per stack (status, "
            "reason, thickness mixture, NDF lobes, dE00, masked fraction, time) and "
            "DIR/batch_errors.log with the tracebacks of failed stacks. A failing stack does "
            "not stop the others. A rerun skips stacks whose results are complete, so an "
            "interrupted batch resumes where it stopped. With --scheduler the stacks run on an "
            "existing Dask distributed cluster; its workers need microfacet installed and the "
            "stack and output folders under the same paths (a shared file system). Exit "
            "status: 0 when every stack is done or skipped, 1 when some failed (see the "
            "summary), 2 for bad arguments."),
        epilog=example_epilog(
            "microfacet batch drawer/* --out results --jobs 4",
            "microfacet batch drawer/* --out results --scheduler local --jobs 2",
            "microfacet batch --stacks-from list.txt --out results --scheduler tcp://head:8786",
            "microfacet batch drawer/* --out results --mode seed --overwrite"),
        formatter_class=HelpFormatter,
    )
    p.add_argument("stacks", nargs="*", metavar="STACK", help="stack folders")
    p.add_argument("--stacks-from", metavar="FILE", default=None,
                   help="also read stack folders from FILE, one per line ('#' comments)")
    p.add_argument("--out", required=True, metavar="DIR",
                   help="output folder (created; one results folder per stack)")
    run_g = p.add_argument_group("execution")
    run_g.add_argument("--jobs", type=int, default=None, metavar="N",
                       help="local worker processes (default: CPU count); 1 = in this process")
    run_g.add_argument("--scheduler", default=None, metavar="ADDRESS",
                       help="run on the Dask distributed scheduler at ADDRESS "
                            "(e.g. tcp://10.0.0.5:8786) instead of local processes; 'local' "
                            "starts a Dask LocalCluster of --jobs workers on this machine")
    add_analysis_options(p)
    p.add_argument("--no-report", action="store_true", help="skip each report.pdf")
    p.add_argument("--overwrite", action="store_true",
                   help="re-analyse stacks whose results already exist")
    p.set_defaults(run=run)
    return p


def _read_list(path: str) -> list[str]:
    try:
        text = Path(path).read_text()
    except OSError as exc:
        raise InputError(f"--stacks-from: {path}: {exc.strerror or exc}") from None
    base = Path(path).parent
    out = []
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        if line:
            p = Path(line)
            out.append(str(p if p.is_absolute() else base / p))
    return out


def run(args) -> int:
    limit_malloc_arenas()         # an in-process batch runs the analysis' threads here
    stacks = list(args.stacks)
    if args.stacks_from:
        stacks += _read_list(args.stacks_from)
    if not stacks:
        raise ValueError("STACK: give at least one stack folder (or --stacks-from FILE)")
    if args.jobs is not None and args.jobs < 1:
        raise ValueError(f"--jobs: must be >= 1, got {args.jobs}")
    opts = analysis_options(args)

    with Progress("batch", total=len(stacks), unit="stacks", quiet=args.quiet) as bar:
        try:
            result = workflow.run_batch(stacks, args.out, options=opts, jobs=args.jobs,
                               scheduler=args.scheduler, overwrite=args.overwrite,
                               report=not args.no_report,
                               progress=lambda done, total, row: bar.update(done, total))
        except workflow.BatchInterrupted as exc:
            interrupted = exc
        else:
            interrupted = None
    if interrupted is not None:  # after the bar's line is ended
        print(f"microfacet batch: interrupted; {interrupted.done} of {interrupted.total} "
              f"stacks done, rerun to resume", file=sys.stderr)
        return EXIT_INTERRUPTED
    n_failed = result.n_failed
    if not args.quiet:
        print(f"{len(result.rows)} stacks: {result.count('done')} done, "
              f"{result.count('skipped')} skipped (complete), {n_failed} failed "
              f"in {result.elapsed_s:.1f} s; summary: {result.summary_csv}", file=sys.stderr)
    return EXIT_SOME_FAILED if n_failed else 0
