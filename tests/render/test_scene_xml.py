"""microfacet.render.scene_xml: the scene written as Mitsuba XML renders what the dictionary
renders (a custom Python BSDF included), with its meshes copied beside it."""

from __future__ import annotations

import numpy as np
import pytest

mi = pytest.importorskip("mitsuba")
dr = pytest.importorskip("drjit")

from microfacet.core.errors import InputError  # noqa: E402
from microfacet.render.scene import Camera, Light, build_scene, luminance_cd_m2  # noqa: E402
from microfacet.render.scene_xml import write_scene_xml  # noqa: E402


def render(scene: dict, *, spp: int, seed: int = 0) -> np.ndarray:
    return np.array(mi.render(mi.load_dict(scene), spp=spp, seed=seed), dtype=np.float64)


class _Lambert:
    """A trivial Python BSDF, registered under a custom name like the thin-film one."""

    NAME = "microfacet_test_lambert"

    @classmethod
    def register(cls):
        class Lambert(mi.BSDF):
            def __init__(self, props):
                mi.BSDF.__init__(self, props)
                self.r = props.get("reflectance", 0.5)
                self.m_flags = mi.BSDFFlags.DiffuseReflection | mi.BSDFFlags.FrontSide
                self.m_components = [self.m_flags]

            def sample(self, ctx, si, sample1, sample2, active=True):
                bs = dr.zeros(mi.BSDFSample3f)
                bs.wo = mi.warp.square_to_cosine_hemisphere(sample2)
                bs.pdf = mi.warp.square_to_cosine_hemisphere_pdf(bs.wo)
                bs.eta = 1.0
                bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
                bs.sampled_component = mi.UInt32(0)
                ok = active & (mi.Frame3f.cos_theta(si.wi) > 0)
                return bs, dr.select(ok, mi.Spectrum(self.r), mi.Spectrum(0.0))

            def eval(self, ctx, si, wo, active=True):
                co = mi.Frame3f.cos_theta(wo)
                ok = active & (mi.Frame3f.cos_theta(si.wi) > 0) & (co > 0)
                return dr.select(ok, mi.Spectrum(self.r * dr.inv_pi * co), mi.Spectrum(0.0))

            def pdf(self, ctx, si, wo, active=True):
                ok = active & (mi.Frame3f.cos_theta(si.wi) > 0)
                return dr.select(ok, mi.warp.square_to_cosine_hemisphere_pdf(wo), 0.0)

            def eval_pdf(self, ctx, si, wo, active=True):
                return self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active)

            def traverse(self, callback):
                pass

            def to_string(self):
                return "TestLambert"

        mi.register_bsdf(cls.NAME, lambda props: Lambert(props))


@pytest.mark.slow
@pytest.mark.parametrize("obj, light", [("sheet", Light()), ("sphere", Light(kind="sun"))])
def test_scene_xml_renders_what_the_dict_renders(tmp_path, variant, obj, light):
    _Lambert.register()
    cam = Camera(width_px=48, height_px=32, elevation_deg=60.0, distance_m=0.35)
    scene = build_scene(obj=obj, bsdf={"type": _Lambert.NAME, "reflectance": 0.6},
                        camera=cam, light=light, mesh_folder=tmp_path / "gen")
    path = write_scene_xml(scene, tmp_path / "out")
    text = path.read_text()
    assert f'<bsdf type="{_Lambert.NAME}"' in text
    meshes = list((tmp_path / "out").glob("meshes/*.ply"))
    assert len(meshes) == (obj == "sheet")                        # copied beside scene.xml
    assert ('value="meshes/' in text) == (obj == "sheet")
    a = render(scene, spp=8, seed=3)
    b = np.array(mi.render(mi.load_file(str(path)), spp=8, seed=3), dtype=np.float64)
    assert a.shape == b.shape and a.mean() > 1.0                  # the sheet is lit
    assert np.abs(a - b).mean() <= 1e-3 * a.mean()
    # and the built-in Lambertian agrees with the custom one through the same file
    ref = render({**scene, "object": {**scene["object"],
                                      "bsdf": {"type": "diffuse", "reflectance": 0.6}}},
                 spp=64, seed=5)
    assert luminance_cd_m2(b).mean() == pytest.approx(luminance_cd_m2(ref).mean(), rel=0.05)


def test_a_dict_that_is_not_a_scene_is_refused(tmp_path):
    with pytest.raises(InputError, match="scene"):
        write_scene_xml({"type": "diffuse"}, tmp_path)
