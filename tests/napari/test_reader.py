"""The napari readers and sample data through npe2 (the installed manifest; no Qt, no
napari): a stack folder → one z-stack layer, a results folder → the map layers with their
scale, units and the two mixtures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from microfacet.io.stack import read_stack
from microfacet.napari import reader, sample_data

npe2 = pytest.importorskip("npe2")

ND_FIXTURE = Path(__file__).resolve().parents[2] / "fixtures" / "stacks" / "nd-fixture"
MANIFEST = Path(reader.__file__).resolve().parents[1] / "napari.yaml"


@pytest.fixture(scope="module")
def plugins():
    """npe2's plugin manager with microfacet's manifest registered."""
    pm = npe2.PluginManager.instance()
    pm.discover()
    if "microfacet" not in pm._manifests:   # not installed with its entry point
        pm.register(npe2.PluginManifest.from_file(MANIFEST))
    return pm


def test_the_manifest_validates_and_is_the_installed_one(plugins):
    manifest = npe2.PluginManifest.from_file(MANIFEST)
    assert manifest.name == "microfacet"
    assert plugins.get_manifest("microfacet").contributions.readers is not None
    assert {c.id for c in manifest.contributions.commands} == {
        "microfacet.read_stack", "microfacet.read_results", "microfacet.nd_fixture",
        "microfacet.analysis_widget"}
    assert [s.key for s in manifest.contributions.sample_data] == ["nd-fixture"]


def test_the_fixture_stack_opens_as_one_z_stack(plugins):
    st = read_stack(ND_FIXTURE)
    layers = npe2.read([str(ND_FIXTURE)], stack=False, plugin_name="microfacet")
    assert len(layers) == 1
    data, kwargs, kind = layers[0]
    assert kind == "image" and kwargs["rgb"]
    assert data.shape == (st.n_slices, *st.shape, 3) and data.dtype == st.dtype
    z = np.sort(st.z_um)
    assert kwargs["scale"] == pytest.approx((np.median(np.diff(z)), *st.pixel_size_yx_um))
    assert kwargs["translate"][0] == pytest.approx(z[0])
    assert kwargs["metadata"]["stack_path"] == str(st.path)
    assert kwargs["metadata"]["z_um"] == pytest.approx(z.tolist())
    # slices in increasing z: the first plane is the lowest slice
    first = st.read_slice(int(st.z_order[0]), st.dtype)
    assert np.array_equal(data[0], first)


def test_small_results_folder_opens_as_map_layers(plugins, small_results):
    layers = npe2.read([str(small_results.path)], stack=False, plugin_name="microfacet")
    names = [kw["name"] for _, kw, _ in layers]
    assert names == ["height_um", "thickness_nm", "tilt_deg", "facets"]
    kinds = {kw["name"]: kind for _, kw, kind in layers}
    assert kinds["facets"] == "labels" and kinds["height_um"] == "image"
    for data, kw, _ in layers:
        assert kw["scale"] == small_results.pixel_um and data.shape == (3, 4)
        meta = kw["metadata"]
        assert meta["thickness_mixture"] == small_results.thickness
        assert meta["ndf_mixture"] == small_results.ndf
        assert meta["ndf_identified"] is False and meta["thickness_identified"] is True
        assert meta["unit"] == reader.UNITS[kw["name"]]
    assert layers[3][0].dtype == np.int32


def test_readers_refuse_what_they_do_not_read(small_results, tmp_path):
    assert reader.get_stack_reader(str(small_results.path)) is None
    assert reader.get_results_reader(str(ND_FIXTURE)) is None
    assert reader.get_results_reader(str(tmp_path)) is None
    assert reader.get_stack_reader(str(ND_FIXTURE / "stack.json")) is None
    assert reader.get_stack_reader([str(ND_FIXTURE), str(ND_FIXTURE)]) is None


def test_sample_data_is_the_fixture(plugins):
    assert sample_data.fixture_path() == ND_FIXTURE
    contrib = plugins.get_manifest("microfacet").contributions.sample_data[0]
    layers = contrib.open()
    assert layers[0][1]["metadata"]["stack_path"] == str(ND_FIXTURE.resolve())


def test_sample_data_is_made_when_the_source_tree_is_absent(monkeypatch, tmp_path):
    """A regular install has no fixtures/: the same stack is generated into the cache."""
    monkeypatch.setattr(sample_data, "FIXTURE_SOURCE", tmp_path / "absent")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    monkeypatch.setattr(sample_data, "FIXTURE_RECIPE", {**sample_data.FIXTURE_RECIPE,
                        "height_px": 32, "width_px": 32, "n_slices": 3})
    with pytest.raises(FileNotFoundError):
        sample_data.fixture_path(generate=False)
    made = sample_data.fixture_path()
    assert made == tmp_path / "cache" / "microfacet" / "nd-fixture"
    assert json.loads((made / "stack.json").read_text())["format"] == "microfacet-stack/1"
    assert sample_data.fixture_path(generate=False) == made     # cached


@pytest.mark.slow
def test_the_fixture_results_folder_opens_with_its_mixtures(plugins, nd_results):
    from microfacet.io.results import Results

    res = Results(nd_results)
    layers = npe2.read([str(nd_results)], stack=False, plugin_name="microfacet")
    names = [kw["name"] for _, kw, _ in layers]
    assert names == ["all_in_focus", "height_um", "thickness_nm", "tilt_deg", "facets"]
    st = read_stack(ND_FIXTURE)
    for data, kw, _ in layers:
        assert kw["scale"] == pytest.approx(st.pixel_size_yx_um)
        assert data.shape[:2] == st.shape
        assert kw["metadata"]["thickness_mixture"] == res.get("thickness", "mixture")
        assert kw["metadata"]["ndf_mixture"] == res.get("ndf", "mixture")
        assert kw["metadata"]["results_path"] == str(nd_results)
    means = sorted(c["mean_nm"] for c in layers[1][1]["metadata"]["thickness_mixture"]
                   ["components"])
    assert means == sorted(res.thickness_mixture().means_nm.tolist())
