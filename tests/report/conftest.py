"""Fixtures of the report tests: a real results folder written by the analysis, its report,
and readers of PDFs and PNGs."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import numpy as np
import pytest

from microfacet.analysis import analyse_stack
from microfacet.analysis.output import write_results
from microfacet.io.images import read_png
from microfacet.report import PAGES, write_report

STACK = Path(__file__).resolve().parents[2] / "fixtures/stacks/nd-fixture"


@pytest.fixture(scope="module")
def results(tmp_path_factory):
    """A results folder written by the analysis of the nd fixture (once per test module)."""
    r = analyse_stack(STACK)
    return write_results(r, tmp_path_factory.mktemp("res") / "nd")


@pytest.fixture(scope="module")
def report(results, tmp_path_factory):
    """(report.pdf, PNG folder) of :func:`results`."""
    png = tmp_path_factory.mktemp("png")
    return write_report(results, png_dir=png), png


@pytest.fixture
def results_copy(results, tmp_path):
    """``results_copy(name="nd", only=None)``: a copy of the real results folder (without the
    report of :func:`report`; only the files in the set ``only`` if given) that a test may
    change."""
    def copy(name="nd", *, only=None):
        dest = tmp_path / name
        shutil.copytree(results, dest, ignore=lambda d, names: [
            n for n in names if n == "report.pdf" or (only is not None and n not in only)])
        return dest
    return copy


@pytest.fixture(scope="session")
def pdf_text():
    """``pdf_text(path, page)``: text of one PDF page (1-based), read by pypdf (a test extra:
    these tests never skip): the lines as laid out on the page, then the page's text in
    every orientation (the layout mode leaves out rotated text, such as the colour bars'
    labels)."""
    from pypdf import PdfReader

    def read(path, page):
        p = PdfReader(path).pages[page - 1]
        return p.extract_text(extraction_mode="layout") + "\n" + p.extract_text()
    return read


@pytest.fixture(scope="session")
def pdf_pages():
    """``pdf_pages(path)``: number of page objects in a PDF written by matplotlib."""
    return lambda path: len(re.findall(rb"/Type\s*/Page\b(?!s)", Path(path).read_bytes()))


@pytest.fixture(scope="session")
def png_rgb():
    """``png_rgb(path)``: an 8-bit PNG as an RGB uint8 array."""
    def read(path):
        img = read_png(path)
        assert img.ndim == 3, f"{path} is not RGB"
        return np.round(img[..., :3] * 255).astype(np.uint8)
    return read


@pytest.fixture(scope="session")
def check_pngs(png_rgb):
    """``check_pngs(folder)``: every page PNG exists, is A4 landscape at ~110 dpi and is not
    blank; returns their names."""
    def check(folder):
        names = [f"report_{i}_{n}.png" for i, n in enumerate(PAGES, start=1)]
        for name in names:
            img = png_rgb(folder / name)
            h, w = img.shape[:2]
            assert 1200 <= w <= 1400 and abs(w / h - 11.69 / 8.27) < 0.01, (name, img.shape)
            assert img.std() > 10, f"{name} looks blank"
        return names
    return check
