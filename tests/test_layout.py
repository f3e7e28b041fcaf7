"""The package's shape, checked on its source (``ast``): one-way layers without cycles,
functions short enough to read at once, few parameters in the analysis, and every default of
an option declared once (docs/architecture.md, "Rules a module follows").

The import graph comes from the module-map study (``python -m pipelines.module_map``),
loaded here from its file so that both read the package the same way.
"""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

import pytest

from microfacet.analysis.options import AnalysisOptions
from microfacet.core.options import option_fields

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "microfacet"
#: Longest function anywhere in the package, and most parameters of a function in analysis/.
MAX_FUNCTION_LINES = 120
MAX_ANALYSIS_PARAMETERS = 8
#: The modules that declare the one default of each option (they may repeat it).
DEFAULT_HOMES = {"analysis/options.py", "focus/options.py", "optics/defaults.py",
                 "core/defaults.py", "core/options.py"}
#: Parameters that share an option's name and value but are another setting: the spectrum
#: fit's own thickness grid (not the ROI scan's).
NOT_THE_OPTION = {("optics/spectrumfit.py", "grid_step_nm")}
#: Where "D65" names the sRGB standard's white point, which is D65 by definition (not a
#: default the user could change).
STANDARD_CONSTANTS = {"colour/srgb.py"}


def _module_map():
    path = ROOT / "pipelines" / "module_map.py"   # the layer lint (not a study)
    spec = importlib.util.spec_from_file_location("_module_map", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _functions():
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                yield rel, node


def _n_parameters(node) -> int:
    a = node.args
    names = [x.arg for x in a.posonlyargs + a.args + a.kwonlyargs]
    names += [x.arg for x in (a.vararg, a.kwarg) if x is not None]
    return len([n for n in names if n not in ("self", "cls")])


@pytest.mark.slow
def test_layers_are_one_way_without_cycles():
    mm = _module_map()
    modules = mm.scan()
    assert mm.cycles(modules) == []
    assert mm.violations(modules) == []
    assert sum(len(i["private_uses"]) for i in modules.values()) == 0


@pytest.mark.slow
def test_no_function_is_longer_than_a_screenful():
    long = [f"{rel}:{n.lineno} {n.name} ({n.end_lineno - n.lineno + 1} lines)"
            for rel, n in _functions() if n.end_lineno - n.lineno + 1 > MAX_FUNCTION_LINES]
    assert long == []


@pytest.mark.slow
def test_analysis_functions_take_few_parameters():
    many = [f"{rel}:{n.lineno} {n.name} ({_n_parameters(n)})" for rel, n in _functions()
            if rel.startswith("analysis/") and _n_parameters(n) > MAX_ANALYSIS_PARAMETERS]
    assert many == []


def _literal(node):
    try:
        return ast.literal_eval(node)
    except ValueError:
        return None


def _option_defaults() -> dict:
    """``{parameter name: default}`` a function would use to repeat an option's default: the
    field's name and its flattened path (``roi.size_px`` → ``size_px``, ``roi_size_px``)."""
    out = {}
    for f in option_fields(AnalysisOptions):
        if f.default is None or f.path == "seed":   # None: "not given"; seed: any RNG's seed
            continue
        for name in (f.field.name, f.path.replace(".", "_")):
            out[name] = f.default
    return out


@pytest.mark.slow
def test_every_option_default_is_declared_once():
    """No function outside the options modules gives a parameter named after an option the
    option's default as a literal (it takes the option's section, or no default)."""
    defaults = _option_defaults()
    repeats = []
    for rel, node in _functions():
        if rel in DEFAULT_HOMES:
            continue
        a = node.args
        pos = a.posonlyargs + a.args
        pairs = list(zip(pos[len(pos) - len(a.defaults):], a.defaults))
        pairs += [(x, d) for x, d in zip(a.kwonlyargs, a.kw_defaults) if d is not None]
        for arg, default in pairs:
            value = _literal(default)
            if (arg.arg in defaults and value is not None and value == defaults[arg.arg]
                    and (rel, arg.arg) not in NOT_THE_OPTION):
                repeats.append(f"{rel}:{node.lineno} {node.name}({arg.arg}={value!r})")
    assert repeats == []


@pytest.mark.slow
@pytest.mark.parametrize("literal", ["D65"])
def test_defaults_of_the_optics_are_named_not_repeated(literal):
    """The default illuminant is ``optics.defaults.DEFAULT_ILLUMINANT``: no other module
    writes it as a string in code (docstrings and comments may)."""
    found = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel in DEFAULT_HOMES | STANDARD_CONSTANTS:
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        docs = {id(n.body[0].value) for n in ast.walk(tree)
                if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef,
                                  ast.AsyncFunctionDef))
                and n.body and isinstance(n.body[0], ast.Expr)
                and isinstance(n.body[0].value, ast.Constant)}
        found += [f"{rel}:{n.lineno}" for n in ast.walk(tree)
                  if isinstance(n, ast.Constant) and n.value == literal and id(n) not in docs]
    assert found == []
