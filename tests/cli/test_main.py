"""The command line (microfacet.cli.main): help, registered commands, error handling (one
line, exit 2), ``python -m microfacet``. Each command's own tests: test_<command>.py."""

import subprocess
import sys

import pytest

from microfacet.cli import main

HEAVY = ("colour", "sklearn", "matplotlib", "scipy", "skimage", "cv2")


@pytest.mark.slow
def test_help_does_not_import_heavy_modules():
    code = ("import sys\nfrom microfacet.cli.main import build_parser\nbuild_parser()\n"
            f"print([m for m in {HEAVY!r} if m in sys.modules])")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_every_registered_command_has_help_with_an_example(capsys):
    from microfacet.cli.main import build_parser

    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    assert set(sub.choices) == {"init", "analyze", "height", "synth", "simulate", "fit-spectrum",
                                "batch", "export-brdf", "render"}
    for name, p in sub.choices.items():
        assert "example" in (p.epilog or ""), name


def test_no_command_prints_help_and_fails(capsys):
    assert main([]) == 2


@pytest.mark.parametrize("argv, msg", [
    (["fit-spectrum", "missing.csv"], "missing.csv"),
    (["fit-spectrum", "{spec}", "--film", "Nope"], "--film"),
    (["fit-spectrum", "{spec}", "--angle-deg", "95"], "--angle-deg"),
    (["simulate", "--thickness-nm", "-5", "--out", "{tmp}/o"], "--thickness-nm"),
    (["simulate", "--thickness-nm", "50", "--out", "{tmp}/o", "--theta-max-deg", "90"],
     "--theta-max-deg"),
])
def test_user_errors_are_one_line_with_exit_2(tmp_path, capsys, spectrum_csv, argv, msg):
    spec = spectrum_csv(tmp_path / "s.csv", 80.0)
    argv = [a.format(spec=spec, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert msg in err and "Traceback" not in err and err.count("\n") == 1
    assert not (tmp_path / "o").exists()


@pytest.mark.slow
def test_console_script_runs_as_module():
    out = subprocess.run([sys.executable, "-m", "microfacet", "--version"], capture_output=True,
                         text=True)
    assert out.returncode == 0 and "microfacet" in out.stdout


@pytest.mark.parametrize("argv, verbose, quiet", [
    (["-v", "height", "s", "--out", "o"], 1, False),
    (["height", "s", "--out", "o", "-v"], 1, False),
    (["-v", "height", "s", "--out", "o", "-v"], 2, False),
    (["-q", "batch", "s", "--out", "o"], 0, True),
    (["batch", "s", "--out", "o", "-q"], 0, True),
    (["analyze", "s", "--out", "o"], 0, False),
])
def test_verbosity_before_or_after_the_command(argv, verbose, quiet):
    from microfacet.cli.main import build_parser, merge_verbosity

    args = build_parser().parse_args(argv)
    merge_verbosity(args)
    assert (args.verbose, args.quiet) == (verbose, quiet)


def test_verbose_before_the_command_shows_the_traceback(tmp_path, capsys):
    # -v is the switch for tracebacks: it must take effect wherever it is given
    with pytest.raises(ValueError):
        main(["-v", "fit-spectrum", str(tmp_path / "s.csv"), "--angle-deg", "95"])
    assert main(["fit-spectrum", str(tmp_path / "s.csv"), "--angle-deg", "95"]) == 2


@pytest.mark.slow
def test_help_imports_no_heavy_module_per_importtime():
    out = subprocess.run([sys.executable, "-X", "importtime", "-m", "microfacet", "--help"],
                         capture_output=True, text=True, check=True)
    imported = {line.split("|")[-1].strip().split(".")[0]
                for line in out.stderr.splitlines() if line.startswith("import time:")}
    assert "usage: microfacet" in out.stdout
    assert not imported & {*HEAVY, "distributed", "dask", "joblib", "tifffile"}
