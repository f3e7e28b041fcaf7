"""``microfacet analyze``: bad input exits 2 with one line and writes nothing.

The results folder it writes: tests/analysis/test_output.py; broken stacks end to end:
test_bad_input.py and test_hostile_input.py."""

from pathlib import Path

import pytest

from microfacet.cli import main

FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"


def test_bad_inputs_exit_2_and_leave_nothing(tmp_path, capsys):
    assert main(["analyze", str(tmp_path / "nope"), "--out", str(tmp_path / "o")]) == 2
    assert main(["analyze", str(FIXTURE), "--out", str(tmp_path / "o"), "--film", "Nope"]) == 2
    assert main(["analyze", str(FIXTURE), "--out", str(tmp_path / "o"),
                 "--thickness-range-nm", "50:10"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "Nope" in err and "thickness-range-nm" in err
    assert list(tmp_path.iterdir()) == []


FAST = ["--roi-size-px", "48", "--no-report"]


@pytest.mark.slow
def test_summary_on_stdout_logs_on_stderr_and_json(batch_drawer, tmp_path, capsys, caplog):
    import json

    out = tmp_path / "res"
    # a pixel size for a stack with stack.json: ignored, with one warning line
    assert main(["analyze", str(batch_drawer / "a"), "--out", str(out), "--pixel-size-um", "9",
                 *FAST]) == 0
    cap = capsys.readouterr()
    assert cap.out.startswith(f"wrote {out}") and "thickness:" in cap.out
    assert "NDF lobes" in cap.out and "wrote" not in cap.err
    warn = [r.getMessage() for r in caplog.records if "--pixel-size-um" in r.getMessage()]
    assert len(warn) == 1 and "ignored" in warn[0] and "stack.json" in warn[0]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["pixel_size_um"] != 9

    assert main(["analyze", str(batch_drawer / "a"), "--out", str(out), "--overwrite",
                 "--json", "-q", *FAST]) == 0
    cap = capsys.readouterr()
    data = json.loads(cap.out)                       # stdout is JSON and nothing else
    summary = json.loads((out / "summary.json").read_text())
    assert data["results"] == str(out) and data["stack"] == str(batch_drawer / "a")
    for key in ("thickness", "ndf", "delta_e", "warnings"):
        assert data[key] == summary[key], key
    assert isinstance(data["ndf"]["identified"], bool) and "reason" in data["ndf"]


@pytest.mark.slow
def test_plain_folder_of_images_with_pixel_size_and_z_step(batch_drawer, tmp_path, capsys):
    import json
    import shutil

    src = batch_drawer / "a"
    meta = json.loads((src / "stack.json").read_text())
    plain = tmp_path / "plain"
    plain.mkdir()
    for k, name in enumerate(meta["slices"]):
        shutil.copy(src / name, plain / f"img_{k + 1}{Path(name).suffix}")
    out = tmp_path / "res"
    assert main(["analyze", str(plain), "--out", str(out), "--json", "--pixel-size-um", "0.4",
                 "--z-step-um", "0.5", *FAST]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["inputs"]["pixel_size_um"] == 0.4
    assert summary["inputs"]["n_slices"] == len(meta["slices"])
    assert not (plain / "stack.json").exists()          # nothing written into the input
    capsys.readouterr()
    # without the options, or with one: one line naming what is missing
    assert main(["analyze", str(plain), "--out", str(tmp_path / "o2")]) == 2
    assert main(["analyze", str(plain), "--out", str(tmp_path / "o2"), "--z-step-um", "1"]) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2 and "missing stack.json" in err[0] and "--pixel-size-um" in err[0]
    assert "give both --pixel-size-um and --z-step-um" in err[1]
    assert not (tmp_path / "o2").exists()


@pytest.mark.slow
def test_a_flat_reference_is_applied_and_said_so(batch_drawer, tmp_path, capsys):
    """``--flat-reference``: the summary line names the field and where it came from; a
    reference of another size exits 2 with one line naming the option and the file."""
    import json

    import numpy as np

    from microfacet.colour.transfer import srgb_encode
    from microfacet.forward.imaging import vignetting_factor
    from microfacet.io.images import write_image
    from microfacet.io.stack import read_stack

    h, w = read_stack(batch_drawer / "a").shape
    lin = 0.5 * vignetting_factor((h, w), corner_loss=0.3)
    write_image(tmp_path / "flat.png", srgb_encode(np.repeat(lin[..., None], 3, axis=-1),
                                                   dtype=np.uint8))
    write_image(tmp_path / "small.png", srgb_encode(np.full((h // 2, w, 3), 0.5, np.float32),
                                                    dtype=np.uint8))
    out = tmp_path / "res"
    assert main(["analyze", str(batch_drawer / "a"), "--out", str(out), "--flat-reference",
                 str(tmp_path / "flat.png"), *FAST]) == 0
    line = capsys.readouterr().out.splitlines()[-1]
    assert "flat field 30% lost at the corners (flat reference flat.png)" in line
    summary = json.loads((out / "summary.json").read_text())
    assert summary["flat_field"]["source"] == "flat reference flat.png"
    assert main(["analyze", str(batch_drawer / "a"), "--out", str(tmp_path / "r2"),
                 "--flat-reference", str(tmp_path / "small.png"), *FAST]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "flat_reference (small.png)" in err[0] and "size" in err[0]
    assert not (tmp_path / "r2").exists()


@pytest.mark.slow
def test_an_analysis_with_its_report_imports_neither_colour_science_nor_scipy_stats(tmp_path):
    """colour-science (0.78 s) and scipy.stats (0.19 s) are not imported by a whole
    `microfacet analyze`, report included (docs/benchmarks.md): its CIE tables are stored with
    the package and its χ² quantiles come from scipy.special (fresh process)."""
    import subprocess
    import sys

    code = ("import sys\n"
            "from microfacet.cli import main\n"
            f"assert main(['analyze', {str(FIXTURE)!r}, '--out', {str(tmp_path / 'o')!r},"
            " '-q']) == 0\n"
            "print(sorted(m for m in ('colour', 'scipy.stats') if m in sys.modules))\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=600)
    assert run.returncode == 0, run.stderr[-2000:]
    assert run.stdout.strip().splitlines()[-1] == "[]"
    assert (tmp_path / "o" / "report.pdf").is_file()
