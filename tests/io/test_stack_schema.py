"""The keys of stack.json as data (microfacet.io.stack_schema): the table of keys in
docs/stack-format.md is the one the specs generate, every key refuses a value outside its
spec with one line naming the file and the key, and accepts its default (and its bounds).

To regenerate the doc's table after changing a spec::

    python -c "from pathlib import Path; from microfacet.io.stack_schema import embed_table; \
p = Path('docs/stack-format.md'); p.write_text(embed_table(p.read_text()))"
"""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.stack import read_stack
from microfacet.io.stack_schema import (
    ABSENT,
    EXCLUSIVE,
    KINDS,
    KNOWN_KEYS,
    MARKERS,
    SPECS,
    TOGETHER,
    KeySpec,
    embed_table,
    markdown_table,
)

DOC = Path(__file__).resolve().parents[2] / "docs" / "stack-format.md"
H, W = 12, 17  # the size of the random_images fixture (tests/io/conftest.py)


def _doc_table(text: str) -> str:
    start, end = MARKERS
    assert text.count(start) == 1 and text.count(end) == 1, "the table's markers"
    return text.split(start, 1)[1].split(end, 1)[0].strip("\n")


def test_the_docs_table_of_keys_is_generated_from_the_specs():
    text = DOC.read_text(encoding="utf-8")
    assert _doc_table(text) == markdown_table(), (
        "docs/stack-format.md's table of keys is not the specs' (regenerate it: see this "
        "module's docstring)")
    assert embed_table(text) == text


def test_the_table_has_one_row_per_key_and_key_of_an_object():
    rows = [line.split("|")[1].strip().strip("`") for line in markdown_table().splitlines()[2:]]
    inner = [f"{s.name}.{f.name}" for s in SPECS.values() for f in s.fields]
    assert sorted(rows) == sorted(list(KNOWN_KEYS) + inner)
    assert all(s.doc and s.kind in KINDS for s in SPECS.values())


def test_the_rules_name_specified_keys():
    named = [k for pair in EXCLUSIVE for k in pair]
    named += [k for pair, _ in TOGETHER for k in pair]
    assert set(named) <= set(SPECS)
    with pytest.raises(ValueError, match="kind"):
        KeySpec("x", "colour", "no such kind")


# ---------------------------------------------------------------- values outside the spec
def _bad_numbers(spec: KeySpec) -> list:
    out = [float("nan"), float("inf"), "1", True, [1.0]]
    if spec.low is not None:
        out.append(spec.low if spec.low_exclusive else spec.low - 1)
    if spec.high is not None:
        out.append(spec.high + 1)
    if spec.nonzero:
        out.append(0)
    return out


def _bad_values(spec: KeySpec) -> list:
    """Values the spec does not allow (its kind, its range, its choices)."""
    null = [] if spec.null_absent else [None]
    if spec.kind == "number":
        return _bad_numbers(spec) + null
    if spec.kind == "size":
        return [v for v in _bad_numbers(spec) if v != [1.0]] + [[], [1, 2, 3], [1, -1]]
    if spec.choices is not None:
        return ["not-one-of-them", 5] + null
    if spec.kind in ("string", "name"):
        return [5, ["x"]] + null + (["", "  "] if spec.kind == "name" else [])
    if spec.kind == "path":
        wrong_type = ["slices/000.png"] if spec.suffixes else []
        return ["", 5, "../outside.png", "/abs/x.png", "missing.png", "a\x00b"] + wrong_type \
            + null
    if spec.kind == "paths":
        return [[], "slices/000.png", [5], ["slices/000.png", "../outside.png"]] + null
    if spec.kind == "numbers":
        return ["x", [0, 1, None], [0, 1, float("nan")], [0, 1], [0, 0, 1]] + null
    if spec.kind == "object":
        return [5, [], "x"] + null
    return []                                                # "any": not read


def _cases():
    for spec in SPECS.values():
        for value in _bad_values(spec):
            yield pytest.param(spec.name, None, value, id=f"{spec.name}={value!r}")
        for sub in spec.fields:
            for value in _bad_values(sub):
                yield pytest.param(spec.name, sub.name, value,
                                   id=f"{spec.name}.{sub.name}={value!r}")
        if spec.required:
            yield pytest.param(spec.name, None, ABSENT, id=f"{spec.name} absent")


@pytest.fixture
def stack(tmp_path, good_stack):
    """``stack(**changes)``: a valid stack with slices and an export (``h.npy``,
    ``image.png``), stack.json changed (ABSENT removes a key)."""
    def make(**changes):
        d = good_stack()
        np.save(d / "h.npy", np.zeros((H, W), np.float32))
        shutil.copy(d / "slices/000.png", d / "image.png")
        (tmp_path / "outside.png").write_bytes((d / "slices/000.png").read_bytes())
        meta = json.loads((d / "stack.json").read_text())
        meta.update({"height_um": "h.npy", "image": "image.png"})
        for key, value in changes.items():
            if value is ABSENT:
                meta.pop(key, None)
            else:
                meta[key] = value
        (d / "stack.json").write_text(json.dumps(meta))
        return d
    return make


def _without_partners(key: str) -> dict:
    """The keys that may not be given with ``key`` removed."""
    return {b if a == key else a: ABSENT for a, b in EXCLUSIVE if key in (a, b)}


@pytest.mark.parametrize("key,sub,value", list(_cases()))
def test_a_value_outside_its_spec_is_refused_naming_the_key(stack, key, sub, value):
    changes = _without_partners(key)
    changes[key] = {sub: value} if sub else value
    d = stack(**changes)
    named = rf"stack\.json: key '{key}'" + (rf": {sub}" if sub else "")
    with pytest.raises(InputError, match=named) as ei:
        read_stack(d)
    assert "\n" not in str(ei.value)


def test_every_key_but_an_unread_one_has_values_it_refuses():
    assert [s.name for s in SPECS.values() if not _bad_values(s)] == ["synthetic"]


# --------------------------------------------------------------------- values it accepts
@pytest.mark.parametrize("spec", [s for s in SPECS.values()
                                  if s.default is not ABSENT or s.fields],
                         ids=lambda s: s.name)
def test_every_default_is_accepted_and_is_the_value_when_absent(stack, spec):
    given = read_stack(stack(**{spec.name: spec.default_value()}))
    absent = read_stack(stack(**{spec.name: ABSENT}))
    assert getattr(given, spec.name) == spec.default_value() == getattr(absent, spec.name)
    for sub in spec.fields:
        st = read_stack(stack(**{spec.name: {sub.name: sub.default}}))
        assert getattr(st, spec.name)[sub.name] == sub.default


def _bounds():
    for spec in SPECS.values():
        for s, inside in [(spec, None)] + [(f, spec.name) for f in spec.fields]:
            as_list = (lambda v: [v] * s.length) if s.length else (lambda v: v)
            for bound, open_ in ((s.low, s.low_exclusive), (s.high, False)):
                if bound is not None and not open_:
                    yield pytest.param(s.name, inside, as_list(bound), id=f"{s.name}={bound}")
                elif bound is not None:
                    yield pytest.param(s.name, inside,
                                       as_list(math.nextafter(bound, math.inf)),
                                       id=f"{s.name} just above {bound}")


@pytest.mark.parametrize("key,inside,value", list(_bounds()))
def test_values_at_the_bounds_are_accepted(stack, key, inside, value):
    changes = {inside: {key: value}} if inside else {key: value}
    read_stack(stack(**changes))


@pytest.mark.parametrize("key", ["exposure", "pixel_size_um"])
def test_null_counts_as_absent_where_the_spec_says_so(stack, key):
    assert SPECS[key].null_absent
    changes = {key: None}
    st = read_stack(stack(**changes), pixel_size_um=0.5)
    assert st.exposure is None if key == "exposure" else st.pixel_size_yx_um == (0.5, 0.5)
