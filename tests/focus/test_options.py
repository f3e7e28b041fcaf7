"""The options of height from focus (microfacet.focus.options): defaults, validation naming
the field, and the command-line flags generated from the fields."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from microfacet.cli.options import add_option_fields, cli_flags, options_from_args
from microfacet.core.errors import InputError
from microfacet.core.options import option_fields
from microfacet.focus.options import (
    EARLIER_DEFAULT,
    OPERATORS,
    RELIABILITY_CUTS_DB,
    FocusOptions,
)

#: The options ``microfacet height`` offered before the options were typed, and their flags.
CLI_OPTIONS = {"operator": "--operator", "window_px": "--window-px", "window": "--window",
               "interpolation": "--interpolation", "fit_radius": "--fit-radius",
               "min_reliability_db": "--min-reliability-db", "fill": "--fill",
               "align": "--align"}


def test_defaults():
    o = FocusOptions()
    assert (o.operator, o.window_px, o.window, o.interpolation, o.fit_radius) == (
        "tenengrad", 7, "gaussian", "lorentz", 2)
    assert (o.min_reliability_db, o.fill, o.align, o.reference) == (None, None, None, None)
    assert (o.colour, o.coarse_window_px, o.fine_window_px, o.reliability) == (
        "luma", 15, 0, "sigma")
    assert o.reliability_cut_db == 4.0 and o.fit_radius_used == 2
    assert FocusOptions.from_dict(o.to_dict()) == o


def test_every_field_is_documented():
    for f in option_fields(FocusOptions):
        assert f.help and len(f.help) > 20, f.path
        assert f"{f.path} :" in FocusOptions.__doc__, f.path


def test_reliability_cut_resolves_per_measure_and_operator():
    assert set(RELIABILITY_CUTS_DB) == {"sigma", "pertuz"}
    for table in RELIABILITY_CUTS_DB.values():
        assert set(table) == set(OPERATORS)
    assert FocusOptions(reliability="pertuz", operator="sml").reliability_cut_db == 9.0
    assert FocusOptions(min_reliability_db=-np.inf).reliability_cut_db == -math.inf
    assert FocusOptions(min_reliability_db=6).reliability_cut_db == 6.0


def test_fit_radius_used():
    assert FocusOptions(interpolation="lsq", fit_radius=3).fit_radius_used == 3
    assert FocusOptions(interpolation="gauss3", fit_radius=3).fit_radius_used == 1
    assert FocusOptions(interpolation="none").fit_radius_used == 1


def test_earlier_default():
    assert EARLIER_DEFAULT.interpolation == "lsq" and EARLIER_DEFAULT.coarse_window_px == 0
    assert EARLIER_DEFAULT.reliability == "pertuz" and EARLIER_DEFAULT.reliability_cut_db == 12


@pytest.mark.parametrize("field,value,reason", [
    ("operator", "laplace", "must be one of tenengrad, sml, glv"),
    ("window_px", 4, "must be an odd integer >= 1"),
    ("window_px", 0, "must be an odd integer >= 1"),
    ("window_px", True, "must be an odd integer >= 1"),
    ("window_px", 7.0, "must be an odd integer >= 1"),
    ("window", "disc", "must be one of gaussian, box"),
    ("interpolation", "cubic", "must be one of"),
    ("fit_radius", 0, "must be an integer in 1..10"),
    ("fit_radius", 11, "must be an integer in 1..10"),
    ("fit_radius", 2.5, "must be an integer in 1..10"),
    ("min_reliability_db", float("nan"), "must be a number"),
    ("min_reliability_db", "4", "must be a number"),
    ("fill", True, "must be one of smooth, nearest"),
    ("align", "sift", "must be one of ecc, phase"),
    ("align", True, "must be one of ecc, phase"),
    ("reference", -1, "must be an integer >= 0"),
    ("colour", "hsv", "must be one of luma, rgb"),
    ("coarse_window_px", 14, "must be 0 (none) or an odd integer >= 1"),
    ("coarse_window_px", None, "must be given"),
    ("fine_window_px", -3, "must be 0 (none) or an odd integer >= 1"),
    ("reliability", "snr", "must be one of sigma, pertuz"),
])
def test_validation_names_the_field(field, value, reason):
    with pytest.raises(InputError) as exc:
        FocusOptions(**{field: value})
    assert exc.value.param == field
    assert str(exc.value).startswith(f"{field}: {reason}")


def test_numpy_integers_are_integers():
    o = FocusOptions(window_px=np.int64(9), fit_radius=np.int32(3), reference=np.int64(0),
                     coarse_window_px=np.int16(0))
    assert o.window_px == 9 and o.fit_radius_used == 3


def test_validation_inside_a_tree_names_the_dotted_path():
    from microfacet.analysis.options import AnalysisOptions

    with pytest.raises(InputError) as exc:
        AnalysisOptions.from_dict({"focus": {"window_px": 8}})
    assert exc.value.param == "focus.window_px"


def _parse(argv):
    p = argparse.ArgumentParser()
    add_option_fields(p, FocusOptions)
    return p, p.parse_args(argv)


def test_cli_flags_generated_from_the_fields():
    assert cli_flags(FocusOptions) == CLI_OPTIONS
    p, args = _parse([])
    assert options_from_args(args, FocusOptions) == FocusOptions()
    help_text = p.format_help()
    for flag in CLI_OPTIONS.values():
        assert flag in help_text
    assert "(default 7 px)" in help_text and "(default tenengrad)" in help_text
    assert "--colour" not in help_text and "--reference" not in help_text


def test_cli_values():
    _, args = _parse(["--operator", "sml", "--window-px", "9", "--window", "box",
                      "--interpolation", "lsq", "--fit-radius", "3",
                      "--min-reliability-db=-inf", "--fill", "--align"])
    o = options_from_args(args, FocusOptions)
    assert o == FocusOptions(operator="sml", window_px=9, window="box", interpolation="lsq",
                             fit_radius=3, min_reliability_db=-math.inf, fill="smooth",
                             align="ecc")
    _, args = _parse(["--fill", "nearest", "--align", "phase"])
    o = options_from_args(args, FocusOptions)
    assert (o.fill, o.align) == ("nearest", "phase")


def test_cli_choices_and_errors():
    p, _ = _parse([])
    with pytest.raises(SystemExit):
        p.parse_args(["--align", "sift"])
    with pytest.raises(SystemExit):
        p.parse_args(["--operator", "laplace"])
    _, args = _parse(["--window-px", "8"])
    with pytest.raises(InputError) as exc:
        options_from_args(args, FocusOptions)
    assert exc.value.cli_message(cli_flags(FocusOptions)).startswith(
        "--window-px: must be an odd integer >= 1, got 8")
