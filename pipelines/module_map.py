"""The package's module map: lines, imports between modules, private names used across
modules, import cycles and layer violations.

    python -m pipelines.module_map            # the table and the checks
    python -m pipelines.module_map --json     # machine-readable

Not a study: the layer lint of the package, imported by tests/test_layout.py (``scan``,
``cycles``, ``violations``).

Imports are read from the source (``ast``), function-level imports included. A *layer
violation* is an import of a subpackage that sits above the importer in the one-way order of
docs/architecture.md (``LAYERS`` below); a *private use* is ``from x import _name`` or
``x._name`` where ``x`` is another microfacet module.
"""

from __future__ import annotations

import argparse
import ast
import json
import sys
from collections import defaultdict
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "microfacet"

#: The one-way order of the subpackages (lower index = lower layer); a module may import its
#: own layer and those below it.
LAYERS = ["core", "optics", "colour", "io", "focus", "analysis", "forward", "report", "render",
          "workflow", "cli", "napari"]
_COMPAT = {"thinfilm", "color"}  # re-export shims of the public names in shared/spec/api.md
_ENTRY = {"__main__"}            # ``python -m microfacet``: the command line's entry point


def module_name(path: Path) -> str:
    rel = path.relative_to(ROOT.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def layer_of(name: str) -> int | None:
    parts = name.split(".")
    if len(parts) < 2:
        return None
    top = parts[1]
    if top in LAYERS:
        return LAYERS.index(top)
    if top in _ENTRY:
        return len(LAYERS)
    if top in _COMPAT:
        return None
    return 0


def resolve(importer: str, is_pkg: bool, node: ast.ImportFrom) -> str:
    if node.level == 0:
        return node.module or ""
    base = importer.split(".")
    if not is_pkg:
        base = base[:-1]
    base = base[:len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def scan():
    modules = {}
    for path in sorted(ROOT.rglob("*.py")):
        name = module_name(path)
        src = path.read_text(encoding="utf-8")
        tree = ast.parse(src)
        is_pkg = path.name == "__init__.py"
        imports, function_imports, private = set(), set(), []
        top_level = {id(n) for n in tree.body}
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                mod = resolve(name, is_pkg, node)
                targets = [mod]
                for a in node.names:
                    sub = f"{mod}.{a.name}"
                    if (ROOT.parent / (sub.replace(".", "/") + ".py")).exists() or (
                            ROOT.parent / sub.replace(".", "/") / "__init__.py").exists():
                        targets.append(sub)
                    elif a.name.startswith("_") and not a.name.startswith("__") and \
                            mod.startswith("microfacet") and mod != name:
                        private.append(f"{mod}.{a.name}")
            for t in targets:
                if not t.startswith("microfacet") or t == name:
                    continue
                (imports if id(node) in top_level else function_imports).add(t)
        # x._name where x is an imported microfacet module alias
        aliases = {}
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                mod = resolve(name, is_pkg, node)
                for a in node.names:
                    sub = f"{mod}.{a.name}"
                    if (ROOT.parent / (sub.replace(".", "/") + ".py")).exists():
                        aliases[a.asname or a.name] = sub
        for node in ast.walk(tree):
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and \
                    node.value.id in aliases and node.attr.startswith("_") and \
                    not node.attr.startswith("__"):
                private.append(f"{aliases[node.value.id]}.{node.attr}")
        n_func_imports = sum(
            1 for f in ast.walk(tree) if isinstance(f, (ast.FunctionDef, ast.AsyncFunctionDef))
            for n in ast.walk(f) if isinstance(n, (ast.Import, ast.ImportFrom)))
        modules[name] = {
            "lines": src.count("\n") + 1,
            "imports": sorted(imports),
            "function_imports": sorted(function_imports - imports),
            "imports_inside_functions": n_func_imports,
            "private_uses": sorted(set(private)),
        }
    return modules


def _known(modules, target):
    while target and target not in modules:
        target = target.rpartition(".")[0]
    return target


def cycles(modules):
    graph = defaultdict(set)
    for m, info in modules.items():
        for t in info["imports"] + info["function_imports"]:
            k = _known(modules, t)
            if k and k != m and not m.startswith(k + "."):   # a package's own submodules
                graph[m].add(k)
    found, state, stack = set(), {}, []

    def visit(v):
        state[v] = 1
        stack.append(v)
        for w in graph[v]:
            if state.get(w) == 1:
                cyc = stack[stack.index(w):]
                i = cyc.index(min(cyc))
                found.add(tuple(cyc[i:] + cyc[:i]))
            elif w not in state:
                visit(w)
        stack.pop()
        state[v] = 2

    for v in list(graph):
        if v not in state:
            visit(v)
    return sorted(found)


def violations(modules):
    out = []
    for m, info in modules.items():
        lm = layer_of(m)
        if lm is None:
            continue
        for t in info["imports"] + info["function_imports"]:
            lt = layer_of(_known(modules, t) or t)
            if lt is not None and lt > lm:
                out.append((m, t))
    return sorted(set(out))


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args(argv)
    mods = scan()
    cyc, viol = cycles(mods), violations(mods)
    if args.json:
        print(json.dumps({"modules": mods, "cycles": cyc, "violations": viol}, indent=1))
        return 0
    print("| module | lines | imports (microfacet) | imports inside functions | "
          "private names of other modules |")
    print("|---|---:|---|---:|---|")
    for m, info in mods.items():
        deps = sorted({d.removeprefix("microfacet.") for d in
                       info["imports"] + info["function_imports"]})
        print(f"| {m} | {info['lines']} | {', '.join(deps)} | "
              f"{info['imports_inside_functions']} | {', '.join(info['private_uses'])} |")
    total = sum(i["lines"] for i in mods.values())
    big = [m for m, i in mods.items() if i["lines"] > 500]
    print(f"\n{len(mods)} modules, {total} lines; over 500 lines: {', '.join(big) or 'none'}")
    print(f"imports inside functions: {sum(i['imports_inside_functions'] for i in mods.values())}")
    print(f"private names used across modules: "
          f"{sum(len(i['private_uses']) for i in mods.values())}")
    print(f"import cycles: {len(cyc)}" + "".join(f"\n  {' -> '.join(c)}" for c in cyc))
    print(f"layer violations: {len(viol)}" + "".join(f"\n  {a} imports {b}" for a, b in viol))
    return 0


if __name__ == "__main__":
    sys.exit(main())
