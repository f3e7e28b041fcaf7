"""Command line: help, error handling, fit-spectrum and simulate."""

import json
import subprocess
import sys

import numpy as np
import pytest

from microfacet.cli import main
from microfacet.optics.thinfilm import reflectance

HEAVY = ("colour", "sklearn", "matplotlib", "scipy", "skimage", "cv2")


def test_help_does_not_import_heavy_modules():
    code = ("import sys\nfrom microfacet.cli.main import build_parser\nbuild_parser()\n"
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_registered_command_has_help_with_an_example(capsys):
    from microfacet.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == {"analyze", "height", "synth", "simulate", "fit-spectrum", "batch"}
    for name, p in sub.choices.items():
        assert "example" in (p.epilog or ""), name


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2


def _spectrum_csv(path, d, angle=0.0):
    wl = np.arange(400.0, 751.0, 5.0)
    R = reflectance(wl, angle, d, "TiO2_Jolivet2023_amorphous", "Ti_JohnsonChristy1974")
    path.write_text("wavelength_nm,reflectance\n" + "".join(f"{w},{r}\n" for w, r in zip(wl, R)))
    return path


def test_fit_spectrum_prints_thickness_and_runner_up(tmp_path, capsys):
    p = _spectrum_csv(tmp_path / "s.csv", 138.4, angle=20.0)
    assert main(["fit-spectrum", str(p), "--angle-deg", "20", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["thickness_nm"] == pytest.approx(138.4, abs=0.01)
    assert abs(out["runner_up_thickness_nm"] - 138.4) > 2
    assert main(["fit-spectrum", str(p), "--angle-deg", "20"]) == 0
    text = capsys.readouterr().out
    assert "thickness_nm" in text and "runner-up" in text


@pytest.mark.parametrize("argv, msg", [
    (["fit-spectrum", "missing.csv"], "missing.csv"),
    (["fit-spectrum", "{spec}", "--film", "Nope"], "--film"),
    (["fit-spectrum", "{spec}", "--angle-deg", "95"], "angle_deg"),
    (["simulate", "--thickness-nm", "-5", "--out", "{tmp}/o"], "--thickness-nm"),
    (["simulate", "--thickness-nm", "50", "--out", "{tmp}/o", "--theta-max-deg", "90"],
     "--theta-max-deg"),
])
def test_user_errors_are_one_line_with_exit_2(tmp_path, capsys, argv, msg):
    spec = _spectrum_csv(tmp_path / "s.csv", 80.0)
    argv = [a.format(spec=spec, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


def test_simulate_writes_a_complete_folder_and_refuses_to_overwrite(tmp_path, capsys):
    out = tmp_path / "sim"
    argv = ["simulate", "--thickness-nm", "51", "--out", str(out), "--theta-max-deg", "60",
            "--theta-step-deg", "5", "-q"]
    assert main(argv) == 0
    lab = np.load(out / "angular_lab.npy")
    assert lab.shape == (13, 13, 3) and lab.dtype == np.float32
    meta = json.loads((out / "simulate.json").read_text())
    assert meta["format"] == "microfacet-simulate/2" and meta["model"] == "half-vector"
    assert meta["thickness"] == {"thickness_nm": 51.0} and meta["exposure"] == 1.0
    assert meta["film"] == "TiO2_Jolivet2023_amorphous"
    assert main(argv) == 2  # exists
    assert main(argv + ["--overwrite", "--exposure", "0.5"]) == 0
    lab2 = np.load(out / "angular_lab.npy")
    assert (lab2[..., 0] < lab[..., 0]).all()  # darker with lower exposure
    assert [p.name for p in tmp_path.iterdir()] == ["sim"]  # no partial folders left


def test_console_script_runs_as_module():
    out = subprocess.run([sys.executable, "-m", "microfacet", "--version"], capture_output=True,
                         text=True)
    assert out.returncode == 0 and "microfacet" in out.stdout
