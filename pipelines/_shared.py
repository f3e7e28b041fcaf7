"""Helpers shared by the studies: timing, Markdown tables and pages, numbers, Pareto fronts,
figures, CSV, direct colour, noisy synthetic scenes, the focus stacks with ground truth.

Imported as ``from pipelines import _shared``. Studies return their tables; what they say
while they work goes to stderr (:func:`note`).
"""

from __future__ import annotations

import csv
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
DOCS = ROOT / "docs"
#: Cou & Guennebaud (2023) synthetic stacks 1-3 with their ground-truth depth
COU = ROOT / "fixtures" / "focus-stacks" / "cou2023-synthetic-rough"
COU_OFFSET_PX = 20  # reference[i, j] <-> pixel (i + 20, j + 20)


# ----------------------------------------------------------------------------- timing
def best_of(fn, repeat, *, min_total_s=0.0, max_calls=30, max_total_s=math.inf):
    """Minimum wall time of ``fn()`` over ``repeat`` calls, and the fastest call's result.

    With ``min_total_s``, calls that take milliseconds are repeated until that much time has
    been spent (at most ``max_calls``), so their minimum is as stable as that of slow ones;
    with ``max_total_s``, calls that take seconds stop after two once it is spent.
    """
    best, res, total, calls = math.inf, None, 0.0, 0
    while (calls < max(1, repeat) and not (calls >= 2 and total > max_total_s)) or (
            total < min_total_s and calls < max_calls):
        t0 = time.perf_counter()
        out = fn()
        dt = time.perf_counter() - t0
        if dt < best:
            best, res = dt, out
        total, calls = total + dt, calls + 1
    return best, res


def round_robin(fns, rounds):
    """Minimum time of each function over ``rounds`` interleaved rounds.

    Interleaving spreads bursts of load from other jobs over all settings, so the ratios
    between them are fairer than with one block of repeats per setting.
    """
    best = [math.inf] * len(fns)
    for _ in range(rounds):
        for i, fn in enumerate(fns):
            t0 = time.perf_counter()
            fn()
            best[i] = min(best[i], time.perf_counter() - t0)
    return best


# ----------------------------------------------------------------------- text, tables
def fmt(x):
    """A number with 2-3 significant digits ("n/a" for None and non-finite)."""
    if x is None or not np.isfinite(x):
        return "n/a"
    if x == 0:
        return "0"
    a = abs(x)
    if a >= 100:
        return f"{x:.0f}"
    if a >= 10:
        return f"{x:.1f}"
    if a >= 0.1:
        return f"{x:.2f}"
    if a >= 0.001:
        return f"{x:.3f}"
    return f"{x:.1e}"


def md_row(cells):
    """One Markdown table row."""
    return "| " + " | ".join(str(c) for c in cells) + " |"


def md_header(header):
    """Header row and rule of a Markdown table (print it, then rows as they come)."""
    return md_row(header) + "\n|" + "---|" * len(header)


def md_table(header, rows):
    """A whole Markdown table."""
    return "\n".join([md_header(header)] + [md_row(r) for r in rows])


def note(*parts):
    """Say what a study is doing (stderr: stdout is the table)."""
    print(*parts, file=sys.stderr, flush=True)


class Doc:
    """A Markdown page kept while it is written: ``doc(text)`` keeps ``text`` (and shows it
    on stderr as progress); ``doc.text()`` is the page."""

    def __init__(self, *, echo=True):
        self.parts = []
        self.echo = echo

    def __call__(self, text=""):
        if self.echo:
            note(text)
        self.parts.append(text)

    def text(self):
        return "\n".join(self.parts) + "\n"

    def write(self, path):
        path = Path(path)
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(self.text())
        return path


# --------------------------------------------------------------------- Pareto fronts
def pareto_front(times, errors):
    """Indices of the points no other point beats in both time and error (sorted by time)."""
    order = sorted(range(len(times)), key=lambda i: (times[i], errors[i]))
    front, best = [], math.inf
    for i in order:
        if errors[i] < best * (1 - 1e-9) - 1e-15:
            front.append(i)
            best = errors[i]
    return front


def verdict(names, times, errors, default, *, target=None, unit="", rel_tol=0.03, fmt=fmt):
    """One sentence: where the default sits (front, cheapest within target, ratios).

    Errors within ``rel_tol`` of the default's count as equal ("as accurate"): differences in
    the last digits of a noisy error are not a reason to prefer a setting.
    """
    front = pareto_front(times, errors)
    d = default
    nm = names[d].replace(" (default)", "")
    s = f"default **{nm}**: error {fmt(errors[d])}{unit}; "
    s += "on the Pareto front" if d in front else "**not** on the Pareto front"
    same = [i for i in range(len(names)) if i != d and times[i] < 0.9 * times[d]
            and errors[i] <= errors[d] * (1 + rel_tol) + 1e-12]
    if same:
        i = min(same, key=lambda k: times[k])
        how = "more accurate" if errors[i] < errors[d] * (1 - rel_tol) else "as accurate"
        s += (f"; {names[i]} is faster ({times[i] / times[d]:.2f}× the default's time) and "
              f"{how} ({fmt(errors[i])}{unit})")
    if target is not None:
        ok = [i for i in range(len(names)) if errors[i] <= target]
        if ok:
            i = min(ok, key=lambda k: times[k])
            s += (f"; the cheapest setting within {fmt(target)}{unit} is **{names[i]}** "
                  f"({times[i] / times[d]:.2f}× the default's time, error {fmt(errors[i])}{unit})")
        else:
            s += f"; no setting reaches {fmt(target)}{unit}"
    return s + "."


# ------------------------------------------------------------------- figures, files
def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path, *, dpi=90):
    """Save ``fig`` to ``path`` (folders made) and close it."""
    import matplotlib.pyplot as plt

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)
    return path






def _csv_cell(v):
    if v is None:
        return ""
    if isinstance(v, float):
        return "" if math.isnan(v) else f"{v:.5g}"
    return v


def write_csv(path, rows, columns):
    """Rows (dicts) as CSV with ``columns``; floats with 5 significant digits, NaN empty."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=columns, extrasaction="ignore", lineterminator="\n")
        w.writeheader()
        for r in rows:
            w.writerow({k: _csv_cell(r.get(k)) for k in columns})
    return path




def git_describe():
    """Commit of the measured library (read-only git query), '+ local changes' if dirty."""
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(ROOT), "status", "--porcelain", "--",
                                "microfacet"], capture_output=True, text=True,
                               timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "commit unknown"
    return f"commit {head}" + (" + local changes in microfacet/" if dirty else "")


# ------------------------------------------------------------------ colour and scenes
def lab_direct(theta_deg, thickness_nm, step=1.0, **optics):
    """Lab by direct spectral integration at ``step`` nm (white of the same grid).

    ``optics``: ``film``, ``substrate``, ... of :func:`microfacet.colour.table.direct_xyz`.
    """
    from microfacet.colour.colorimetry import spectral_weights, xyz_to_lab
    from microfacet.colour.table import WAVELENGTH_RANGE_NM, direct_xyz

    lo, hi = WAVELENGTH_RANGE_NM
    white = spectral_weights(np.linspace(lo, hi, int(round((hi - lo) / step)) + 1)).sum(axis=0)
    return xyz_to_lab(direct_xyz(theta_deg, thickness_nm, spectral_step_nm=step, **optics),
                      white=white)


def through_sensor(linear_rgb, params, rng):
    """Linear RGB through the synthetic sensor (shot + read noise), 8-bit sRGB → (Lab, sRGB)."""
    from microfacet.colour.srgb import srgb_encode, srgb_to_lab
    from microfacet.forward.synth import apply_sensor

    img = apply_sensor(np.asarray(linear_rgb, np.float32), params, rng)
    enc = srgb_encode(img, dtype=np.uint8).astype(np.float32) / 255.0
    return srgb_to_lab(enc).astype(np.float32), enc


def noisy_scene(name="nd", *, size, seed=11):
    """A preset's sharp image with its sensor noise: (params, scene, Lab, mask, σ_n ΔE00)."""
    from microfacet.analysis.colour_image import estimate_colour_noise
    from microfacet.analysis.mask import colour_mask
    from microfacet.forward.synth import preset, render_scene

    p = preset(name, seed=seed, height_px=size, width_px=size)
    sc = render_scene(p)
    lab, enc = through_sensor(sc.linear_rgb, p, np.random.default_rng([seed, 1]))
    mask = colour_mask(enc).mask
    return p, sc, lab, mask, estimate_colour_noise(lab, mask, delta_e_method="CIEDE2000")


def worst_mean_error(true_means, fit_means):
    """Largest distance from a true component mean to the nearest fitted mean (NaN if none)."""
    t = np.asarray(true_means, float)
    f = np.asarray(fit_means, float)
    if f.size == 0:
        return math.nan
    return float(np.max(np.min(np.abs(t[:, None] - f[None, :]), 1)))


def tilt_scores(tilt_est, tilt_true, visible):
    """Median |error| of the per-pixel tilt and the NDF's W1 distance (visible, finite)."""
    from microfacet.core.densities import wasserstein1

    ok = np.isfinite(tilt_est) & visible
    if not ok.any():
        return math.nan, math.nan
    return (float(np.median(np.abs(tilt_est[ok] - tilt_true[ok]))),
            wasserstein1(tilt_est[ok], tilt_true[visible]))


# --------------------------------------------------------------- focus ground truth
def cou_stack(number):
    """Stack ``number`` (1-3) of Cou & Guennebaud (2023) and its true height (−reference)."""
    from microfacet.io.stack import read_stack

    folder = COU / f"stack{number}"
    return read_stack(folder), -np.load(folder / "reference.npy")


def cou_rmse(height, reference):
    """RMSE of a height map against the registered ground truth, all pixels (z units)."""
    o = COU_OFFSET_PX
    d = height[o:o + reference.shape[0], o:o + reference.shape[1]]
    return float(np.sqrt(np.mean((d - reference) ** 2)))


def truthy(v) -> bool:
    """A flag from a row: a bool or 1, or its text in a resumed CSV ("True", "1")."""
    return v is True or v in ("True", "1") or v == 1


def row_number(v) -> float:
    """A number from a row: the value, or its text in a resumed CSV (NaN when missing).

    >>> row_number("0.85"), row_number(2), row_number(None)
    (0.85, 2.0, nan)
    """
    try:
        return float(v)
    except (TypeError, ValueError):
        return math.nan
