"""``render_to_folder`` / ``microfacet render``: a results folder or a material file becomes a
picture whose files agree with each other, a scene Mitsuba re-renders, and the output rules."""

import json

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")

from microfacet.cli.main import main  # noqa: E402
from microfacet.core.distributions import NDFMixture, ThicknessMixture  # noqa: E402
from microfacet.core.errors import InputError  # noqa: E402
from microfacet.forward.material import Material  # noqa: E402
from microfacet.render import bsdf  # noqa: E402
from microfacet.render.scene import luminance_cd_m2  # noqa: E402
from microfacet.workflow.render import RenderOptions, passes, render_to_folder  # noqa: E402

G3 = ThicknessMixture([(0.3, 112.0, 3.0), (0.45, 130.0, 3.0), (0.25, 149.0, 3.0)])
F2 = NDFMixture([(0.6, 4.0), (0.4, 12.0)])
TINY = {"camera": {"width_px": 32}, "spp": 8}


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    folder = tmp_path_factory.mktemp("analysis")
    (folder / "summary.json").write_text(json.dumps({
        "format": "microfacet-results/1", "thickness": {"mixture": G3.to_json()},
        "ndf": {"mixture": F2.to_json(), "identified": False, "reason": "too few planes"}}))
    return folder


@pytest.fixture(scope="module")
def rendered(results, tmp_path_factory):
    out = tmp_path_factory.mktemp("r") / "render"
    done = render_to_folder(out, results=results, options=RenderOptions.from_dict(TINY))
    return out, done


def _exr(path):
    return np.asarray(mi.Bitmap(str(path)), dtype=np.float64)


def test_the_folder_holds_what_it_says(rendered):
    out, done = rendered
    assert sorted(p.name for p in out.iterdir()) == [
        "material.npz", "render.exr", "render.json", "render.png", "scene.xml"]
    record = json.loads((out / "render.json").read_text())
    assert record["format"] == "microfacet-render/1" and record["variant"] == done.variant
    linear = _exr(out / "render.exr")
    assert linear.shape == (21, 32, 3) == (*done.shape, 3)
    assert luminance_cd_m2(linear).mean() == pytest.approx(record["mean_luminance_cd_m2"],
                                                           rel=1e-5)
    png = np.asarray(mi.Bitmap(str(out / "render.png")), dtype=np.float64) / 255.0
    exposed = np.clip(linear * record["exposure_scale"], 0, 1)
    srgb = np.where(exposed <= 0.0031308, 12.92 * exposed,
                    1.055 * exposed ** (1 / 2.4) - 0.055)
    assert np.abs(png - srgb).max() <= 1.5 / 255
    assert Material.read(out / "material.npz").ndf == F2
    assert record["source"]["ndf_identified"] is False and done.source["ndf_reason"]


def test_the_scene_file_re_renders_in_mitsuba(rendered, monkeypatch, tmp_path):
    """scene.xml names material.npz relative to itself: it renders from any folder."""
    out, done = rendered
    monkeypatch.chdir(tmp_path)
    mi.set_variant(done.variant)
    bsdf.register()
    again = np.asarray(mi.render(mi.load_file(str(out / "scene.xml")), spp=64), np.float64)
    first = _exr(out / "render.exr")
    assert again.shape == first.shape
    assert again.mean() == pytest.approx(first.mean(), rel=0.15)


def test_a_material_file_renders_the_same_material(results, tmp_path):
    m = Material.from_results(results, theta_step_deg=1.0, wavelength_step_nm=5.0)
    path = m.write(tmp_path / "m.npz")
    out = tmp_path / "from-file"
    render_to_folder(out, material=path, options=RenderOptions.from_dict(
        {**TINY, "scene": "plate"}))
    np.testing.assert_array_equal(Material.read(out / "material.npz").film_average,
                                  m.film_average)


@pytest.mark.parametrize("kind", ["ply", "obj"])
def test_a_users_mesh(results, tmp_path, kind):
    """A mesh file is rendered centred, copied beside scene.xml, and its object is lit."""
    from microfacet.render.scene import Sheet, write_ply
    if kind == "ply":
        mesh = write_ply(tmp_path / "part.ply", Sheet().mesh())
    else:
        mesh = tmp_path / "part.obj"
        mesh.write_text("v -0.05 -0.05 1.0\nv 0.05 -0.05 1.0\nv 0.05 0.05 1.0\n"
                        "v -0.05 0.05 1.0\nf 1 2 3\nf 1 3 4\n")
    out = tmp_path / f"mesh-{kind}"
    render_to_folder(out, results=results, options=RenderOptions.from_dict(
        {**TINY, "scene": str(mesh), "light": {"sky_fraction": 0.0}}))
    y = luminance_cd_m2(_exr(out / "render.exr"))
    assert y.max() > 0 and (y > 0).mean() > 0.05   # the object fills part of the frame
    assert (y == 0).mean() > 0.05                   # and the black background the rest
    assert (out / "meshes" / mesh.name).is_file()
    assert f'value="meshes/{mesh.name}"' in (out / "scene.xml").read_text()


def test_the_scalar_variant_renders_too(results, tmp_path):
    out = tmp_path / "scalar"
    done = render_to_folder(out, results=results, options=RenderOptions.from_dict(
        {"camera": {"width_px": 12}, "spp": 2, "variant": "scalar_spectral"}))
    assert done.variant == "scalar_spectral" and np.isfinite(_exr(out / "render.exr")).all()


def test_output_rules(results, tmp_path):
    with pytest.raises(InputError, match="results"):
        render_to_folder(tmp_path / "x", options=RenderOptions.from_dict(TINY))
    with pytest.raises(InputError, match="no such mesh"):
        render_to_folder(tmp_path / "x", results=results,
                         options=RenderOptions.from_dict({**TINY, "scene": "none.obj"}))
    with pytest.raises(InputError):
        render_to_folder(results, results=results, options=RenderOptions.from_dict(TINY))
    with pytest.raises(InputError, match="variant"):
        render_to_folder(tmp_path / "x", results=results,
                         options=RenderOptions.from_dict({**TINY, "variant": "scalar_rgb"}))
    assert not (tmp_path / "x").exists()
    assert sorted(p.name for p in results.iterdir()) == ["summary.json"]


def test_passes_add_up_to_the_samples():
    for spp in (1, 7, 8, 64, 1000):
        plan = passes(spp)
        assert sum(plan) == spp and len(plan) == min(spp, 8) and max(plan) - min(plan) <= 1


def test_command_line(results, tmp_path, capsys):
    out = tmp_path / "cli"
    assert main(["render", "--results", str(results), "--out", str(out), "--spp", "4",
                 "--camera-width-px", "24", "--light-kind", "sun", "--scene", "sheet"]) == 0
    captured = capsys.readouterr()
    assert "render.png" in captured.out and "too few planes" in captured.err
    assert json.loads((out / "render.json").read_text())["options"]["light"]["kind"] == "sun"
    assert main(["render", "--results", str(results), "--out", str(out), "--spp", "4"]) == 2
    assert "--out" in capsys.readouterr().err
    assert main(["render", "--results", str(results), "--out", str(tmp_path / "b"),
                 "--camera-f-number", "-1"]) == 2
    assert "--camera-f-number" in capsys.readouterr().err
