"""The simulate workflow (microfacet.workflow.simulate): the API behind ``microfacet
simulate`` — what is simulated, which optics win, the options' checks, the folder written."""

from __future__ import annotations

import json
import re

import numpy as np
import pytest

import microfacet
from microfacet import workflow
from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
from microfacet.forward.angular import simulate_map
from microfacet.io.angular_map import save_map
from microfacet.io.simulation import read_simulation
from microfacet.optics.defaults import DEFAULT_FILM, DEFAULT_ILLUMINANT
from microfacet.workflow.simulate import FilmOptics, SimulateOptions, simulate_to_folder

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 3.0), (0.4, 9.0)])
GRID = np.arange(0.0, 61.0, 10.0)
SMALL = SimulateOptions(theta_max_deg=60, theta_step_deg=10, spectral_step_nm=10)


def _results(tmp_path, *, illuminant="D50", film=DEFAULT_FILM, ndf=True):
    folder = tmp_path / "analysis"
    folder.mkdir()
    summary = {"format": "microfacet-results/1", "summary_version": 2,
               "inputs": {"illuminant": illuminant, "film": film},
               "thickness": {"mixture": G3.to_json()}}
    if ndf:
        summary["ndf"] = {"mixture": F2.to_json()}
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def test_exported_from_the_package_and_the_workflow():
    assert microfacet.simulate_to_folder is simulate_to_folder
    assert workflow.simulate_to_folder is simulate_to_folder
    assert workflow.SimulateOptions is SimulateOptions


@pytest.mark.slow
def test_one_thickness_is_the_half_vector_map_at_exposure_1(tmp_path):
    done = simulate_to_folder(tmp_path / "o", thickness_nm=51.0, options=SMALL)
    assert (done.model, done.exposure, done.shape, done.compare) == ("half-vector", 1.0,
                                                                     (7, 7), None)
    back = read_simulation(done.out)
    ref = simulate_map(model="half-vector", thickness=51.0, theta_light_deg=GRID,
                       theta_view_deg=GRID, wavelength_nm=np.linspace(380, 780, 41))
    np.testing.assert_array_equal(back.map.lab, ref.lab)
    assert back.meta["thickness"] == {"thickness_nm": 51.0} and back.meta == done.meta | {
        "format": back.meta["format"], "timings_s": back.meta["timings_s"]}
    assert (done.out / "figure.pdf").is_file()


@pytest.mark.slow
def test_a_mixture_given_as_components_or_as_a_mixture_is_the_same_map(tmp_path):
    a = simulate_to_folder(tmp_path / "a", thickness_mixture=G3, ndf_lobes=F2, options=SMALL)
    b = simulate_to_folder(tmp_path / "b", thickness_mixture=[(0.3, 112, 3), (0.45, 130, 3),
                                                              (0.25, 149, 3)],
                           ndf_lobes=[(0.6, 3), (0.4, 9)], options=SMALL)
    assert a.model == b.model == "microfacet" and a.exposure == b.exposure
    np.testing.assert_array_equal(read_simulation(a.out).map.spectra,
                                  read_simulation(b.out).map.spectra)


@pytest.mark.parametrize("given, expected", [
    (FilmOptics(), "D50"),                            # not given: the results folder's
    (FilmOptics(illuminant=DEFAULT_ILLUMINANT), "D65"),  # the default, given: it wins
    (FilmOptics(illuminant="A"), "A"),
])
@pytest.mark.slow
def test_explicit_optics_win_over_the_results_folders(tmp_path, given, expected):
    res = _results(tmp_path, illuminant="D50")
    done = simulate_to_folder(tmp_path / "o", results=res, options=SMALL.replace(
        exposure=0.25, optics=given))
    assert done.meta["illuminant"] == expected
    assert read_simulation(done.out).map.illuminant == expected
    assert done.meta["results"] == str(res)


@pytest.mark.slow
def test_explicit_distributions_win_over_the_results_folders(tmp_path):
    res = _results(tmp_path)
    one = ThicknessMixture([(1.0, 51.0, 2.0)])
    done = simulate_to_folder(tmp_path / "o", results=res, thickness_mixture=one,
                              ndf_lobes=NDFMixture([(1.0, 7.0)]), options=SMALL)
    assert done.meta["thickness"] == one.to_json()
    assert done.meta["ndf"]["components"][0]["sd_deg"] == 7.0


@pytest.mark.slow
def test_a_results_folder_without_ndf_gives_the_half_vector_map(tmp_path):
    done = simulate_to_folder(tmp_path / "o", results=_results(tmp_path, ndf=False),
                              options=SMALL)
    assert done.model == "half-vector" and done.meta["ndf"] is None


@pytest.mark.slow
def test_compare_and_fit_on_the_measured_grid(tmp_path):
    meas = simulate_map(model="eq6", thickness=G3, ndf=F2, n=25.0, exposure=1.7,
                        theta_light_deg=GRID, theta_view_deg=GRID[:5])
    save_map(tmp_path / "measured.npz", meas)
    done = simulate_to_folder(tmp_path / "o", thickness_mixture=G3, ndf_lobes=F2,
                              compare=tmp_path / "measured.npz",
                              options=SimulateOptions(model="eq6", fit_exponent=True,
                                                      fit_exposure=True))
    assert done.shape == (7, 5)
    assert done.fit["n"] == pytest.approx(25.0, rel=0.01)
    assert done.exposure == pytest.approx(1.7, rel=0.005)
    assert done.compare["mean"] < 0.05 and done.meta["compare"]["measured"] == str(
        tmp_path / "measured.npz")
    assert read_simulation(done.out).delta_e.shape == (7, 5)


@pytest.mark.parametrize("make, param, pattern", [
    (lambda: SimulateOptions(theta_step_deg=10, theta_max_deg=5), "theta_step_deg",
     r"must be >= 0\.05 and <= `theta_max_deg`"),
    (lambda: SimulateOptions(fit_exponent=True), "fit_exponent", r"only with `model` eq6"),
    (lambda: SimulateOptions(exposure=1e300), "exposure", r"must be in \[1e-06, 1e\+06\]"),
    (lambda: SimulateOptions(theta_max_deg=90), "theta_max_deg", r"must be in \(0, 90\)"),
    (lambda: SimulateOptions(model="gonio"), "model", r"must be one of microfacet"),
    (lambda: SimulateOptions.from_dict({"optics": {"film": "Unobtainium"}}), "optics.film",
     r"unknown optical-constant set"),
    (lambda: SimulateOptions.from_dict({"optics": {"observer": "5"}}), "optics.observer",
     r"must be one of 2, 10"),
])
def test_options_are_checked_when_made(make, param, pattern):
    with pytest.raises(InputError) as err:
        make()
    assert err.value.param == param and re.search(pattern, err.value.raw_reason)


@pytest.mark.parametrize("kwargs, param, pattern", [
    (dict(), "thickness_mixture", r"give `results`, `thickness_mixture` or `thickness_nm`"),
    (dict(thickness_nm=-5.0), "thickness_nm", r"must be in \[0, 5000\] nm"),
    (dict(thickness_mixture=[(1, 130, 1e9)]), "thickness_mixture", r"sd_nm must be <= 1000"),
    (dict(thickness_mixture=[(1, 130)]), "thickness_mixture", r"needs 3 numbers"),
    (dict(thickness_nm=51.0, ndf_lobes=[(1, 95)]), "ndf_lobes", r"sd_deg must be in \(0, 90\)"),
    (dict(thickness_nm=51.0, options=SimulateOptions(model="eq6")), "ndf_lobes",
     r"model eq6 needs NDF lobes"),
    (dict(thickness_nm=51.0, options=SimulateOptions(fit_exposure=True)), "compare",
     r"need a measured map"),
    (dict(results="nowhere"), "results", r"results folder not found"),
    (dict(thickness_mixture=[(0.5, 130, 0.01), (0.5, 1000, 1000)]), "thickness_mixture",
     r"quadrature nodes, more than the limit"),
])
def test_inputs_are_checked_before_any_work(tmp_path, kwargs, param, pattern):
    with pytest.raises(InputError) as err:
        simulate_to_folder(tmp_path / "o", **kwargs)
    assert err.value.param == param and re.search(pattern, err.value.raw_reason)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.slow
def test_a_second_writer_on_the_same_out_is_refused_and_overwrite_replaces(tmp_path):
    out = tmp_path / "o"
    simulate_to_folder(out, thickness_nm=51.0, options=SMALL)
    with pytest.raises(InputError, match="already exists") as err:
        simulate_to_folder(out, thickness_nm=51.0, options=SMALL)
    assert err.value.param == "out"
    done = simulate_to_folder(out, thickness_nm=80.0, options=SMALL, overwrite=True)
    assert done.meta["thickness"] == {"thickness_nm": 80.0}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["o"]
