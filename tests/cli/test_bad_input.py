"""Broken stacks through the command line, end to end (``analyze`` and ``height``).

Every case must exit with status 2 and print one line on stderr that names the file and the
key (or slice) at fault, with no traceback; no results folder and no ``.partial`` temporary
folder may be left beside ``--out``, and the input stack must be unchanged (files hashed
before and after).

``read_stack`` itself is tested on most of these cases in tests/io/test_stack_checks.py
(test_bad_stack_json, test_truncated_image, test_mismatched_sizes_depths_channels, ...), and
a few through ``height`` in tests/cli/test_height.py; this is the complete CLI suite. The
mutations start from one small valid stack (64×64 px RGB, 5 slices) written with
:func:`microfacet.io.stack.write_stack`.
"""

from __future__ import annotations

import hashlib
import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from microfacet.cli import main
from microfacet.io.images import write_image
from microfacet.io.stack import read_stack, write_stack

H = W = 64
N = 5


def _valid_stack(folder: Path) -> Path:
    rng = np.random.default_rng(0)
    imgs = [rng.integers(0, 256, (H, W, 3), dtype=np.uint8) for _ in range(N)]
    write_stack(folder, imgs, z_um=[0.0, 0.5, 1.0, 1.5, 2.0], pixel_size_um=0.25)
    read_stack(folder)  # it really is valid
    return folder


def _edit_json(d: Path, **changes):
    meta = json.loads((d / "stack.json").read_text())
    for k, v in changes.items():
        if v is None:
            meta.pop(k, None)
        else:
            meta[k] = v
    (d / "stack.json").write_text(json.dumps(meta, indent=1))


def _replace_in_json(d: Path, old: str, new: str):
    """Edit the raw text (for the JSON literals NaN / Infinity that json.dumps will not
    write on purpose)."""
    text = (d / "stack.json").read_text()
    assert old in text
    (d / "stack.json").write_text(text.replace(old, new, 1))


def _truncate(p: Path):
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])


def _corrupt_inside(p: Path):
    # intact signature, header and IEND: passes validation, fails to decode
    data = bytearray(p.read_bytes())
    for k in range(40, len(data) - 20):
        data[k] = 0x55
    p.write_bytes(bytes(data))


def _outside(d: Path):
    shutil.copy(d / "slices/001.png", d.parent / "outside.png")
    _edit_json(d, slices=["slices/000.png", "../outside.png", "slices/002.png",
                          "slices/003.png", "slices/004.png"])


# (id, mutation, regex the one-line message must match: file and key)
CASES = [
    ("missing-stack-json", lambda d: (d / "stack.json").unlink(),
     r"stack/stack\.json: missing stack\.json"),
    ("invalid-json", lambda d: (d / "stack.json").write_text('{"format": '),
     r"stack/stack\.json: invalid JSON"),
    ("wrong-format", lambda d: _edit_json(d, format="microfacet-stack/9"),
     r"stack/stack\.json: key 'format': 'microfacet-stack/9' is not"),
    ("missing-format", lambda d: _edit_json(d, format=None),
     r"stack/stack\.json: key 'format': missing"),
    ("missing-pixel-size", lambda d: _edit_json(d, pixel_size_um=None),
     r"stack/stack\.json: key 'pixel_size_um': missing"),
    ("negative-pixel-size", lambda d: _edit_json(d, pixel_size_um=-0.25),
     r"stack/stack\.json: key 'pixel_size_um': must be a finite number > 0"),
    ("zero-pixel-size", lambda d: _edit_json(d, pixel_size_um=0),
     r"stack/stack\.json: key 'pixel_size_um'"),
    ("inf-pixel-size", lambda d: _replace_in_json(d, '"pixel_size_um": 0.25',
                                                  '"pixel_size_um": Infinity'),
     r"stack/stack\.json: key 'pixel_size_um': must be a finite number > 0, got inf"),
    ("nan-pixel-size", lambda d: _replace_in_json(d, '"pixel_size_um": 0.25',
                                                  '"pixel_size_um": NaN'),
     r"stack/stack\.json: key 'pixel_size_um'.*nan"),
    ("z-too-short", lambda d: _edit_json(d, z_um=[0.0, 0.5, 1.0]),
     r"stack/stack\.json: key 'z_um': has 3 values but there are 5 slices"),
    ("z-too-long", lambda d: _edit_json(d, z_um=[0.0, 0.5, 1.0, 1.5, 2.0, 2.5]),
     r"stack/stack\.json: key 'z_um': has 6 values but there are 5 slices"),
    ("z-missing", lambda d: _edit_json(d, z_um=None),
     r"stack/stack\.json: key 'z_um': missing"),
    ("nan-z", lambda d: _replace_in_json(d, "0.5,", "NaN,"),
     r"stack/stack\.json: key 'z_um'\[1\]: must be a finite number, got nan"),
    ("inf-z", lambda d: _replace_in_json(d, "1.5,", "-Infinity,"),
     r"stack/stack\.json: key 'z_um'\[3\]: must be a finite number, got -inf"),
    ("nan-z-step", lambda d: (_edit_json(d, z_um=None), _replace_in_json(
        d, '"format"', '"z_step_um": NaN, "format"')),
     r"stack/stack\.json: key 'z_step_um'"),
    ("duplicate-z", lambda d: _edit_json(d, z_um=[0.0, 0.5, 0.5, 1.5, 2.0]),
     r"stack/stack\.json: key 'z_um': duplicate height 0\.5"),
    ("truncated-slice", lambda d: _truncate(d / "slices/002.png"),
     r"stack/stack\.json: key 'slices'\[2\] \(002\.png\): truncated PNG"),
    ("not-an-image", lambda d: (d / "slices/002.png").write_bytes(b"not a png at all" * 9),
     r"stack/stack\.json: key 'slices'\[2\] \(002\.png\): not a PNG"),
    ("empty-slice-file", lambda d: (d / "slices/004.png").write_bytes(b""),
     r"stack/stack\.json: key 'slices'\[4\] \(004\.png\)"),
    ("corrupt-slice-data", lambda d: _corrupt_inside(d / "slices/002.png"),
     r"slice 2 \(.*stack/slices/002\.png\): cannot decode"),
    ("missing-slice-file", lambda d: (d / "slices/003.png").unlink(),
     r"stack/stack\.json: key 'slices'\[3\]: file not found"),
    ("mismatched-size", lambda d: write_image(d / "slices/001.png",
                                              np.zeros((H, W + 8, 3), np.uint8)),
     r"stack/stack\.json: slices\[1\] \(001\.png\): size 72x64 differs"),
    ("mixed-bit-depth", lambda d: write_image(d / "slices/003.png",
                                              np.zeros((H, W, 3), np.uint16)),
     r"stack/stack\.json: slices\[3\] \(003\.png\): bit depth 16 differs.*mixed bit depths"),
    ("mixed-grey-colour", lambda d: write_image(d / "slices/003.png",
                                                np.zeros((H, W), np.uint8)),
     r"stack/stack\.json: slices\[3\] \(003\.png\): 1 channel\(s\).*mixed grey and colour"),
    ("unknown-film", lambda d: _edit_json(d, film="TiO2_Unobtainium"),
     r"stack/stack\.json: key 'film': unknown optical-constant set 'TiO2_Unobtainium'"),
    ("unknown-substrate", lambda d: _edit_json(d, substrate="Ti_Nope"),
     r"stack/stack\.json: key 'substrate': unknown optical-constant set 'Ti_Nope'"),
    ("slice-outside-folder", _outside,
     r"stack/stack\.json: key 'slices'\[1\]: '\.\./outside\.png' escapes the stack folder"),
    ("slice-absolute-path", lambda d: _edit_json(
        d, slices=[str((d / "slices/000.png").resolve())] + [f"slices/{i:03d}.png"
                                                              for i in range(1, N)]),
     r"stack/stack\.json: key 'slices'\[0\]: '/.*000\.png' is an absolute path"),
    ("bad-numerical-aperture", lambda d: _edit_json(d, illumination={"numerical_aperture": 0}),
     r"stack/stack\.json: key 'illumination': numerical_aperture"),
]


def _digest(folder: Path) -> str:
    h = hashlib.sha256()
    for p in sorted(folder.rglob("*")):
        h.update(p.relative_to(folder).as_posix().encode())
        if p.is_file():
            h.update(p.read_bytes())
    return h.hexdigest()


def _broken(tmp_path: Path, mutate) -> tuple[Path, Path, str]:
    stack = _valid_stack(tmp_path / "in" / "stack")
    mutate(stack)
    parent = tmp_path / "results"
    parent.mkdir()
    return stack, parent, _digest(tmp_path / "in")


@pytest.mark.parametrize("command", ["analyze", "height"])
@pytest.mark.parametrize("case, mutate, pattern", CASES, ids=[c[0] for c in CASES])
def test_broken_stack_exits_2_with_one_line_and_leaves_nothing(tmp_path, capfd, command, case,
                                                               mutate, pattern):
    stack, parent, before = _broken(tmp_path, mutate)
    out = parent / "out"
    status = main([command, str(stack), "--out", str(out)])
    captured = capfd.readouterr()  # file descriptors: OpenCV's C++ warnings too
    err = captured.err
    assert status == 2, err
    assert "Traceback" not in err and captured.out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith(f"microfacet {command}: error: ")
    assert re.search(pattern, lines[0]), lines[0]
    assert list(parent.iterdir()) == []            # no results, no .out.partial-*
    assert _digest(tmp_path / "in") == before      # the input is untouched


def test_valid_stack_passes_the_same_checks(tmp_path):
    # the base of every case really is valid: the same command succeeds on it
    stack, parent, before = _broken(tmp_path, lambda d: None)
    assert main(["height", str(stack), "--out", str(parent / "out"), "-q"]) == 0
    assert [p.name for p in parent.iterdir()] == ["out"]
    assert _digest(tmp_path / "in") == before


def _run(argv):
    return subprocess.run(argv, capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("launcher, command, case", [
    ("module", "analyze", "nan-z"),
    ("script", "height", "corrupt-slice-data"),
])
@pytest.mark.slow
def test_broken_stack_in_a_fresh_process(tmp_path, launcher, command, case):
    mutate, pattern = next((m, p) for c, m, p in CASES if c == case)
    stack, parent, before = _broken(tmp_path, mutate)
    out = parent / "out"
    if launcher == "module":
        argv = [sys.executable, "-m", "microfacet"]
    else:
        script = Path(sys.executable).with_name("microfacet")
        if not script.exists():
            pytest.skip("console script not installed next to the interpreter")
        argv = [str(script)]
    res = _run(argv + [command, str(stack), "--out", str(out)])
    assert res.returncode == 2, res.stderr
    assert "Traceback" not in res.stderr and res.stdout == ""
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and re.search(pattern, lines[0]), res.stderr
    assert list(parent.iterdir()) == [] and _digest(tmp_path / "in") == before
