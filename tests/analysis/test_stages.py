"""The stages of an analysis (microfacet.analysis.stages): one enum for the timer, the
progress bar and the stage table of docs/architecture.md. That the pipeline runs them in this
order: test_pipeline.py; the progress bar: tests/cli/test_progress.py."""

from __future__ import annotations

import importlib
from pathlib import Path

import pytest

from microfacet.analysis.stages import JOINT_ONLY, Stage, stage_table

ARCHITECTURE = Path(__file__).resolve().parents[2] / "docs" / "architecture.md"


def _doc_table(text):
    """The Markdown table whose header is the stage table's, as it stands in the doc (its
    contiguous ``|`` lines), or None."""
    lines = text.splitlines()
    head = stage_table().splitlines()[0]
    starts = [i for i, line in enumerate(lines) if line.strip() == head]
    if not starts:
        return None
    out = []
    for line in lines[starts[0]:]:
        if not line.startswith("|"):
            break
        out.append(line.rstrip())
    return "\n".join(out)


def test_the_stage_table_is_the_one_in_the_architecture_doc():
    """docs/architecture.md shows the stages as :func:`stage_table` makes them, right after
    the sentence announcing that a test compares them."""
    text = ARCHITECTURE.read_text(encoding="utf-8")
    assert "(a test compares them):" in text
    assert _doc_table(text) == stage_table()
    after = text.split("(a test compares them):", 1)[1].lstrip("\n")
    assert after.startswith(stage_table().splitlines()[0])


def test_the_table_reader_finds_a_table_and_its_differences():
    """The comparison above can fail: the reader finds the table in a document, and a stale
    row makes it differ."""
    doc = f"intro (a test compares them):\n\n{stage_table()}\n\nmore text\n| other |"
    assert _doc_table(doc) == stage_table()
    stale = doc.replace("`normals`", "`surface_normals`")
    assert _doc_table(stale) != stage_table()
    assert _doc_table("no table here") is None


def test_the_table_has_one_row_per_stage_in_order():
    rows = stage_table().splitlines()
    assert rows[0] == "| stage (timing key) | function | produces |" and rows[1] == "|---|---|---|"
    assert len(rows) == 2 + len(Stage)
    for row, s in zip(rows[2:], Stage):
        cells = [c.strip() for c in row.strip("|").split(" | ")]
        assert cells[0] == f"`{s.key}`" and cells[1] == f"`{s.value.function}`"
        assert cells[2] == s.value.produces and "\n" not in row


def test_stages_have_unique_keys_labels_and_positive_weights():
    assert len({s.key for s in Stage}) == len({s.label for s in Stage}) == len(Stage)
    assert all(s.weight > 0 for s in Stage)
    order = list(Stage)
    assert order[0] is Stage.HEIGHT and order[-2:] == [Stage.WRITE, Stage.REPORT]
    assert order.index(Stage.ROI) < order.index(Stage.SEGMENTATION) < order.index(
        Stage.FACET_FITS) < order.index(Stage.TILT) < order.index(Stage.MIXTURES)
    assert JOINT_ONLY == (Stage.SEGMENTATION, Stage.FACET_FITS, Stage.SELF_CHECK)
    assert order.index(Stage.MIXTURES) < order.index(Stage.SELF_CHECK) < order.index(Stage.WRITE)


def _functions(spec):
    """``"analysis.joint.a / analysis.tilt.b"`` → the named objects (a bare name after the
    first takes the previous one's module)."""
    out, module = [], None
    for part in spec.split(" / "):
        *mod, name = part.strip().split(".")
        if mod:
            module = importlib.import_module("microfacet." + ".".join(mod))
        out.append(getattr(module, name))
    return out


@pytest.mark.parametrize("stage", list(Stage), ids=lambda s: s.key)
def test_every_function_the_table_names_exists(stage):
    fns = _functions(stage.value.function)
    assert fns and all(callable(f) for f in fns)
