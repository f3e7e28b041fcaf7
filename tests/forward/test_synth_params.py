"""Parameters of synthetic stacks (microfacet.forward.synth_params): validation naming the
parameter, variations, JSON round trip, ``microfacet synth --variation``."""

import dataclasses
import json

import pytest

from microfacet.cli import main
from microfacet.forward.synth import preset
from microfacet.forward.synth_params import (
    IMAGING_VARIATIONS,
    VARIATIONS,
    SynthParams,
    parse_variation,
)


@pytest.mark.parametrize("kw", [
    dict(facet_aspect=0.5), dict(facet_size_spread=-0.1), dict(facet_dome_deg=40.0),
    dict(terrace_step_um=-1.0), dict(pit_density_per_mm2=-1.0), dict(pit_wall_deg=90.0),
    dict(scratch_width_um=0.0), dict(scratch_spread_deg=120.0), dict(dust_bright_fraction=2.0),
    dict(illumination_fill=1.5), dict(vignetting_corner_loss=1.0),
    dict(white_balance_gains=(1.0, 0.0, 1.0)), dict(drift_px_per_slice=-0.1),
    dict(jpeg_quality=0), dict(film="nope"), dict(substrate="nope"),
    dict(stain_density_per_mm2=-1.0), dict(stain_radius_um=0.0),
    dict(stain_reflectance_max=1.5), dict(relief_file=""), dict(relief_file="/no/such.x3p")])
def test_out_of_range_variations_name_the_parameter(kw):
    (name,) = kw
    with pytest.raises(ValueError, match=f"^{name}:"):
        preset("nd", **kw)


def test_every_variation_is_off_by_default_and_reported_when_on():
    p = SynthParams()
    assert p.variations_on() == {}
    assert set(IMAGING_VARIATIONS) <= set(VARIATIONS)     # all settable from the CLI
    q = dataclasses.replace(p, dust_density_per_mm2=10.0, vignetting_corner_loss=0.2)
    assert q.variations_on() == {"dust_density_per_mm2": 10.0, "vignetting_corner_loss": 0.2}


def test_json_round_trip_and_older_files():
    p = preset("nd", seed=9, scratch_density_per_mm2=300.0, white_balance_gains=(1.1, 1, 0.95),
               jpeg_quality=80)
    assert SynthParams.from_json(json.loads(json.dumps(p.to_json()))) == p
    old = {k: v for k, v in p.to_json().items() if k not in IMAGING_VARIATIONS}
    assert SynthParams.from_json(old) == dataclasses.replace(
        p, scratch_density_per_mm2=0.0, white_balance_gains=(1.0, 1.0, 1.0), jpeg_quality=None)


def test_relief_file_is_recorded_by_name_only(tmp_path):
    f = tmp_path / "deep" / "m.x3p"
    f.parent.mkdir()
    f.write_bytes(b"x")
    p = SynthParams(relief_file=str(f))
    assert p.measured and p.to_json()["relief_file"] == "m.x3p"
    assert "relief_file" in p.variations_on()
    assert not SynthParams().measured


def test_parse_variation():
    assert parse_variation("facet_aspect=2.5") == ("facet_aspect", 2.5)
    assert parse_variation(" jpeg_quality = 85 ") == ("jpeg_quality", 85)
    assert parse_variation("film=TiO2_Jolivet2023_anatase") == ("film",
                                                                "TiO2_Jolivet2023_anatase")
    assert parse_variation("relief_file=none") == ("relief_file", None)
    assert parse_variation("stain_density_per_mm2=900") == ("stain_density_per_mm2", 900.0)
    for bad, name in (("facet_aspect", "variation"), ("nope=1", "variation"),
                      ("facet_aspect=big", "facet_aspect")):
        with pytest.raises(ValueError, match=f"^{name}:"):
            parse_variation(bad)


@pytest.mark.slow
def test_cli_synth_takes_variations(tmp_path, capsys):
    out = tmp_path / "s"
    assert main(["synth", str(out), "--preset", "sd", "--size", "40x48", "--slices", "3",
                 "--variation", "jpeg_quality=80", "--variation", "pit_density_per_mm2=900",
                 "--variation", "white_balance_gains=1.1,1,0.9", "-q"]) == 0
    meta = json.loads((out / "truth" / "params.json").read_text())
    assert meta["variations"] == {"pit_density_per_mm2": 900.0, "jpeg_quality": 80,
                                  "white_balance_gains": [1.1, 1.0, 0.9]}
    assert (out / "slices" / "000.jpg").is_file()
    assert main(["synth", str(tmp_path / "t"), "--preset", "sd", "--variation",
                 "vignetting_corner_loss=1.5", "-q"]) == 2
    assert "--variation: vignetting_corner_loss" in capsys.readouterr().err
    assert main(["synth", str(tmp_path / "u"), "--preset", "sd", "--variation", "zz=1"]) == 2
    assert "'zz=1'" in capsys.readouterr().err
    assert not (tmp_path / "t").exists() and not (tmp_path / "u").exists()
