"""microfacet.colour against colour-science (and CIEDE2000 against scikit-image) at the sizes
the analysis uses.

``part="functions"`` (the default): for each function family (XYZ <-> Lab, sRGB
decode/encode, RGB <-> XYZ with and without Bradford adaptation, the Bradford matrix, spectral
weights and spectral integration, the whole image <-> Lab paths, CIEDE2000) it times
microfacet's function and the colour-science equivalent on the same inputs, interleaved in one
loop (best of ``repeat``, the machine is shared), measures the peak memory of one call of each
with ``tracemalloc`` (numpy's allocations are traced; the input is not counted, the output
is), and the largest absolute difference of the outputs after putting them on the same
convention (XYZ with the perfect reflector at ``Y = 1``; colour-science's ``sd_to_XYZ`` gives
``Y = 100``). colour-science runs at its default "reference" domain-range scale. ``ratio`` is
colour-science time / microfacet time (> 1: microfacet is faster); ``rule`` applies the
project's rule (keep our implementation only if colour-science is > 1.5x slower or needs
> 1.5x the memory on a hot-path size). Sizes: a 12-megapixel image (4000 x 3000 x 3), model
tables of 1e5 and 1e6 colours, reflectance arrays of 1e4 and 1e5 spectra x 81 wavelengths
(380-780 nm, 5 nm), 1e6 Lab pairs.

``part="ciede2000"``: ``delta_e_2000`` (float64, float32) against colour-science and
scikit-image on ``n`` random Lab pairs (half near each other, ΔLab ~ N(0, 5), half
independent): ms per 1e6 pairs, pairs/s, time ratio to microfacet float64 and the largest
|ΔE − colour's ΔE| (float32 rows against colour on the float32-rounded inputs).

To measure another copy of microfacet (e.g. the implementation before a change), put it first
on the path and run from outside this checkout (the current folder comes first on the path):
``cd /tmp && PYTHONPATH=/path/to/other:/path/to/this/checkout python -m pipelines run
speed-colour``.
"""

from __future__ import annotations

import gc
import platform
import time
import tracemalloc
import warnings
from pathlib import Path

import numpy as np

from pipelines import Study
from pipelines._shared import md_table, note

STUDY = Study(
    name="speed-colour",
    question="Is each colour function of microfacet faster or leaner than colour-science's "
             "(the rule for keeping our own), and CIEDE2000 than scikit-image's?",
    doc=("docs/colour-benchmarks.md", "speed-colour"),
    run_time="5 min",
    quick_time="5 s",
    options={"part": ("functions", "functions (against colour-science) or ciede2000 "
                                   "(delta_e_2000 against colour-science and scikit-image)"),
             "repeat": (0, "timing repeats, best kept (0: 5, or 1 with --quick)"),
             "only": ("", "functions: only names containing one of these (comma-separated)"),
             "memory": (True, "functions: measure peak memory with tracemalloc"),
             "n": (1_000_000, "ciede2000: number of Lab pairs"),
             "seed": (0, "random inputs")},
)

MB = 1024.0 * 1024.0
HOT = "hot"  # a row at a hot-path size: the 1.5x rule applies
COLD = "one-off"  # (3, 3) matrices, whites, cached weights: delegate whatever the ratio


def _best_pair(ours, theirs, repeat, *, boost=True):
    """Best-of-``repeat`` seconds of two callables, timed alternately in one loop.

    With ``boost`` (a full run), calls under 0.1 s get 5x the repeats (the shared machine's
    noise is larger there) and the garbage collector runs before each call (a quick run
    skips it: with colour-science imported one collection takes ~0.1 s).
    """
    t0 = time.perf_counter()
    theirs()
    repeat = repeat if not boost or time.perf_counter() - t0 > 0.1 else 5 * repeat
    best = [float("inf"), float("inf")]
    for _ in range(repeat):
        for k, fn in enumerate((ours, theirs)):
            if boost:
                gc.collect()
            t0 = time.perf_counter()
            fn()
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


def _peak_mb(fn, *, collect=True):
    """Peak traced memory (MB) of one call above what was allocated before it."""
    if collect:
        gc.collect()
    tracemalloc.start()
    try:
        base = tracemalloc.get_traced_memory()[0]
        tracemalloc.reset_peak()
        out = fn()
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    del out
    return peak / MB


def _max_abs(a, b):
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        return float(np.nanmax(np.abs(a - b)))


def lab_pairs(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """``n`` random Lab pairs: half near each other (ΔLab ~ N(0, 5)), half independent."""
    rng = np.random.default_rng(seed)

    def lab(k):
        return np.column_stack([rng.uniform(0, 100, k), rng.uniform(-128, 128, k),
                                rng.uniform(-128, 128, k)])

    lab1 = lab(n)
    half = n // 2
    return lab1, np.concatenate([lab1[:half] + rng.normal(0, 5, (half, 3)), lab(n - half)])


def _cases(args):  # noqa: C901  (one flat list of cases reads best)
    import colour

    import microfacet.colour as mc
    from microfacet.colour import colorimetry

    rng = np.random.default_rng(args.seed)
    h, w = (150, 200) if args.quick else (3000, 4000)
    img_label = f"{h}x{w}x3"
    tables = (10**4,) if args.quick else (10**5, 10**6)
    n_spectra = (10**3,) if args.quick else (10**4, 10**5)
    n_pairs = 10**4 if args.quick else 10**6

    cs = colour.RGB_COLOURSPACES["sRGB"]
    # The same sRGB as microfacet's: IEC matrix, its exact inverse, white = M @ (1, 1, 1).
    cs_mf = colour.RGB_Colourspace(
        "sRGB (microfacet white)", cs.primaries, colour.XYZ_to_xy(mc.SRGB_WHITE_XYZ),
        matrix_RGB_to_XYZ=mc.SRGB_TO_XYZ, matrix_XYZ_to_RGB=mc.XYZ_TO_SRGB)
    xy_d65 = colour.XYZ_to_xy(mc.white_xyz())
    xy_img = colour.XYZ_to_xy(mc.SRGB_WHITE_XYZ)
    white_a = mc.white_xyz(illuminant="A")
    xy_a = colour.XYZ_to_xy(white_a)

    img8 = rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    lin = {dt: rng.uniform(0, 1, (h, w, 3)).astype(dt) for dt in (np.float32, np.float64)}
    lab_img = {dt: mc.srgb_to_lab(img8).astype(dt) for dt in (np.float32, np.float64)}

    def srgb_to_lab_colour(im):
        rgb = colour.cctf_decoding(im / 255.0, "sRGB")
        return colour.XYZ_to_Lab(colour.RGB_to_XYZ(rgb, cs_mf, chromatic_adaptation_transform=None),
                                 xy_img)

    def lab_to_srgb_colour(lab):
        xyz = colour.Lab_to_XYZ(lab, xy_img)
        rgb = colour.XYZ_to_RGB(xyz, cs_mf, chromatic_adaptation_transform=None)
        enc = colour.cctf_encoding(np.clip(rgb, 0.0, 1.0), "sRGB")
        return np.rint(enc * 255.0).astype(np.uint8)

    cases = []

    def add(fn, size, dt, ours, theirs, kind, theirs_cmp=None, ours_cmp=None):
        cases.append(dict(fn=fn, size=size, dtype=np.dtype(dt).name if dt else "-", ours=ours,
                          theirs=theirs, kind=kind, ours_cmp=ours_cmp, theirs_cmp=theirs_cmp))

    # -- XYZ <-> Lab: model tables and the 12 MP image
    for n in tables:
        xyz = rng.uniform(0, 1.1, (n, 3))
        xyz[: n // 20] *= 0.005  # the linear branch below epsilon
        for dt in (np.float32, np.float64):
            x = xyz.astype(dt)
            add("xyz_to_lab", f"({n:.0e}, 3)", dt, lambda x=x: mc.xyz_to_lab(x),
                lambda x=x: colour.XYZ_to_Lab(x, xy_d65), HOT)
            lab = mc.xyz_to_lab(xyz).astype(dt)
            add("lab_to_xyz", f"({n:.0e}, 3)", dt, lambda lab=lab: mc.lab_to_xyz(lab),
                lambda lab=lab: colour.Lab_to_XYZ(lab, xy_d65), HOT)
    for dt in (np.float32, np.float64):
        x = mc.linear_srgb_to_xyz(lin[dt]).astype(dt)
        add("xyz_to_lab", img_label, dt, lambda x=x: mc.xyz_to_lab(x, white=mc.SRGB_WHITE_XYZ),
            lambda x=x: colour.XYZ_to_Lab(x, xy_img), HOT)
        lab = lab_img[dt]
        add("lab_to_xyz", img_label, dt,
            lambda lab=lab: mc.lab_to_xyz(lab, white=mc.SRGB_WHITE_XYZ),
            lambda lab=lab: colour.Lab_to_XYZ(lab, xy_img), HOT)

    # -- sRGB transfer functions
    add("srgb_decode", img_label, np.uint8, lambda: mc.srgb_decode(img8),
        lambda: colour.cctf_decoding(img8 / 255.0, "sRGB"), HOT)
    img16 = (img8.astype(np.uint16) * 257)
    add("srgb_decode", img_label, np.uint16, lambda: mc.srgb_decode(img16),
        lambda: colour.cctf_decoding(img16 / 65535.0, "sRGB"), HOT)
    for dt in (np.float32, np.float64):
        v = (img8 / 255.0).astype(dt)
        add("srgb_decode", img_label, dt, lambda v=v: mc.srgb_decode(v),
            lambda v=v: colour.cctf_decoding(v, "sRGB"), HOT)
        x = lin[dt]
        add("srgb_encode -> uint8", img_label, dt, lambda x=x: mc.srgb_encode(x),
            lambda x=x: np.rint(colour.cctf_encoding(np.clip(x, 0.0, 1.0), "sRGB") * 255.0
                                ).astype(np.uint8), HOT)
        add("srgb_encode -> float32", img_label, dt,
            lambda x=x: mc.srgb_encode(x, dtype=np.float32),
            lambda x=x: colour.cctf_encoding(np.clip(x, 0.0, 1.0), "sRGB"), HOT)

    # -- RGB <-> XYZ (D65: no adaptation; A: Bradford from the sRGB white)
    for dt in (np.float32, np.float64):
        x = lin[dt]
        add("linear_srgb_to_xyz D65", img_label, dt, lambda x=x: mc.linear_srgb_to_xyz(x),
            lambda x=x: colour.RGB_to_XYZ(x, cs_mf, chromatic_adaptation_transform=None), HOT)
        add("linear_srgb_to_xyz A (Bradford)", img_label, dt,
            lambda x=x: mc.linear_srgb_to_xyz(x, illuminant="A"),
            lambda x=x: colour.RGB_to_XYZ(x, cs_mf, xy_a,
                                          chromatic_adaptation_transform="Bradford"), HOT)
        add("xyz_to_linear_srgb D65", img_label, dt, lambda x=x: mc.xyz_to_linear_srgb(x),
            lambda x=x: colour.XYZ_to_RGB(x, cs_mf, chromatic_adaptation_transform=None), HOT)
        add("xyz_to_linear_srgb A (Bradford)", img_label, dt,
            lambda x=x: mc.xyz_to_linear_srgb(x, illuminant="A"),
            lambda x=x: colour.XYZ_to_RGB(x, cs_mf, xy_a,
                                          chromatic_adaptation_transform="Bradford"), HOT)
    add("bradford_matrix", "(3, 3)", np.float64,
        lambda: mc.bradford_matrix(mc.SRGB_WHITE_XYZ, white_a),
        lambda: colour.adaptation.matrix_chromatic_adaptation_VonKries(
            mc.SRGB_WHITE_XYZ, white_a, transform="Bradford"), COLD)

    # -- spectral weights (one-off, cached by microfacet) and spectral integration
    shape = colour.SpectralShape(380, 780, 5)
    wl = np.asarray(shape.wavelengths, dtype=np.float64)
    cmfs = colour.MSDS_CMFS["CIE 1931 2 Degree Standard Observer"].copy().align(shape)
    ill = colour.SDS_ILLUMINANTS["D65"].copy().align(shape)
    eye = np.eye(wl.size)
    obs = "CIE 1931 2 Degree Standard Observer"

    def weights(grid):  # microfacet's weights without its cache
        return colorimetry._weights_cached.__wrapped__(tuple(grid.tolist()), "D65", obs)

    add("spectral_weights (uncached)", f"{wl.size} wl", np.float64, lambda: weights(wl),
        lambda: colour.msds_to_XYZ(eye, cmfs, ill, method="Integration", shape=shape) / 100.0,
        COLD)
    grid1 = np.arange(360.0, 831.0)
    add("white_xyz (uncached)", "(3,)", np.float64, lambda: weights(grid1).sum(axis=0),
        lambda: colour.sd_to_XYZ(colour.sd_ones(colour.SpectralShape(360, 830, 1)),
                                 colour.MSDS_CMFS[obs], colour.SDS_ILLUMINANTS["D65"],
                                 method="Integration") / 100.0, COLD)
    for n in n_spectra:
        R = 0.5 + 0.45 * np.sin(wl / rng.uniform(20, 120, (n, 1)) + rng.uniform(0, 6, (n, 1)))
        for dt in (np.float32, np.float64):
            r = R.astype(dt)
            add("spectrum_to_xyz", f"({n:.0e}, {wl.size})", dt,
                lambda r=r: mc.spectrum_to_xyz(r, wl),
                lambda r=r: colour.msds_to_XYZ(r, cmfs, ill, method="Integration",
                                               shape=shape) / 100.0, HOT)

    # -- CIEDE2000 (ours is float32 throughout for float32 input)
    lab1, lab2 = lab_pairs(n_pairs, args.seed)
    for dt in (np.float32, np.float64):
        a, b = lab1.astype(dt), lab2.astype(dt)
        add("delta_e_2000", f"({n_pairs:.0e}, 3) pairs", dt,
            lambda a=a, b=b: mc.delta_e_2000(a, b),
            lambda a=a, b=b: colour.delta_E(a, b, method="CIE 2000"), HOT)

    # -- whole image paths (the analysis: uint8 camera image -> Lab; Lab -> uint8 preview)
    add("srgb_to_lab", img_label, np.uint8, lambda: mc.srgb_to_lab(img8),
        lambda: srgb_to_lab_colour(img8), HOT)
    for dt in (np.float32, np.float64):
        lab = lab_img[dt]
        add("lab_to_srgb", img_label, dt, lambda lab=lab: mc.lab_to_srgb(lab),
            lambda lab=lab: lab_to_srgb_colour(lab), HOT)
    return cases


def _rule(ratio, mem_ratio, kind):
    if kind == COLD:
        return "not hot: delegate"
    if ratio > 1.5 or mem_ratio > 1.5:
        return f"keep ours ({ratio:.1f}x time, {mem_ratio:.1f}x memory)"
    return "comparable: delegate"


class _Args:
    def __init__(self, **kw):
        self.__dict__.update(kw)


def functions_table(args) -> str:
    import colour

    import microfacet

    colour.set_domain_range_scale("reference")
    cases = _cases(args)
    if args.only:
        cases = [c for c in cases if any(s in c["fn"] for s in args.only)]
    note(f"colour-science {colour.__version__}, numpy {np.__version__}, "
         f"Python {platform.python_version()}, {platform.machine()}; best of {args.repeat}; "
         f"microfacet from {microfacet.__file__.rsplit('/microfacet/', 1)[0]}")
    rows = []
    for c in cases:
        t_ours, t_theirs = _best_pair(c["ours"], c["theirs"], args.repeat,
                                       boost=not args.quick)
        diff = _max_abs(c["ours"](), c["theirs"]())
        if not args.memory:
            m_ours = m_theirs = float("nan")
        else:
            m_ours, m_theirs = (_peak_mb(c[k], collect=not args.quick)
                                for k in ("ours", "theirs"))
        ratio = t_theirs / t_ours
        mem_ratio = m_theirs / m_ours if m_ours > 0 else float("nan")
        ms = (lambda t: f"{t * 1e3:.3f}") if t_ours < 1e-3 else (lambda t: f"{t * 1e3:.1f}")
        rows.append([c["fn"], c["size"], c["dtype"], ms(t_ours), ms(t_theirs), f"{ratio:.2f}",
                     f"{diff:.1e}", f"{m_ours:.1f} / {m_theirs:.1f}",
                     _rule(ratio, mem_ratio, c["kind"])])
        note(" | ".join(rows[-1]))
    table = md_table(["function", "size", "dtype", "ours ms", "colour-science ms", "ratio",
                      "max abs diff", "peak MB ours / theirs", "rule"], rows)
    # right-align the numeric columns, as the doc's table
    lines = table.splitlines()
    lines[1] = "|---|---|---|---:|---:|---:|---:|---:|---|"
    return (f"colour-science {colour.__version__}, numpy {np.__version__}, Python "
            f"{platform.python_version()}, {platform.machine()}; best of {args.repeat}\n\n"
            + "\n".join(lines))


def ciede2000_table(n: int, repeat: int, seed: int) -> str:
    import colour
    import skimage
    from skimage.color import deltaE_ciede2000

    from microfacet.colour import delta_e_2000

    lab1, lab2 = lab_pairs(n, seed)
    lab1_32, lab2_32 = lab1.astype(np.float32), lab2.astype(np.float32)
    ref = colour.delta_E(lab1, lab2, method="CIE 2000")
    ref32 = colour.delta_E(lab1_32.astype(np.float64), lab2_32.astype(np.float64),
                           method="CIE 2000")
    methods = [
        ("microfacet float64", lambda: delta_e_2000(lab1, lab2), ref),
        ("microfacet float32", lambda: delta_e_2000(lab1_32, lab2_32), ref32),
        (f"colour-science {colour.__version__}",
         lambda: colour.delta_E(lab1, lab2, method="CIE 2000"), ref),
        (f"scikit-image {skimage.__version__}", lambda: deltaE_ciede2000(lab1, lab2), ref),
    ]
    rows = []
    for name, fn, reference in methods:
        best, out = float("inf"), None
        for _ in range(repeat):
            t0 = time.perf_counter()
            out = fn()
            best = min(best, time.perf_counter() - t0)
        rows.append((name, best, float(np.max(np.abs(np.asarray(out, np.float64) - reference)))))
    base = rows[0][1]
    note(f"n = {n} pairs, best of {repeat}; numpy {np.__version__}, Python "
         f"{platform.python_version()}, {platform.machine()}")
    table = md_table(["method", "ms per 1e6 pairs", "pairs/s",
                      "time ratio vs microfacet float64", "max abs(dE - colour dE)"],
                     [[name, f"{t * 1e3 * 1e6 / n:.1f}", f"{n / t:.3g}", f"{t / base:.2f}",
                       f"{err:.1e}"] for name, t, err in rows])
    lines = table.splitlines()
    lines[1] = "|---|---:|---:|---:|---:|"
    return "\n".join(lines)


def run(*, quick: bool, out: Path, part="functions", repeat=0, only="", memory=True,
        n=1_000_000, seed=0) -> str:
    repeat = repeat or (1 if quick else 5)
    warnings.simplefilter("ignore")
    if part == "ciede2000":
        return ciede2000_table(min(n, 10**5) if quick else n, repeat, seed)
    if part != "functions":
        raise ValueError(f"part: functions or ciede2000, got {part!r}")
    return functions_table(_Args(quick=quick, repeat=repeat, seed=seed, memory=memory,
                                 only=[x for x in (only or "").split(",") if x]))
