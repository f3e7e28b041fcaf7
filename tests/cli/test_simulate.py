"""``microfacet simulate`` (microfacet.cli.simulate): a single thickness, distributions from a
results folder or given explicitly, comparison with a measured map, fitting."""

import json

import numpy as np
import pytest

from microfacet.cli.main import build_parser, main
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.forward.angular import simulate_map
from microfacet.io.angular_map import load_map, save_map

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
SMALL = ["--theta-max-deg", "60", "--theta-step-deg", "5", "-q"]


def _results(tmp_path, **extra):
    folder = tmp_path / "analysis"
    folder.mkdir()
    summary = {"format": "microfacet-results/1",
               "thickness": {"mixture": {**G3.to_json(), "bic": 0.0}},
               "ndf": {"mixture": {**F2.to_json(), "bic": 0.0}}, "exposure": 0.25, **extra}
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


@pytest.mark.slow
def test_from_an_analyze_results_folder(tmp_path):
    res = _results(tmp_path, film="TiO2_Jolivet2023_amorphous")
    out = tmp_path / "sim"
    assert main(["simulate", "--results", str(res), "--out", str(out), "--exposure", "0.25"]
                + SMALL) == 0
    names = {p.name for p in out.iterdir()}
    assert {"spectra.npy", "wavelength_nm.npy", "angular_lab.npy", "angular_map.png",
            "angular_map.npz", "figure.pdf", "simulate.json"} <= names
    meta = json.loads((out / "simulate.json").read_text())
    assert meta["model"] == "microfacet" and meta["exposure"] == 0.25
    spectra = np.load(out / "spectra.npy")
    assert spectra.shape == (13, 13, 81)
    # The written map is the library's map for the same parameters.
    ref = simulate_map(model="microfacet", thickness=G3, ndf=F2, exposure=0.25,
                       theta_light_deg=np.arange(0, 61, 5.0),
                       theta_view_deg=np.arange(0, 61, 5.0))
    np.testing.assert_allclose(spectra, ref.spectra, rtol=1e-5)
    m = load_map(out / "angular_map.npz")
    np.testing.assert_array_equal(m.lab, np.load(out / "angular_lab.npy"))
    # Without --exposure the display scale is automatic (the camera exposure of the analysis
    # is not a gonio-map scale): the 98th percentile of Y lands at 0.9 of white.
    out2 = tmp_path / "sim-auto"
    assert main(["simulate", "--results", str(res), "--out", str(out2)] + SMALL) == 0
    meta2 = json.loads((out2 / "simulate.json").read_text())
    y = np.load(out2 / "angular_xyz.npy")[..., 1]
    from microfacet import colour as color

    white = color.spectral_weights(np.linspace(380, 780, 81)).sum(axis=0)
    assert meta2["exposure"] != 0.25
    assert np.percentile(y / white[1], 98) == pytest.approx(0.9, rel=1e-3)


@pytest.mark.slow
def test_explicit_parameters_eq6_and_compare(tmp_path, capsys):
    grid = np.arange(0.0, 61.0, 5.0)
    meas = simulate_map(model="eq6", thickness=G3, ndf=F2, n=25.0, exposure=1.7,
                        theta_light_deg=grid, theta_view_deg=grid)
    save_map(tmp_path / "measured.npz", meas)
    out = tmp_path / "sim"
    argv = ["simulate", "--thickness-mixture", "0.3:112:3,0.45:130:3,0.25:149:3",
            "--ndf-lobes", "0.6:3,0.4:9", "--model", "eq6", "--lobe-exponent", "25",
            "--exposure", "1.7", "--compare", str(tmp_path / "measured.npz"),
            "--out", str(out)]
    assert main(argv) == 0
    assert "mean dE00 0.00" in capsys.readouterr().out
    meta = json.loads((out / "simulate.json").read_text())
    assert meta["compare"]["mean"] < 1e-3 and meta["compare"]["mean_excluding_specular"] < 1e-3
    assert np.nanmax(np.load(out / "delta_e.npy")) < 1e-2
    # Wrong exponent and exposure: fitted back.
    out2 = tmp_path / "fit"
    argv2 = [a for a in argv if a not in ("25", "1.7", "--lobe-exponent", "--exposure")]
    argv2[argv2.index(str(out))] = str(out2)
    assert main(argv2 + ["--fit-exponent", "--fit-exposure", "-q"]) == 0
    fit = json.loads((out2 / "simulate.json").read_text())["fit"]
    assert fit["n"] == pytest.approx(25.0, rel=0.01)
    assert fit["exposure"] == pytest.approx(1.7, rel=0.005)


@pytest.mark.slow
def test_half_vector_model_from_a_mixture(tmp_path):
    out = tmp_path / "hv"
    assert main(["simulate", "--thickness-mixture", "1:51:2", "--model", "half-vector",
                 "--out", str(out)] + SMALL) == 0
    lab = np.load(out / "angular_lab.npy")
    assert lab.shape == (13, 13, 3) and np.all(np.isfinite(lab))


@pytest.mark.parametrize("argv, msg", [
    (["--thickness-mixture", "0.3:1x2:3"], "--thickness-mixture"),
    (["--thickness-mixture", "1:100"], "--thickness-mixture"),
    (["--ndf-lobes", "1:95", "--thickness-nm", "100"], "--ndf-lobes"),
    (["--thickness-nm", "100", "--model", "eq6"], "--ndf-lobes"),
    (["--model", "microfacet"], "--thickness-mixture"),
    (["--results", "{tmp}/nowhere"], "--results"),
    (["--thickness-nm", "100", "--fit-exposure"], "--compare"),
    (["--thickness-nm", "100", "--ndf-lobes", "1:5", "--fit-exponent"], "--fit-exponent"),
    (["--thickness-nm", "100", "--compare", "{tmp}/missing.npz"], "missing.npz"),
    (["--thickness-nm", "100", "--ndf-lobes", "1:5", "--film", "Unobtainium"], "--film"),
])
def test_user_errors_are_one_line_exit_2(tmp_path, capsys, argv, msg):
    argv = ["simulate"] + [a.format(tmp=tmp_path) for a in argv] + ["--out", str(tmp_path / "o")]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_help_has_examples_of_every_path():
    sub = build_parser()._subparsers._group_actions[0].choices["simulate"]
    text = sub.format_help()
    assert "example" in text and "--results" in text and "--compare" in text


@pytest.mark.slow
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


def _results_under(tmp_path, illuminant, *, name="analysis", top_level=False):
    """A version-2 results folder recorded under ``illuminant`` (in ``inputs``; at the top
    level of a version-1 summary with ``top_level``)."""
    folder = tmp_path / name
    folder.mkdir()
    summary = {"format": "microfacet-results/1",
               "thickness": {"mixture": G3.to_json()}, "ndf": {"mixture": F2.to_json()}}
    if top_level:
        summary.update(inputs={"stack": "s"}, illuminant=illuminant)
    else:
        summary.update(summary_version=2, inputs={"illuminant": illuminant,
                                                  "film": "TiO2_Jolivet2023_amorphous"})
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


@pytest.mark.slow
def test_an_explicit_d65_wins_over_the_results_folders_illuminant(tmp_path):
    """``--illuminant D65`` given explicitly is not "not given": with a results folder
    recorded under D50 the map is simulated under D65; without the option, under D50."""
    res = _results_under(tmp_path, "D50")
    base = ["simulate", "--results", str(res), "--exposure", "0.25"] + SMALL
    assert main(base + ["--out", str(tmp_path / "d65"), "--illuminant", "D65"]) == 0
    assert main(base + ["--out", str(tmp_path / "rec")]) == 0
    d65 = json.loads((tmp_path / "d65" / "simulate.json").read_text())
    rec = json.loads((tmp_path / "rec" / "simulate.json").read_text())
    assert d65["illuminant"] == "D65" and rec["illuminant"] == "D50"
    assert load_map(tmp_path / "d65" / "angular_map.npz").illuminant == "D65"
    grid = np.arange(0, 61, 5.0)
    for out, ill in (("d65", "D65"), ("rec", "D50")):
        ref = simulate_map(model="microfacet", thickness=G3, ndf=F2, exposure=0.25,
                           theta_light_deg=grid, theta_view_deg=grid, illuminant=ill)
        np.testing.assert_allclose(np.load(tmp_path / out / "angular_lab.npy"), ref.lab,
                                   atol=1e-4)


@pytest.mark.slow
def test_an_old_summary_records_its_illuminant_at_the_top_level(tmp_path):
    res = _results_under(tmp_path, "D50", top_level=True)
    assert main(["simulate", "--results", str(res), "--out", str(tmp_path / "o")] + SMALL) == 0
    assert json.loads((tmp_path / "o" / "simulate.json").read_text())["illuminant"] == "D50"


@pytest.mark.slow
def test_explicit_distributions_win_over_the_results_folders(tmp_path):
    res = _results_under(tmp_path, "D65")
    out = tmp_path / "o"
    assert main(["simulate", "--results", str(res), "--thickness-mixture", "1:51:2",
                 "--ndf-lobes", "1:7", "--substrate", "Ti_JohnsonChristy1974",
                 "--out", str(out)] + SMALL) == 0
    meta = json.loads((out / "simulate.json").read_text())
    assert meta["thickness"] == ThicknessMixture([(1.0, 51.0, 2.0)]).to_json()
    assert meta["ndf"] == NDFMixture([(1.0, 7.0)]).to_json()
    assert meta["results"] == str(res) and meta["model"] == "microfacet"


def test_fit_spectrum_and_simulate_share_one_declaration_of_the_optics():
    sub = build_parser()._subparsers._group_actions[0].choices
    for name in ("simulate", "fit-spectrum"):
        optics = next(g for g in sub[name]._action_groups if g.title == "optics")
        flags = [a.option_strings[0] for a in optics._group_actions]
        assert flags == ["--film", "--substrate", "--illuminant", "--observer"]
        assert sub[name].get_default("opt__illuminant") is None  # "not given", not D65
