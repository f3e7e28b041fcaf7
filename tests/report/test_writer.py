"""write_report (microfacet.report.writer): the PDF and PNGs of a results folder, what it
records in summary.json, and its errors."""

from __future__ import annotations

import copy
import json
import re

import numpy as np
import pytest

from microfacet.core.errors import InputError
from microfacet.io.results import Results, write_results_files
from microfacet.report import NO_VALUE, PAGES, parameter_tables, write_report


def test_real_folder_gives_five_pages_and_pngs(results, report, pdf_pages, check_pngs):
    out, png = report
    assert PAGES == ("overview", "maps", "distributions", "parameters", "angular")
    assert out == results / "report.pdf" and out.is_file()
    assert out.read_bytes().startswith(b"%PDF") and pdf_pages(out) == len(PAGES)
    assert out.stat().st_size < 2_000_000
    assert sorted(p.name for p in png.iterdir()) == check_pngs(png)
    assert not [p for p in results.iterdir() if p.name.startswith(".report.pdf")]


def test_masked_pixels_are_drawn_in_the_no_value_grey(results, report, png_rgb):
    _, png = report
    assert Results(results).map("mask").mean() > 0.01  # the fixture has masked pixels
    grey = tuple(int(NO_VALUE[i:i + 2], 16) for i in (1, 3, 5))
    maps = png_rgb(png / "report_2_maps.png")
    n = int(np.all(maps == grey, axis=-1).sum())
    assert n > 1000  # the masked pixels, on five maps
    # the histogram page has no maps: the grey is only on map pages
    dist = png_rgb(png / "report_3_distributions.png")
    assert int(np.all(dist == grey, axis=-1).sum()) < n / 10


def test_report_time_is_recorded_in_summary_json(results_copy, tmp_path):
    folder = results_copy()
    f = folder / "summary.json"
    before = json.loads(f.read_text())
    before["timings_s"].pop("report", None)   # as the analysis writes it
    f.write_text(json.dumps(before))
    text = f.read_text()
    write_report(folder, out_pdf=tmp_path / "elsewhere" / "r.pdf")
    assert f.read_text() == text  # a PDF outside the folder records nothing
    write_report(folder)
    after = json.loads(f.read_text())
    t = after["timings_s"].pop("report")
    assert isinstance(t, float) and t > 0 and round(t, 4) == t
    assert after == before  # nothing else changed
    # the next report shows it on page 4
    assert dict(parameter_tables(folder)["timings"]["rows"])["report (previous)"] == \
        f"{t:.3g} s"


def test_pdf_elsewhere_and_missing_optional_files(results_copy, tmp_path, pdf_pages):
    folder = results_copy()
    for name in ("mask.npy", "delta_e.npy", "tilt_height_deg.npy", "ndf_pdf.csv"):
        (folder / name).unlink()
    out = write_report(folder, out_pdf=tmp_path / "elsewhere.pdf")
    assert out == tmp_path / "elsewhere.pdf" and pdf_pages(out) == len(PAGES)
    assert not (folder / "report.pdf").exists()


def _all_masked(real, folder):
    """Edge case, hand-made: what the analysis writes when every pixel is masked (NaN maps,
    header-only CSVs, empty mixtures, null statistics), from the real folder's summary."""
    s = copy.deepcopy(Results(real).summary)
    s["thickness"] = {"mixture": {"components": [], "bic": None},
                      "roi": {"count": 1, "fitted": 0, "thickness_nm_mean": None,
                              "ambiguous_count": 0}}
    s["ndf"]["mixture"] = {"components": [], "bic": None}
    s.update(delta_e={"mean": None, "median": None, "p95": None}, masked_fraction=1.0)
    nan = np.full((64, 80), np.nan)
    maps = {n: nan for n in ("height_um", "thickness_nm", "tilt_deg", "tilt_sigma_deg",
                             "delta_e", "colour_weight")}
    maps.update(tilt_height_deg=np.zeros((64, 80)), mask=np.ones((64, 80), bool))
    folder.mkdir()
    write_results_files(
        folder, summary=s, maps=maps, images={"all_in_focus": (np.full((64, 80, 3), 0.5), 8)},
        tables={"thickness_pdf": (np.empty((0, 3)), ["thickness_nm", "density",
                                                     "mixture_density"], "%.6g"),
                "ndf_pdf": (np.empty((0, 3)), ["tilt_deg", "density", "mixture_density"],
                            "%.6g"),
                "thickness_roi": ([[0, 0, 64, np.nan, np.nan, 0]],
                                  ["row0", "col0", "size", "thickness_nm", "mean_delta_e",
                                   "n_pixels"], "%.6g")})
    return folder


def test_all_masked_folder_without_fits_still_renders(results, tmp_path, capsys, pdf_pages,
                                                      check_pngs):
    folder = _all_masked(results, tmp_path / "empty")
    out = write_report(folder, png_dir=tmp_path / "png")
    assert pdf_pages(out) == len(PAGES)
    check_pngs(tmp_path / "png")
    t = parameter_tables(folder)
    assert t["thickness"]["rows"] == [] and t["ndf"]["rows"] == []
    assert t["thickness"]["note"].startswith("no fit")
    assert dict(t["analysis"]["rows"])["masked fraction"] == "100.0 %"
    assert capsys.readouterr() == ("", "")  # library code prints nothing


def test_only_summary_json_is_needed_even_without_an_ndf_fit(results_copy, pdf_pages):
    """summary.json alone (of a folder being written), with the empty NDF mixture the
    analysis writes when it cannot fit."""
    folder = results_copy(".run.partial-abc123", only={"summary.json"})
    assert [p.name for p in folder.iterdir()] == ["summary.json"]
    s = json.loads((folder / "summary.json").read_text())
    s["ndf"]["mixture"] = {"components": [], "bic": None}
    (folder / "summary.json").write_text(json.dumps(s))
    out = write_report(folder)
    assert pdf_pages(out) == len(PAGES)
    title = out.read_bytes().split(b"/Title (", 1)[1].split(b") >>", 1)[0]
    assert title.decode("utf-16").endswith("run")  # the folder's final name, not .partial-


def test_missing_folder_or_summary_is_an_input_error_naming_it(results_copy, tmp_path):
    folder = results_copy()
    (folder / "summary.json").unlink()
    with pytest.raises(InputError, match="summary.json"):
        write_report(folder)
    with pytest.raises(InputError, match="nowhere"):
        write_report(tmp_path / "nowhere")
    assert not (folder / "report.pdf").exists()


@pytest.mark.parametrize("name, text, where", [
    ("summary.json", "{not json", "summary.json"),
    ("summary.json", json.dumps({"thickness": {"mixture": {"components": [
        {"weight": 1.0, "mean_nm": 130.0, "sd_nm": 0.0}]}}}), "summary.json"),
    ("ndf_pdf.csv", "tilt_deg,density\n1,0.1\n", "ndf_pdf.csv"),
    ("thickness_pdf.csv", "thickness_nm,density,mixture_density\n2,0.1,0.1\n1,0.1,0.1\n",
     "thickness_pdf.csv"),
    ("thickness_roi.csv", "row0,col0,size,thickness_nm,mean_delta_e,n_pixels\n0,0,x,1,1,1\n",
     "thickness_roi.csv"),
    ("delta_e.npy", "not an array", "delta_e.npy"),
])
def test_malformed_files_are_input_errors_naming_them(results_copy, name, text, where):
    """Edge cases: one file of a real folder replaced by a malformed one."""
    folder = results_copy()
    (folder / name).write_text(text)
    with pytest.raises(InputError, match=re.escape(where)):
        write_report(folder)
    assert not [p for p in folder.iterdir() if "report.pdf" in p.name]


@pytest.mark.parametrize("fork", [True, False])
def test_png_pages_are_the_same_from_a_forked_child_or_this_process(results_copy, tmp_path,
                                                                    report, png_rgb,
                                                                    pdf_pages, monkeypatch,
                                                                    fork):
    """The PNG pages are drawn by a forked child while this process draws the PDF (on Linux,
    with no other thread), else here after each PDF page: the same pixels either way."""
    from microfacet.report import writer

    if fork and not writer._can_fork():
        pytest.skip("this process cannot fork safely (another thread, or not Linux)")
    monkeypatch.setattr(writer, "_can_fork", lambda: fork)
    folder = results_copy()
    _, ref = report
    png = tmp_path / f"png-{fork}"
    out = write_report(folder, png_dir=png)
    assert pdf_pages(out) == len(PAGES)
    for i, name in enumerate(PAGES, start=1):
        if name == "parameters":      # its tables show the folder and the previous run's times
            continue
        f = f"report_{i}_{name}.png"
        got, want = png_rgb(png / f), png_rgb(ref / f)
        # the header's "report written" minute and the footer's folder may differ
        body = slice(80, -40)
        assert np.array_equal(got[body], want[body]), f


def test_maps_given_in_memory_draw_the_same_pages_without_reading_their_files(
        results_copy, tmp_path, report, png_rgb, monkeypatch):
    """The analysis hands the report the maps it holds (``maps=``, as their files hold them):
    the same pixels as a report that reads the files, no map file is opened, and the caller's
    arrays come back unchanged (the report receives them read-only)."""
    import microfacet.io.results as results_module

    folder = results_copy()
    names = ("height_um", "thickness_nm", "tilt_deg", "tilt_sigma_deg", "delta_e",
             "tilt_height_deg", "mask")
    maps = {n: np.load(folder / f"{n}.npy") for n in names}
    before = {n: a.copy() for n, a in maps.items()}
    loads = []
    real_load = np.load
    monkeypatch.setattr(results_module.np, "load",
                        lambda f, *a, **k: loads.append(f) or real_load(f, *a, **k))
    _, ref = report
    png = tmp_path / "png"
    write_report(folder, png_dir=png, maps=maps)
    assert not [f for f in loads if str(f).endswith(tuple(f"{n}.npy" for n in names))]
    for n in names:
        assert np.array_equal(maps[n], before[n], equal_nan=n != "mask"), n
        assert maps[n].flags.writeable, n              # the caller's array, still its own
    for i, name in enumerate(PAGES, start=1):
        if name == "parameters":      # its tables show the folder and the previous run's times
            continue
        f = f"report_{i}_{name}.png"
        assert np.array_equal(png_rgb(png / f)[80:-40], png_rgb(ref / f)[80:-40]), f


@pytest.mark.parametrize("fork", [True, False])
def test_the_angular_maps_are_predicted_once_and_before_the_fork(results_copy, tmp_path,
                                                                 monkeypatch, fork):
    """Page 5's maps (0.2-0.4 s of thin-film optics) are predicted once per report, in this
    process before the PNG child forks, so that the child draws them without predicting
    them again: every prediction is made by this process, and only one."""
    import os

    from microfacet.report import page_angular, writer

    if fork and not writer._can_fork():
        pytest.skip("this process cannot fork safely (another thread, or not Linux)")
    monkeypatch.setattr(writer, "_can_fork", lambda: fork)
    marks = tmp_path / "predictions"
    marks.mkdir()
    predict = page_angular.predicted_maps

    def recorded(ctx):
        (marks / f"{os.getpid()}-{len(list(marks.iterdir()))}").touch()
        return predict(ctx)

    monkeypatch.setattr(page_angular, "predicted_maps", recorded)
    write_report(results_copy(), png_dir=tmp_path / "png")
    assert [f.name.split("-")[0] for f in marks.iterdir()] == [str(os.getpid())]
    assert (tmp_path / "png" / f"report_{len(PAGES)}_angular.png").is_file()


@pytest.mark.parametrize("caller_froze", [False, True])
def test_older_objects_are_frozen_while_the_report_draws(results_copy, tmp_path, monkeypatch,
                                                         caller_froze):
    """While the pages are drawn the objects alive before the report are out of the
    collector's scans (gc.freeze); afterwards they are back, unless the caller had frozen
    them itself, which is left as it was."""
    import gc

    from microfacet.report import page_parameters

    seen = []
    draw = page_parameters.draw

    def recorded(pg, ctx):
        seen.append(gc.get_freeze_count())
        return draw(pg, ctx)

    monkeypatch.setattr(page_parameters, "draw", recorded)
    if caller_froze:
        gc.freeze()
    try:
        before = gc.get_freeze_count()
        write_report(results_copy(), out_pdf=tmp_path / "r.pdf")
        after = gc.get_freeze_count()
    finally:
        gc.unfreeze()
    assert seen and seen[0] > 0
    assert (before > 0) == caller_froze
    assert (after > 0) == caller_froze      # frozen objects freed meanwhile leave the count


@pytest.mark.parametrize("fork", [True, False])
def test_a_png_that_cannot_be_written_fails_the_report_and_leaves_no_pdf(results_copy,
                                                                         tmp_path, fork,
                                                                         monkeypatch):
    """The same error either way (the child's exception is raised here: a full disk stays an
    OSError naming the file), no PDF, and no child left behind."""
    import os

    from microfacet.report import writer

    if fork and not writer._can_fork():
        pytest.skip("this process cannot fork safely (another thread, or not Linux)")
    monkeypatch.setattr(writer, "_can_fork", lambda: fork)
    pids = []
    start = writer._PngChild.start

    def recorded(*a, **k):
        child = start(*a, **k)
        pids.append(child.pid)
        return child
    monkeypatch.setattr(writer._PngChild, "start", recorded)
    folder = results_copy()
    png = tmp_path / "png"
    (png / "report_3_distributions.png").mkdir(parents=True)   # a folder in the PNG's way
    with pytest.raises(IsADirectoryError, match="report_3_distributions.png"):
        write_report(folder, png_dir=png)
    assert not (folder / "report.pdf").exists()
    assert not [p for p in folder.iterdir() if p.name.startswith(".report.pdf")]
    assert len(pids) == (1 if fork else 0)
    for pid in pids:
        with pytest.raises(ChildProcessError):      # reaped
            os.waitpid(pid, os.WNOHANG)


def test_without_a_second_process_the_pages_are_drawn_here(results_copy, tmp_path,
                                                             monkeypatch, check_pngs):
    """A fork that fails (no memory for it) or a child that hangs (killed after the timeout)
    never fails the report: the PNG pages are drawn in this process."""
    import errno
    import os
    import time

    from microfacet.report import writer

    if not writer._can_fork():
        pytest.skip("this process cannot fork safely (another thread, or not Linux)")
    monkeypatch.setattr(writer, "_can_fork", lambda: True)
    folder = results_copy()

    def no_fork():
        raise OSError(errno.ENOMEM, "Cannot allocate memory")
    with monkeypatch.context() as m:
        m.setattr(os, "fork", no_fork)
        write_report(folder, png_dir=tmp_path / "a")
    check_pngs(tmp_path / "a")
    parent, write = os.getpid(), writer._Pages.write

    def hang_in_child(self, pdf=None, png_dir=None):
        if os.getpid() != parent:
            time.sleep(600)
        return write(self, pdf, png_dir)
    monkeypatch.setattr(writer._Pages, "write", hang_in_child)
    monkeypatch.setattr(writer, "CHILD_TIMEOUT_S", 0.5)
    monkeypatch.setattr(writer, "CHILD_TIMEOUT_PER_PDF", 0.0)
    t0 = time.perf_counter()
    write_report(folder, png_dir=tmp_path / "b")
    assert time.perf_counter() - t0 < 60            # the child's 600 s sleep was cut short
    check_pngs(tmp_path / "b")


def test_pages_that_say_they_read_no_maps_read_none(results_copy, monkeypatch):
    """The pages after the last one that reads maps or images (``READS_MAPS``) draw without
    reading any, so the report lets them go before those pages; it does."""
    from microfacet.report import writer
    from microfacet.report.context import Context

    ctx = Context.open(results_copy())
    pages = writer._Pages(ctx, ctx.res.path, "now")
    last = max(i for i, m in enumerate(writer._MODULES, start=1) if m.READS_MAPS)
    assert 1 <= last < len(writer._MODULES)
    first = ctx.res.map("thickness_nm")
    for i in range(1, last + 1):
        pages.draw(i)
        assert (ctx.res.map("thickness_nm") is first) == (i < last)   # let go after `last`

    def no_reading(*a, **k):
        raise AssertionError("a page said READS_MAPS = False and read a map")
    monkeypatch.setattr(ctx.res, "map", no_reading)
    monkeypatch.setattr(ctx.res, "image", no_reading)
    for i in range(last + 1, len(writer._MODULES) + 1):
        pages.draw(i)


def test_no_fork_beside_another_thread():
    import threading

    from microfacet.report import writer

    stop = threading.Event()
    t = threading.Thread(target=stop.wait)
    t.start()
    try:
        assert not writer._can_fork()
    finally:
        stop.set()
        t.join()
