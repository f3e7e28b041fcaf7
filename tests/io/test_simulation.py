"""The simulation folder (microfacet.io.simulation): written whole or not at all, read back
as written, malformed folders refused naming the file."""

from __future__ import annotations

import json

import numpy as np
import pytest

from microfacet.core.distributions import NDFMixture, ThicknessMixture
from microfacet.core.errors import InputError
from microfacet.forward.angular import simulate_map
from microfacet.forward.compare import delta_e_map
from microfacet.io.angular_map import load_map
from microfacet.io.outdir import output_kind
from microfacet.io.simulation import (
    FILES,
    FORMAT,
    Simulation,
    read_simulation,
    save_simulation,
    write_simulation,
)

G = ThicknessMixture([(0.5, 112.0, 3.0), (0.5, 130.0, 3.0)])
F = NDFMixture([(1.0, 6.0)])


@pytest.fixture(scope="module")
def sim():
    m = simulate_map(model="microfacet", thickness=G, ndf=F, exposure=0.3,
                     theta_light_deg=[0.0, 20.0, 40.0], theta_view_deg=[0.0, 15.0, 30.0, 45.0],
                     illuminant="D50", observer="10")
    meas = simulate_map(model="microfacet", thickness=G, ndf=F, exposure=0.35,
                        theta_light_deg=m.theta_light_deg, theta_view_deg=m.theta_view_deg,
                        illuminant="D50", observer="10")
    meta = {"model": "microfacet", "exposure": 0.3, "illuminant": "D50", "observer": "10",
            "thickness": G.to_json(), "compare": {"mean": float("nan")}}
    return Simulation(m, meta, delta_e_map(m, meas))


def _listing(folder):
    return sorted(p.name for p in folder.iterdir())


def test_round_trip(tmp_path, sim):
    out = save_simulation(tmp_path / "sim", sim, started=0.0)
    assert output_kind(out) == "simulate"
    assert set(_listing(out)) == set(FILES.values())
    back = read_simulation(out)
    m, r = sim.map, back.map
    assert back.meta["format"] == FORMAT and back.meta["model"] == "microfacet"
    assert back.meta["compare"]["mean"] is None      # NaN written as null: valid JSON
    assert back.meta["timings_s"]["total"] > 0
    for name in ("theta_light_deg", "theta_view_deg", "wavelength_nm"):
        np.testing.assert_array_equal(getattr(r, name), getattr(m, name))
    np.testing.assert_array_equal(r.lab, m.lab)
    np.testing.assert_array_equal(r.xyz, m.xyz.astype(np.float32))
    np.testing.assert_array_equal(r.spectra, m.spectra.astype(np.float32))
    np.testing.assert_array_equal(back.delta_e, sim.delta_e.astype(np.float32))
    assert (r.illuminant, r.observer) == ("D50", "10")
    assert np.load(out / FILES["spectra"]).dtype == np.float32
    # the angular-map file holds the same map
    np.testing.assert_array_equal(load_map(out / FILES["map"]).lab, m.lab)
    json.loads((out / FILES["meta"]).read_text())  # strict JSON


def test_without_a_comparison_there_is_no_delta_e(tmp_path, sim):
    out = save_simulation(tmp_path / "sim", Simulation(sim.map, {"model": "microfacet"}))
    assert FILES["delta_e"] not in _listing(out)
    assert read_simulation(out).delta_e is None


def test_the_extra_hook_writes_inside_the_same_step_before_the_json(tmp_path, sim):
    seen = []

    def extra(folder):
        seen.append((folder.name, sorted(p.name for p in folder.iterdir())))
        (folder / "figure.pdf").write_bytes(b"%PDF-1.4\n")

    out = save_simulation(tmp_path / "sim", sim, extra=extra)
    name, present = seen[0]
    assert name.startswith(".sim.partial-") and FILES["meta"] not in present
    assert (out / "figure.pdf").is_file()


@pytest.mark.parametrize("failure", [RuntimeError, KeyboardInterrupt])
def test_a_failed_write_leaves_nothing_and_an_earlier_folder_untouched(tmp_path, sim,
                                                                     failure):
    def fail(folder):
        raise failure("disk full")

    with pytest.raises(failure):
        save_simulation(tmp_path / "sim", sim, extra=fail)
    assert _listing(tmp_path) == []                   # nothing, not even a partial folder
    first = save_simulation(tmp_path / "sim", Simulation(sim.map, {"model": "first"}))
    before = {p.name: p.read_bytes() for p in first.iterdir()}
    with pytest.raises(failure):
        save_simulation(first, sim, overwrite=True, extra=fail)
    assert _listing(tmp_path) == ["sim"]
    assert {p.name: p.read_bytes() for p in first.iterdir()} == before
    save_simulation(first, sim, overwrite=True)
    assert read_simulation(first).meta["model"] == "microfacet"


def test_only_a_simulation_folder_is_replaced_and_only_with_overwrite(tmp_path, sim):
    out = save_simulation(tmp_path / "sim", sim)
    with pytest.raises(InputError, match="already exists") as err:
        save_simulation(out, sim)
    assert err.value.param == "out"
    mine = tmp_path / "mine"
    mine.mkdir()
    (mine / "notes.txt").write_text("precious")
    with pytest.raises(InputError, match="never replaced"):
        save_simulation(mine, sim, overwrite=True)
    assert (mine / "notes.txt").read_text() == "precious"


def test_write_simulation_into_an_existing_folder(tmp_path, sim):
    write_simulation(tmp_path, sim)
    assert set(_listing(tmp_path)) == set(FILES.values())


@pytest.mark.parametrize("damage, pattern", [
    (lambda d: (d / FILES["meta"]).unlink(), r"simulate\.json: missing \(not a simulation"),
    (lambda d: (d / FILES["meta"]).write_text('{"format": "microfacet-results/1"}'),
     r"key 'format': 'microfacet-results/1' is not 'microfacet-simulate/2'"),
    (lambda d: (d / FILES["lab"]).unlink(), r"angular_lab\.npy: missing"),
    (lambda d: np.save(d / FILES["lab"], np.zeros((2, 2, 3), np.float32)),
     r"angular_lab\.npy: shape \(2, 2, 3\), expected \(3, 4, 3\)"),
    (lambda d: np.save(d / FILES["spectra"], np.array(["a"] * 3)),
     r"spectra\.npy: expected a 3-D array of numbers"),
    (lambda d: np.save(d / FILES["theta_light_deg"], np.zeros(10**5, np.float32)),
     r"theta_light_deg\.npy: 100,000 values, more than 3,600"),
    (lambda d: (d / FILES["xyz"]).write_bytes(b"not numpy"), r"angular_xyz\.npy: cannot read"),
])
def test_a_damaged_folder_is_refused_naming_the_file(tmp_path, sim, damage, pattern):
    out = save_simulation(tmp_path / "sim", sim)
    damage(out)
    with pytest.raises(InputError, match=pattern) as err:
        read_simulation(out)
    assert "\n" not in str(err.value)
