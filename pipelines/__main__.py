"""``python -m pipelines list`` and ``python -m pipelines run NAME [--quick] [--docs]
[--out DIR] [--set KEY=VALUE ...]`` (see :mod:`pipelines`)."""

from __future__ import annotations

import argparse
import shutil
import sys
import time
from pathlib import Path

from pipelines import ROOT, find, is_protected, registry, replace_block


def _cell(text) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def list_studies() -> str:
    """The registry as a Markdown table."""
    rows = ["| study | question | doc block | run time | quick run |", "|---|---|---|---|---|"]
    for name, mod in registry().items():
        s = mod.STUDY
        doc = f"{s.doc[0]} `{s.doc[1]}`" if s.doc else "–"
        rows.append("| " + " | ".join(_cell(c) for c in (
            f"`{name}`", s.question, doc, s.run_time, s.quick_time or "–")) + " |")
    return "\n".join(rows)


def _options_help(study) -> str:
    if not study.options:
        return f"{study.name}: no options"
    return "\n".join([f"{study.name} options (--set KEY=VALUE):"] + [
        f"  {k} (default {v[0]!r}): {v[1]}" for k, v in study.options.items()])


def run_study(name, *, quick=False, docs=False, out=None, settings=()) -> int:
    mod = find(name)
    study = mod.STUDY
    options = study.parse_options(settings)
    if docs:
        if quick:
            raise SystemExit("--docs records a full run: drop --quick")
        if options:
            raise SystemExit(f"--docs records the default run: drop --set "
                             f"{' '.join(settings)}")
        if study.doc is None and not study.doc_files:
            raise SystemExit(f"{name} regenerates no doc")
    out = Path(out) if out else ROOT / "out" / "studies" / name
    if is_protected(out):
        raise SystemExit(f"--out {out}: inside an input folder (docs/, fixtures/, microfacet/, "
                         f"tests/); studies write only their own output folder")
    out.mkdir(parents=True, exist_ok=True)
    print(f"{name}{' (quick)' if quick else ''}: {study.question}", file=sys.stderr, flush=True)
    t0 = time.perf_counter()
    text = mod.run(quick=quick, out=out, **options)
    elapsed = time.perf_counter() - t0
    if not isinstance(text, str) or not text.strip():
        raise SystemExit(f"{name}: run() returned no table")
    print(text.rstrip() + "\n", flush=True)
    print(f"{name}: {elapsed:.1f} s; outputs in {out}", file=sys.stderr)
    if docs:
        if study.doc is not None:
            path, block = study.doc
            replace_block(ROOT / path, block, text)
            print(f"{name}: rewrote the block {block!r} of {path}", file=sys.stderr)
        for src, dst in study.doc_files.items():
            shutil.copyfile(out / src, ROOT / dst)
            print(f"{name}: copied {src} to {dst}", file=sys.stderr)
    return 0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m pipelines",
                                 description="The studies of microfacet (pipelines/studies).")
    sub = ap.add_subparsers(dest="command", required=True)
    sub.add_parser("list", help="the registry: name, question, doc block, run times")
    r = sub.add_parser("run", help="run one study and print its table")
    r.add_argument("name")
    r.add_argument("--quick", action="store_true", help="small sizes and counts (a check)")
    r.add_argument("--docs", action="store_true",
                   help="rewrite the study's doc block (and figures) with this run")
    r.add_argument("--out", default=None,
                   help="output folder (default out/studies/NAME); never an input folder")
    r.add_argument("--set", dest="settings", action="append", default=[], metavar="KEY=VALUE",
                   help="a study option (repeatable); --set help lists them")
    args = ap.parse_args(argv)
    if args.command == "list":
        print(list_studies())
        return 0
    try:
        mod = find(args.name)
    except KeyError as exc:
        ap.error(exc.args[0])
    if args.settings == ["help"]:
        print(_options_help(mod.STUDY))
        return 0
    try:
        return run_study(args.name, quick=args.quick, docs=args.docs, out=args.out,
                         settings=args.settings)
    except ValueError as exc:
        if str(exc).startswith("--set"):
            ap.error(str(exc))
        raise


if __name__ == "__main__":
    sys.exit(main())
