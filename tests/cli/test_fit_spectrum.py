"""``microfacet fit-spectrum``: the thickness and the runner-up, as text and JSON; the notes
on what was assumed in reading the file; the scale fitted by default; ``--columns``; the
shipped sample spectrum."""

import json
from pathlib import Path

import numpy as np
import pytest

from microfacet.cli import main
from microfacet.optics.thinfilm import reflectance

SAMPLE = Path(__file__).resolve().parents[2] / "fixtures" / "spectra"
FILM, SUB = "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974"


def test_fit_spectrum_prints_thickness_and_runner_up(tmp_path, capsys, spectrum_csv):
    p = spectrum_csv(tmp_path / "s.csv", 138.4, angle=20.0)
    assert main(["fit-spectrum", str(p), "--angle-deg", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["thickness_nm"] == pytest.approx(138.4, abs=0.01)
    assert abs(out["runner_up_thickness_nm"] - 138.4) > 2
    assert main(["fit-spectrum", str(p), "--angle-deg", "20"]) == 0
    text = capsys.readouterr().out
    assert "thickness_nm" in text and "runner-up" in text


def test_shipped_sample_recovers_its_stated_thickness(capsys):
    truth = json.loads((SAMPLE / "tio2-80nm-spectrometer.truth.json").read_text())
    assert main(["fit-spectrum", str(SAMPLE / truth["file"]), "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert abs(out["thickness_nm"] - truth["thickness_nm"]) <= truth["uncertainty_nm"]
    assert out["scale"] == pytest.approx(truth["scale"], abs=0.01)
    assert out["scale_fitted"] is True
    assert out["residual_rms"] == pytest.approx(truth["noise_sd"], rel=0.1)
    notes = " | ".join(out["notes"])
    assert "semicolon-delimited, decimal comma" in notes and "percent" in notes


@pytest.mark.slow
def test_scaled_export_prints_notes_and_fits_the_scale(tmp_path, capsys, caplog):
    wl = np.arange(0.400, 0.7501, 0.002)                        # µm, as some exports write
    R = 0.8 * reflectance(wl * 1000, 0.0, 80.0, FILM, SUB)
    p = tmp_path / "export.txt"
    p.write_text("Wavelength;%R\n" + "".join(f"{w:.3f};{100 * r:.4f}\n".replace(".", ",")
                                              for w, r in zip(wl, R)))
    assert main(["fit-spectrum", str(p)]) == 0
    text = capsys.readouterr().out
    assert "read          wavelength: no unit in the header; values 0.4-0.75 read as µm" in text
    assert "read          reflectance in percent (header '%R')" in text
    assert "thickness_nm  80.00" in text and "scale         0.8000   (fitted)" in text
    assert main(["fit-spectrum", str(p), "--fix-scale", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["scale_fitted"] is False and abs(out["thickness_nm"] - 80.0) > 3
    assert "the spectrum looks scaled" in caplog.text


def test_columns_option(tmp_path, capfd):
    wl = np.arange(400.0, 751.0, 5.0)
    R = reflectance(wl, 0.0, 121.4, FILM, SUB)
    p = tmp_path / "three.csv"
    p.write_text("t,a,b\n"
                 + "".join(f"{i},{r:.6f},{w}\n" for i, (w, r) in enumerate(zip(wl, R))))
    assert main(["fit-spectrum", str(p), "--columns", "3,2", "--json"]) == 0
    assert json.loads(capfd.readouterr().out)["thickness_nm"] == pytest.approx(121.4, abs=0.01)
    assert main(["fit-spectrum", str(p), "--columns", "wl,b"]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--columns: no column 'wl' in " in err[0], err
    assert main(["fit-spectrum", str(p)]) == 2
    err = capfd.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "name the two with --columns" in err[0], err


def test_optics_options_name_their_flag_and_reach_the_fit(tmp_path, capfd, spectrum_csv):
    """The optics flags are the ones ``simulate`` has (one declaration): an unknown set is
    refused naming its flag; a known one is the one fitted with."""
    csv = spectrum_csv(tmp_path / "s.csv", 80.0)
    for flag in ("--film", "--substrate"):
        assert main(["fit-spectrum", str(csv), flag, "Unobtainium"]) == 2
        err = capfd.readouterr().err
        assert err.count("\n") == 1 and f"{flag}: unknown optical-constant set" in err
    assert main(["fit-spectrum", str(csv), "--json", "--substrate",
                 "Ti_JohnsonChristy1974"]) == 0
    out = json.loads(capfd.readouterr().out)
    assert out["substrate"] == "Ti_JohnsonChristy1974" and out["film"] == FILM
