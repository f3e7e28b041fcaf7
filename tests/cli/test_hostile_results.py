"""Hostile results folders and measured maps handed to ``microfacet simulate``: each is refused
in one line (exit 2) naming the file and the key, before the work it claims is spent."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import time
import zipfile

import numpy as np
import pytest

from microfacet.cli.main import main

ONE_LINE = re.compile(r"^microfacet [a-z-]+: error: [^\n]+$")
COMPONENT = {"thickness": {"weight": 1, "mean_nm": 51, "sd_nm": 2},
             "ndf": {"weight": 1, "mean_deg": 0, "sd_deg": 5}}

_RUNNER = textwrap.dedent("""
    import os, resource, sys, time
    cap = int(os.environ["MF_AS_LIMIT"])
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    t0 = time.perf_counter()
    from microfacet.cli import main
    try:
        status = main(sys.argv[1:])
    finally:
        with open("/proc/self/status") as fh:
            peak_kb = next(int(line.split()[1]) for line in fh if line.startswith("VmHWM:"))
        with open(os.environ["MF_STATS_FILE"], "w") as fh:
            fh.write(f"{peak_kb} {time.perf_counter() - t0}")
    sys.exit(status)
""")
AS_LIMIT = 6 << 30      # the old code took 5.6 GB on a summary of a million components
RSS_BOUND_MB = 600      # the interpreter, numpy and the JSON parsed (~50 MB of text)
TIME_BOUND_S = 60       # the old code took 39 s and exited 0


def _run_bounded(tmp_path, argv):
    """The CLI in a subprocess under an address-space cap: (status, stderr, peak MB, s)."""
    stats = tmp_path / f"stats-{time.monotonic_ns()}.txt"
    env = {**os.environ, "MF_AS_LIMIT": str(AS_LIMIT), "MF_STATS_FILE": str(stats)}
    res = subprocess.run([sys.executable, "-c", _RUNNER, *argv], capture_output=True,
                         text=True, env=env, timeout=600)
    peak_kb, seconds = stats.read_text().split()
    return res.returncode, res.stderr, int(peak_kb) / 1024, float(seconds)


def _one_line(stderr, pattern):
    assert "Traceback" not in stderr, stderr
    lines = stderr.strip().splitlines()
    assert len(lines) == 1 and ONE_LINE.match(lines[0]), stderr
    assert re.search(pattern, lines[0]), lines[0]
    return lines[0]


def _results(tmp_path, summary, name="res"):
    folder = tmp_path / name
    folder.mkdir()
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def _summary(**sections):
    out = {"format": "microfacet-results/1", "summary_version": 2,
           "thickness": {"mixture": {"components": [COMPONENT["thickness"]]}}}
    out.update(sections)
    return out


@pytest.mark.slow
@pytest.mark.parametrize("key", ["thickness", "ndf"])
def test_a_summary_claiming_a_million_components_is_refused_in_one_line(tmp_path, key):
    """A results folder whose summary.json claims 10**6 components: once 39 s and 5.6 GB and
    exit 0; now refused naming the file and the key, within a bounded time and memory."""
    res = _results(tmp_path, _summary(
        **{key: {"mixture": {"components": [COMPONENT[key]] * 10**6}}}))
    status, err, peak_mb, seconds = _run_bounded(
        tmp_path, ["simulate", "--results", str(res), "--out", str(tmp_path / "sim")])
    assert status == 2, err
    _one_line(err, r"--results: .*summary\.json: \d+ MB is too large for this file \(limit 4 MB\)$")
    assert peak_mb < RSS_BOUND_MB and seconds < TIME_BOUND_S, (peak_mb, seconds)
    assert not (tmp_path / "sim").exists()


@pytest.mark.parametrize("key", ["thickness", "ndf"])
def test_a_summary_with_more_components_than_the_analysis_fits_is_refused(tmp_path, capfd, key):
    res = _results(tmp_path, _summary(
        **{key: {"mixture": {"components": [COMPONENT[key]] * 11}}}))
    status = main(["simulate", "--results", str(res), "--out", str(tmp_path / "sim")])
    err = capfd.readouterr().err
    assert status == 2, err
    _one_line(err, rf"--results: .*summary\.json: key '{key}\.mixture\.components': "
                   rf"11 components, more than 10$")
    assert not (tmp_path / "sim").exists()


@pytest.mark.parametrize("mixture, pattern", [
    ({"components": [{"weight": 1, "mean_nm": 51, "sd_nm": -2}]},
     r"key 'thickness\.mixture': thickness mixture: component 0 has sd <= 0$"),
    ({"components": [{"weight": 1, "mean_nm": 51}]},
     r"key 'thickness\.mixture': thickness mixture: missing key 'sd_nm'$"),
    ({"components": [{"weight": 1, "mean_nm": 51, "sd_nm": 1e4}]},
     r"key 'thickness\.mixture': sd_nm must be <= 1000$"),
    ({"components": [{"weight": 0.5, "mean_nm": 130, "sd_nm": 0.01},
                     {"weight": 0.5, "mean_nm": 1000, "sd_nm": 1000}]},
     r"--results: the mixture spans .* quadrature nodes, more than the limit"),
])
def test_a_bad_recorded_mixture_names_the_file_and_key(tmp_path, capfd, mixture, pattern):
    res = _results(tmp_path, _summary(thickness={"mixture": mixture}))
    status = main(["simulate", "--results", str(res), "--out", str(tmp_path / "sim")])
    err = capfd.readouterr().err
    assert status == 2, err
    line = _one_line(err, pattern)
    assert line.startswith("microfacet simulate: error: --results: ")
    assert not (tmp_path / "sim").exists()


def test_a_recorded_unknown_film_names_the_key(tmp_path, capfd):
    res = _results(tmp_path, _summary(inputs={"film": "Unobtainium"}))
    assert main(["simulate", "--results", str(res), "--out", str(tmp_path / "sim")]) == 2
    _one_line(capfd.readouterr().err,
              r"--results: .*summary\.json: key 'inputs\.film': unknown optical-constant set "
              r"'Unobtainium'")


def test_a_results_folder_without_a_thickness_mixture_is_refused(tmp_path, capfd):
    res = _results(tmp_path, {"format": "microfacet-results/1", "summary_version": 2})
    assert main(["simulate", "--results", str(res), "--out", str(tmp_path / "sim")]) == 2
    _one_line(capfd.readouterr().err, r"--results: .*summary\.json has no thickness\.mixture")


def _npz_claiming(path, **shapes):
    with zipfile.ZipFile(path, "w") as zf:
        for key, (shape, dtype) in shapes.items():
            with zf.open(f"{key}.npy", "w") as fh:
                np.lib.format.write_array_header_1_0(fh, {"descr": np.dtype(dtype).str,
                                                          "fortran_order": False,
                                                          "shape": shape})
    return path


@pytest.mark.parametrize("shapes, pattern", [
    ({"theta_light_deg": ((10**9,), "<f8"), "theta_view_deg": ((5,), "<f8"),
      "lab": ((10**9, 5, 3), "<f4")}, r"key 'theta_light_deg': shape \(1000000000,\)"),
    ({"theta_light_deg": ((3600,), "<f8"), "theta_view_deg": ((3600,), "<f8"),
      "spectra": ((3600, 3600, 4001), "<f8"), "wavelength_nm": ((4001,), "<f8")},
     r"spectra of 3600 x 3600 angles x 4001 wavelengths needs about [\d,]+ MB of memory"),
])
@pytest.mark.slow
def test_a_measured_map_claiming_gigabytes_is_refused_from_its_headers(tmp_path, shapes,
                                                                       pattern):
    path = _npz_claiming(tmp_path / "measured.npz", **shapes)
    assert path.stat().st_size < 2000
    status, err, peak_mb, seconds = _run_bounded(
        tmp_path, ["simulate", "--thickness-nm", "51", "--ndf-lobes", "1:5", "--compare",
                   str(path), "--out", str(tmp_path / "sim")])
    assert status == 2, err
    _one_line(err, pattern)
    assert peak_mb < RSS_BOUND_MB and seconds < TIME_BOUND_S, (peak_mb, seconds)
    assert not (tmp_path / "sim").exists()
