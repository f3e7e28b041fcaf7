"""``export_material`` / ``microfacet export-brdf``: a results folder's material as one file;
the output rules (never inside the input, replace only a material file)."""

import json

import numpy as np
import pytest

from microfacet.cli.main import main
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
from microfacet.forward.brdf import microfacet_brdf
from microfacet.forward.material import Material
from microfacet.workflow.material import export_material

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = {"theta_step_deg": 1.0, "wavelength_step_nm": 5.0}


@pytest.fixture()
def results(tmp_path):
    folder = tmp_path / "analysis"
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps({
        "format": "microfacet-results/1",
        "inputs": {"film": "TiO2_Jolivet2023_amorphous", "substrate": "Ti_JohnsonChristy1974"},
        "thickness": {"mixture": G3.to_json()},
        "ndf": {"mixture": F2.to_json(), "identified": False, "reason": "too few planes"}}))
    return folder


def test_export_writes_the_results_material(results, tmp_path):
    done = export_material(results, tmp_path / "mat", **GRID)
    assert done.path == tmp_path / "mat.npz" and done.path.is_file()
    m = Material.read(done.path)
    assert m.ndf == F2 and m.thickness == G3
    assert m.metadata["source"]["ndf_identified"] is False
    light, view = np.array([0.3, 0.1, 0.95]), np.array([-0.2, 0.05, 0.98])
    wl = m.wavelength_nm[::10]
    np.testing.assert_allclose(m.brdf(light, view, wavelength_nm=wl),
                               microfacet_brdf(light, view, thickness=G3, ndf=F2,
                                               wavelength_nm=wl), rtol=2e-3)


def test_output_rules(results, tmp_path):
    with pytest.raises(InputError, match="inside the input"):
        export_material(results, results / "m.npz", **GRID)
    export_material(results, tmp_path / "m.npz", **GRID)
    with pytest.raises(InputError, match="already exists"):
        export_material(results, tmp_path / "m.npz", **GRID)
    export_material(results, tmp_path / "m.npz", overwrite=True, **GRID)
    other = tmp_path / "notes.npz"
    other.write_text("my notes")
    with pytest.raises(InputError, match="never replaced"):
        export_material(results, other, overwrite=True, **GRID)
    assert other.read_text() == "my notes"
    with pytest.raises(InputError, match="does not exist"):
        export_material(results, tmp_path / "no" / "m.npz", **GRID)


def test_command_line(results, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["export-brdf", str(results), "--out", str(out), "--theta-step-deg", "1",
                 "--wavelength-step-nm", "5"]) == 0
    captured = capsys.readouterr()
    assert "cli.npz" in captured.out and "did not identify" in captured.err
    assert main(["export-brdf", str(results), "--out", str(out)]) == 2
    assert "--out" in capsys.readouterr().err
