"""``microfacet analyze``: bad input exits 2 with one line and writes nothing.

The results folder it writes: tests/analysis/test_output.py; broken stacks end to end:
test_bad_input.py and test_hostile_input.py."""

from pathlib import Path

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
