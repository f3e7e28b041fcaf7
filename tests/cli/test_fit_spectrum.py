"""``microfacet fit-spectrum``: the thickness and the runner-up, as text and JSON."""

import json

import pytest

from microfacet.cli import main


def test_fit_spectrum_prints_thickness_and_runner_up(tmp_path, capsys, spectrum_csv):
    p = spectrum_csv(tmp_path / "s.csv", 138.4, angle=20.0)
    assert main(["fit-spectrum", str(p), "--angle-deg", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["thickness_nm"] == pytest.approx(138.4, abs=0.01)
    assert abs(out["runner_up_thickness_nm"] - 138.4) > 2
    assert main(["fit-spectrum", str(p), "--angle-deg", "20"]) == 0
    text = capsys.readouterr().out
    assert "thickness_nm" in text and "runner-up" in text
