"""Generalization sweep: the analysis on synthetic scenes drawn across independent imaging
variations it was not tuned on, scored fairly against their truth.

Every scene first draws its *world* (:data:`WORLDS`): ``faceted`` (planar facets with dark
grooves, the generator's own scenes), ``sparse`` (facets with no grooves and no per-facet
thickness offsets, so their interiors carry no texture: the contrast lives only at a few
pits and/or scratches) or ``measured`` (the geometry of a real instrument height map of
``fixtures/instrument-heights/``, :data:`MEASURED_FILES`, resampled with its slopes kept; no
grooves). Then it draws each variation of ``microfacet.forward.synth_params`` on or off
independently (probability ``P_ON``) with a strength log-uniform in a realistic range: no
grooves between facets, pits, scratches, dust, vignetting, JPEG slices, white-balance error,
drift between slices, tilt-dependent brightness, elongated / size-spread / rounded facets,
other optical constants, terraces, stains (dark patches of the film, not in the height).
The world, the stains and the sparse world's defects come from their own stream
(``[seed, i, 1]``), so the other draws of scene ``i`` are those of the sweep before worlds
existed. Always drawn: 1-3 thickness populations (means 20-260 nm,
across the first two interference orders, ≥ 12 nm and ≥ 4 SD apart), 1-2 NDF lobes of
2-14°, facet size, waviness, per-facet thickness offsets, exposure and sensor noise. The
stacks are analysed with ``microfacet.workflow.run_batch`` (``mode``: joint, seed or both)
and scored with :mod:`pipelines._scoring` (its docstring says what and why): thickness per
true region, the share of the thickness map read an order off, number of thickness
populations and NDF lobes, NDF W1 where the analysis says
the NDF is identified, the identified fraction on textured scenes, ΔE00 against the scene's
colour noise floor. A scene that fails to generate, analyse or score is recorded as failed.

Outputs under ``out``: ``generalization.csv`` (one row per scene and mode),
``generalization.png`` (median scores with each variation on and off; ``--docs`` copies both
into docs/data/ and docs/img/) and ``work/`` (the stacks and results; ``work=DIR`` keeps them
elsewhere and resumes a sweep there). The table is the targets beside each mode's summary
scores, over all scenes and per world (docs/accuracy.md); the per-scene table goes to
stderr.
"""

from __future__ import annotations

import functools
import json
import math
import os
import shutil
import time
from pathlib import Path

import numpy as np

from microfacet.forward.synth import SynthParams, ThicknessComponent, TiltLobe
from microfacet.optics import DEFAULT_FILM, known_sets
from pipelines import Study
from pipelines._shared import (
    ROOT,
    fmt,
    md_table,
    note,
    pyplot,
    row_number,
    save_figure,
    truthy,
    write_csv,
)

STUDY = Study(
    name="accuracy-sweep",
    question="How accurate is the analysis on random scenes with imaging variations it was "
             "not tuned on (the accuracy targets)?",
    doc=("docs/accuracy.md", "accuracy-sweep"),
    run_time="5 min",
    quick_time="15 s",
    options={"n": (30, "number of scenes"),
             "seed": (0, "seed of the scene draws"),
             "size": ("256x256", "HxW in px"),
             "slices": (16, "slices per stack"),
             "mode": ("both", "joint, seed or both"),
             "jobs": (0, "local worker processes (0: the batch's default)"),
             "scheduler": ("", "Dask scheduler address"),
             "work": ("", "folder for the stacks and results (default out/work); reused: "
                          "the sweep resumes"),
             "reference": ("none", "none, or substrate: every session also has a field of the "
                                   "bare metal through its camera (native oxide drawn in 2-5 "
                                   "nm), given as stack.json's substrate_reference"),
             "analysis": ("", "analysis options over the defaults, SECTION.KEY=VALUE joined "
                              "by ';' (e.g. joint.unmix_heights=true); with a work folder of "
                              "its own (a resumed sweep keeps the results it has)")},
    doc_files={"generalization.csv": "docs/data/generalization.csv",
               "generalization.png": "docs/img/generalization.png"},
)

#: Probability that a variation is on in a scene.
P_ON = 0.35
SIGNAL = 0.3  # linear signal at which the relative noise is quoted


def _lu(rng, lo, hi):
    """Log-uniform draw in [lo, hi]."""
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


# name -> what it sets, given the scene's generator (each drawn only when the variation is on)
VARIATIONS = {
    "no_grooves": lambda r: dict(groove_wall_deg=0.0),
    "pits": lambda r: dict(pit_density_per_mm2=_lu(r, 500, 5000), pit_radius_um=_lu(r, 1, 4),
                           pit_wall_deg=float(r.uniform(50, 75))),
    "scratches": lambda r: dict(scratch_density_per_mm2=_lu(r, 300, 3000),
                                scratch_length_um=_lu(r, 20, 150),
                                scratch_width_um=_lu(r, 0.5, 2.0),
                                scratch_wall_deg=float(r.uniform(35, 60)),
                                scratch_spread_deg=5.0 if r.random() < 0.5 else 90.0),
    "dust": lambda r: dict(dust_density_per_mm2=_lu(r, 500, 8000), dust_radius_um=_lu(r, 0.5, 3),
                           dust_bright_fraction=float(r.uniform(0.2, 0.8))),
    "vignetting": lambda r: dict(vignetting_corner_loss=_lu(r, 0.1, 0.5)),
    "jpeg": lambda r: dict(jpeg_quality=int(r.integers(70, 96))),
    "white_balance": lambda r: dict(white_balance_gains=(_lu(r, 0.85, 1.15), 1.0,
                                                         _lu(r, 0.85, 1.15))),
    "drift": lambda r: dict(drift_px_per_slice=_lu(r, 0.05, 0.5)),
    "tilt_brightness": lambda r: dict(illumination_fill=float(r.uniform(0.3, 1.0))),
    "elongated": lambda r: dict(facet_aspect=_lu(r, 1.5, 4.0)),
    "size_spread": lambda r: dict(facet_size_spread=float(r.uniform(0.2, 0.6))),
    "rounded": lambda r: dict(facet_dome_deg=_lu(r, 2.0, 10.0)),
    "optics": lambda r: dict(
        film=str(r.choice([s for s in known_sets() if s.startswith("TiO2") and s != DEFAULT_FILM])),
        substrate=str(r.choice([s for s in known_sets() if s.startswith("Ti_")]))),
    "terraces": lambda r: dict(terrace_step_um=_lu(r, 0.3, 1.5), terrace_size_um=_lu(r, 10, 30)),
    "stains": lambda r: dict(stain_density_per_mm2=_lu(r, 300, 3000),
                             stain_radius_um=_lu(r, 0.5, 3.0)),
}
#: Variations drawn from the world's stream (added after the sweep's first version).
WORLD_STREAM_VARIATIONS = ("stains",)

#: The worlds of a scene and their probabilities.
WORLDS = {"faceted": 0.5, "sparse": 0.25, "measured": 0.25}
#: Folder of the instrument height maps of the ``measured`` world.
HEIGHTS = ROOT / "fixtures" / "instrument-heights"
#: Their files and probabilities (al3d: rough, RMS gradient 0.24; plu and mnt: nearly flat).
MEASURED_FILES = {"al3d-1.al3d": 0.6, "plu-1.plu": 0.2, "mnt-1.mnt": 0.2}
#: Variations a measured surface replaces (the generator refuses them with ``relief_file``).
NOT_MEASURED = ("terraces", "rounded", "no_grooves")


def draw_world(rng) -> tuple[str, dict]:
    """A world and the parameters it sets (over the scene's other draws).

    >>> world, kw = draw_world(np.random.default_rng([0, 0, 1]))
    >>> world in WORLDS
    True
    """
    world = str(rng.choice(list(WORLDS), p=list(WORLDS.values())))
    if world == "sparse":
        kw = dict(groove_wall_deg=0.0, thickness_facet_sd_nm=0.0)
        u = rng.random()
        if u < 2 / 3:   # pits (alone or with scratches), sparse
            kw.update(pit_density_per_mm2=_lu(rng, 300, 1500), pit_radius_um=_lu(rng, 1, 3),
                      pit_wall_deg=float(rng.uniform(50, 75)))
        if u >= 1 / 3:  # scratches (alone or with pits), sparse
            kw.update(scratch_density_per_mm2=_lu(rng, 150, 600),
                      scratch_length_um=_lu(rng, 20, 100), scratch_width_um=_lu(rng, 0.5, 1.5),
                      scratch_wall_deg=float(rng.uniform(35, 60)),
                      scratch_spread_deg=5.0 if rng.random() < 0.5 else 90.0)
        return world, kw
    if world == "measured":
        name = str(rng.choice(list(MEASURED_FILES), p=list(MEASURED_FILES.values())))
        return world, dict(relief_file=str(HEIGHTS / name), groove_wall_deg=0.0,
                           terrace_step_um=0.0, facet_dome_deg=0.0)
    return world, {}


def world_of(params: dict) -> str:
    """The world of a scene from its parameters (``truth/params.json`` key ``params``): the
    sweep's scenes name it in their preset (``generalization-WORLD``); others are
    ``measured`` with a ``relief_file``, ``sparse`` without grooves, else ``faceted`` (a
    faceted scene with the ``no_grooves`` variation is then also ``sparse``).

    >>> world_of({"preset": "generalization-faceted", "groove_wall_deg": 0.0})
    'faceted'
    >>> world_of({"relief_file": "al3d-1.al3d"}), world_of({"groove_wall_deg": 0.0})
    ('measured', 'sparse')
    """
    head, _, world = str(params.get("preset", "")).partition("generalization-")
    if not head and world in WORLDS:
        return world
    if params.get("relief_file"):
        return "measured"
    return "sparse" if params.get("groove_wall_deg", 45.0) == 0 else "faceted"


def draw_thickness(rng):
    """1-3 populations, means in 20-260 nm, ≥ 12 nm and ≥ 4 SD apart; weights ≥ 0.15."""
    k = int(rng.integers(1, 4))
    sds = rng.uniform(0.5, 3.0, k)
    means = []
    while len(means) < k:
        m = float(rng.uniform(20.0, 260.0))
        if all(abs(m - o) >= max(12.0, 4 * max(sds)) for o in means):
            means.append(m)
    w = rng.dirichlet([2.0] * k)
    w = np.maximum(w, 0.15) / np.maximum(w, 0.15).sum()
    return tuple(ThicknessComponent(float(a), m, float(s))
                 for a, m, s in sorted(zip(w, means, sds), key=lambda c: c[1]))


def draw_lobes(rng):
    """One lobe of 2-14°, or two whose widths differ by ≥ 2× (2-7° and up to 14°)."""
    if rng.random() < 0.5:
        return (TiltLobe(1.0, _lu(rng, 2.0, 14.0)),)
    a = _lu(rng, 2.0, 7.0)
    b = min(14.0, a * float(rng.uniform(2.0, 4.0)))
    w = float(rng.uniform(0.3, 0.7))
    return (TiltLobe(w, a), TiltLobe(1.0 - w, b))


def draw_scene(i, *, seed, size, slices):
    """Scene ``i``: its name, parameters and the variations switched on (the world is
    :func:`world_of` the parameters)."""
    rng = np.random.default_rng([seed, i])
    on = [name for name in VARIATIONS if name not in WORLD_STREAM_VARIATIONS
          and rng.random() < P_ON]
    kw = dict(height_px=size[0], width_px=size[1], n_slices=slices, seed=seed * 1000 + i,
              facet_size_um=_lu(rng, 1.2, 3.5), tilt_lobes=draw_lobes(rng),
              waviness_amplitude_um=_lu(rng, 0.2, 1.5),
              waviness_wavelength_um=float(rng.uniform(30, 80)),
              thickness=draw_thickness(rng), region_size_um=_lu(rng, 10, 25),
              thickness_fine_sd_nm=float(rng.uniform(0.1, 0.5)),
              thickness_facet_sd_nm=0.0 if rng.random() < 0.5 else float(rng.uniform(0.3, 1.5)),
              groove_wall_deg=float(rng.uniform(35, 60)),
              exposure=float(rng.uniform(0.75, 1.15)), full_well_e=_lu(rng, 300, 20000),
              read_noise=_lu(rng, 0.001, 0.01), rolling_direction_deg=float(rng.uniform(0, 180)),
              bit_depth=16 if rng.random() < 0.15 else 8, preset="generalization")
    for name in on:
        kw.update(VARIATIONS[name](rng))
    wrng = np.random.default_rng([seed, i, 1])
    world, wkw = draw_world(wrng)
    for name in WORLD_STREAM_VARIATIONS:
        if wrng.random() < P_ON:
            on.append(name)
            kw.update(VARIATIONS[name](wrng))
    kw.update(wkw, preset=f"generalization-{world}")
    if world == "measured":
        on = [v for v in on if v not in NOT_MEASURED]
    if world == "sparse":
        on = [v for v in on if v != "no_grooves"]
        on += [v for v, key in (("pits", "pit_density_per_mm2"),
                                ("scratches", "scratch_density_per_mm2"))
               if key in wkw and v not in on]
    if "jpeg" in on:
        kw["bit_depth"] = 8
    p = SynthParams(**kw)
    p.validate()
    return f"g{i:03d}", p, on


def noise_pct(p) -> float:
    """Relative sensor noise (%) at a linear signal of 0.3."""
    var = (SIGNAL / p.full_well_e if p.full_well_e else 0.0) + p.read_noise ** 2
    return 100.0 * math.sqrt(var) / SIGNAL


def generate(plan, work: Path, modes):
    """Write every stack not already there with the same parameters; returns
    ``{name: (seconds, reason or "")}``. A regenerated stack's old results are removed."""
    from microfacet.forward.synth import generate_stack

    out = {}
    for name, p, _ in plan:
        folder = work / "stacks" / name
        meta = folder / "truth" / "params.json"
        want = json.loads(json.dumps(p.to_json()))
        if meta.is_file() and json.loads(meta.read_text()).get("params") == want:
            out[name] = (math.nan, "")
            continue
        for mode in modes:
            shutil.rmtree(work / "results" / mode / name, ignore_errors=True)
        t0 = time.perf_counter()
        try:
            generate_stack(folder, p, overwrite=True)
            out[name] = (time.perf_counter() - t0, "")
        except Exception as exc:  # recorded, the sweep goes on
            out[name] = (time.perf_counter() - t0, f"generation: {type(exc).__name__}: {exc}")
        note(f"  {name}: generated in {out[name][0]:.1f} s {out[name][1]}")
    return out


def score_scene(results: Path, truth: Path, res=None) -> dict:
    """Scores of one results folder against its truth (see :mod:`pipelines._scoring`);
    ``res``: the folder already opened (:class:`~microfacet.io.results.Results`)."""
    from microfacet.io.images import read_png
    from microfacet.io.results import Results
    from pipelines._scoring import (
        colour_floor_de,
        facet_tilts,
        height_coverage,
        lobe_rms_ratio,
        mean_coverage,
        ndf_identified,
        ndf_w1_deg,
        order_off_fraction,
        past_limit_fraction,
        region_thickness_errors,
        true_population_count,
    )

    meta = json.loads((truth / "params.json").read_text())
    res = Results(results) if res is None else res
    est = res.map("thickness_nm")
    region_id, region_nm = (np.load(truth / "region_id.npy"),
                            [r["mean_thickness_nm"] for r in meta["regions"]])
    reg = region_thickness_errors(est, region_id, region_nm)
    thick, ndf = res.thickness_mixture(), res.ndf_mixture()
    lobes = list(ndf.components) if ndf else []
    truth_img = read_png(truth / "all_in_focus.png")
    mask = res.map("mask")
    used = ~mask if mask is not None else np.ones(est.shape, bool)
    floor = colour_floor_de(res.image("all_in_focus"), truth_img, used)
    de = res.get("delta_e", "mean")
    comps = res.get("thickness", "mixture", "components") or []
    unc = res.get("thickness", "mixture", "mean_uncertainty") or []
    cov = mean_coverage(comps, unc, meta["populations"])
    samp = mean_coverage(comps, [{"sigma_nm": u.get("sampling_nm")} for u in unc],
                         meta["populations"])
    wb_parts = [u["white_balance_nm"] for u in unc if u.get("white_balance_nm") is not None]
    return {"region_mae_nm": reg["mae_nm"], "region_median_ae_nm": reg["median_ae_nm"],
            "order_off_fraction": order_off_fraction(est, region_id, region_nm),
            "mean_pairs": cov["pairs"], "mean_within_2sigma": cov["within_2sigma"],
            "mean_within_2sigma_sampling": samp["within_2sigma"],
            "mean_wb_part_nm": float(np.median(wb_parts)) if wb_parts else math.nan,
            "mean_abs_error_nm": (float(np.median(np.abs(cov["errors_nm"])))
                                  if cov["pairs"] else math.nan),
            "mean_sigma_nm": (float(np.median([s for s in cov["sigmas_nm"] if s is not None]))
                              if any(s is not None for s in cov["sigmas_nm"]) else math.nan),
            "regions_scored": reg["n_scored"], "regions_true": reg["n_regions"],
            "pops_true": true_population_count(meta["populations"]),
            "pops_found": len(thick.components) if thick else 0,
            "pops_distinct": res.get("thickness", "mixture", "distinct_populations"),
            "pops_candidates": sum(1 for c in (res.get("thickness", "mixture", "candidates")
                                               or []) if c.get("reported")),
            "lobes_true": len(meta["lobes"]), "lobes_found": len(lobes),
            "identified": ndf_identified(res.summary),
            "ndf_w1_deg": ndf_w1_deg(lobes, np.load(truth / "tilt_deg.npy"),
                                     meta["visibility_limit_deg"]),
            "lobe_rms_ratio": lobe_rms_ratio(lobes, facet_tilts(truth),
                                             meta["visibility_limit_deg"]),
            "censored_fraction": (res.summary.get("ndf") or {}).get("mixture", {}).get(
                "censored_fraction") if ndf else None,
            "past_limit_fraction": past_limit_fraction(truth, meta["visibility_limit_deg"]),
            "height_coverage": height_coverage(res.map("height_um"), res.map("height_sigma_um"),
                                               truth) if res.map("height_sigma_um") is not None
            else None,
            "de_mean": de, "de_floor": floor,
            "de_excess": de - floor if de is not None else math.nan,
            "masked_fraction": res.get("masked_fraction"),
            "order_wrong": bool(np.isfinite(reg["median_ae_nm"])
                                and reg["median_ae_nm"] > WRONG_ORDER_NM),
            "order_flagged": order_flagged(res.summary),
            "exposure_error": (res.get("exposure") / meta["params"]["exposure"] - 1.0
                               if res.summary.get("exposure_source") == "estimated"
                               else math.nan),
            "exposure_ambiguous": bool((res.get("exposure_readings") or {}).get("ambiguous")),
            **white_balance_errors(res.summary.get("white_balance"),
                                   meta["params"].get("white_balance_gains", (1, 1, 1)))}


#: A scene is read in a wrong interference order when the median error of its true regions'
#: thicknesses exceeds this (the orders are ~110 nm apart; populations ≥ 12 nm).
WRONG_ORDER_NM = 20.0


def order_flagged(summary) -> bool:
    """The analysis said the interference order is not established (summary.json
    ``thickness.order``: an ambiguous ROI, ≥ 5 % of the facets' area with a runner-up order,
    colours the film model does not explain, or the thickness not identified)."""
    order = (summary.get("thickness") or {}).get("order") or {}
    return order.get("established") is False


def white_balance_errors(wb, true_gains) -> dict:
    """The estimated R and B gains' relative errors against the truth's (G-normalised),
    each where the analysis says it is determined (NaN elsewhere)."""
    out = {"wb_err_r": math.nan, "wb_err_b": math.nan, "wb_true_r": math.nan,
           "wb_true_b": math.nan}
    g = np.asarray(true_gains, float) / float(true_gains[1])
    out["wb_true_r"], out["wb_true_b"] = float(g[0]), float(g[2])
    if not wb or not wb.get("estimate_rgb"):
        return out
    est, det = wb["estimate_rgb"], wb.get("determined_rb") or (False, False)
    for k, (i, ok) in zip(("wb_err_r", "wb_err_b"), ((0, det[0]), (2, det[1]))):
        if ok:
            out[k] = float(est[i] / g[i] - 1.0)
    return out


def scene_row(name, p, on, truth: Path) -> dict:
    """What a scene is, before any analysis (texture from its noise-free truth image)."""
    import cv2

    from pipelines._scoring import texture_codes

    row = {"name": name, "seed": p.seed, "world": world_of(p.to_json()),
           "relief_file": p.to_json()["relief_file"] or "",
           "variations": " ".join(on) or "-",
           "noise_pct": noise_pct(p), "film": p.film, "substrate": p.substrate,
           "exposure": p.exposure, "bit_depth": p.bit_depth,
           "thickness_means_nm": " ".join(f"{c.mean_nm:.0f}" for c in p.thickness),
           "thickness_span_nm": max(c.mean_nm for c in p.thickness)
           - min(c.mean_nm for c in p.thickness),
           "lobes_deg": " ".join(f"{lb.sd_deg:.1f}" for lb in p.tilt_lobes),
           **{f"v_{v}": int(v in on) for v in VARIATIONS}}
    img = cv2.imread(str(truth / "all_in_focus.png"))
    if img is not None:
        row["texture_codes"] = texture_codes(img)
        row["textured"] = row["texture_codes"] >= 2.0
        row["groove_fraction"] = json.loads((truth / "params.json").read_text())[
            "groove_fraction"]
    return row


#: The native oxide of the sweep's bare-substrate references (nm): drawn uniform in this
#: range, about the analysis' assumed 3 nm (``optics.substrate_oxide_nm``).
REFERENCE_OXIDE_NM = (2.0, 5.0)


def _link_or_copy(a, b):
    try:
        os.link(a, b)
    except OSError:
        shutil.copy2(a, b)


@functools.lru_cache(maxsize=None)
def _bare_table(film, substrate, illuminant):
    """The forward model's colour table of thin films on ``substrate`` (0-10 nm, normal
    incidence), once per optical-constant set: building one takes about a second."""
    from microfacet.colour.table import build_colour_table
    return build_colour_table(thickness_range_nm=(0.0, 10.0), theta_range_deg=(0.0, 1.0),
                              film=film, substrate=substrate, illuminant=illuminant)


def substrate_session(work: Path, name: str, p, seed: int) -> Path:
    """``work/stacks-substrate/NAME``: the stack (its slices linked) with a 64 px
    field of the bare substrate, its native oxide drawn in :data:`REFERENCE_OXIDE_NM`,
    through the scene's camera (white balance, noise, 8-bit sRGB; the scene's exposure, or
    less where that would clip) named by stack.json's ``substrate_reference``."""
    from microfacet.colour.transfer import srgb_encode
    from microfacet.forward.synth import apply_sensor
    from microfacet.io.images import write_image

    src, dst = work / "stacks" / name, work / "stacks-substrate" / name
    shutil.rmtree(dst, ignore_errors=True)
    # hard links where the file system has them (a symlinked folder escapes the stack's)
    shutil.copytree(src / "slices", dst / "slices", copy_function=_link_or_copy)
    rng = np.random.default_rng([seed, 23])
    oxide = float(rng.uniform(*REFERENCE_OXIDE_NM))
    rgb = (_bare_table(p.film, p.substrate, p.illuminant).linear_rgb_at(0.0, oxide)
           * np.asarray(p.white_balance_gains))
    rgb = rgb * min(p.exposure, 0.85 / float(np.max(rgb)))   # exposed not to clip
    img = apply_sensor(np.broadcast_to(rgb, (64, 64, 3)).astype(np.float32), p, rng)
    write_image(dst / "substrate.png", srgb_encode(img, dtype=np.uint8))
    meta = json.loads((src / "stack.json").read_text())
    (dst / "stack.json").write_text(json.dumps({**meta, "substrate_reference": "substrate.png"}))
    (dst / "reference.json").write_text(json.dumps({"native_oxide_nm": oxide}))
    return dst


def analysis_changes(text: str) -> dict:
    """``{section: {key: value}}`` of the study's ``analysis`` option (``SECTION.KEY=VALUE``
    joined by ';'; values read as JSON where they parse, else as text).

    >>> analysis_changes("joint.unmix_heights=true; fits.self_check_sigmas=0.5")
    {'joint': {'unmix_heights': True}, 'fits': {'self_check_sigmas': 0.5}}
    """
    out: dict = {}
    for item in filter(None, (t.strip() for t in text.split(";"))):
        key, eq, value = item.partition("=")
        section, dot, name = key.strip().partition(".")
        if not (eq and dot and section and name):
            raise SystemExit(f"accuracy-sweep: analysis: SECTION.KEY=VALUE, got {item!r}")
        try:
            value = json.loads(value)
        except json.JSONDecodeError:
            value = value.strip()
        out.setdefault(section, {})[name.strip()] = value
    return out


def run_mode(mode, plan, gen, work: Path, jobs, scheduler, reference="none", analysis=""):
    """Analyse the generated stacks in ``mode`` (with ``reference = "substrate"``, each with
    a bare-substrate field: :func:`substrate_session`; with ``analysis``, the options of
    :func:`analysis_changes` over the defaults) and score them: one row per scene."""
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.workflow.batch import run_batch

    todo = [name for name, _, _ in plan if not gen[name][1]]
    params = {name: p for name, p, _ in plan}
    stacks = [work / "stacks" / name if reference == "none"
              else substrate_session(work, name, params[name], i)
              for i, name in enumerate(todo)]
    brows = {}
    if stacks:
        try:
            res = run_batch(stacks, work / "results" / (mode if reference == "none"
                                                         else f"{mode}-{reference}"),
                            jobs=jobs or None,
                            scheduler=scheduler or None,
                            options=AnalysisOptions(mode=mode).replace(
                                optics={"white_balance": "report"}).replace(
                                **analysis_changes(analysis)), report=False)
            brows = dict(zip(todo, res.rows))
        except Exception as exc:  # the whole batch refused: every scene failed
            brows = {n: {"status": "failed", "reason": f"batch: {exc}"} for n in todo}
    rows = []
    for name, p, on in plan:
        truth = work / "stacks" / name / "truth"
        row = {"mode": mode, "gen_s": gen[name][0], **scene_row(name, p, on, truth)}
        b = brows.get(name, {"status": "failed", "reason": gen[name][1]})
        row.update(status="done" if b["status"] in ("done", "skipped") else "failed",
                   reason=b.get("reason", ""), analysis_s=b.get("time_s"))
        if row["status"] == "done":
            try:
                row.update(score_scene(Path(b["results"]), truth))
            except Exception as exc:  # recorded as a failed scene
                row.update(status="failed", reason=f"scoring: {type(exc).__name__}: {exc}")
        rows.append(row)
    return rows


COLUMNS = ["name", "mode", "seed", "world", "relief_file", "status", "reason", "gen_s",
           "analysis_s", "variations", "exposure", "bit_depth",
           "textured", "texture_codes", "groove_fraction", "noise_pct", "film", "substrate",
           "thickness_means_nm", "thickness_span_nm", "lobes_deg", "region_mae_nm",
           "region_median_ae_nm", "order_off_fraction", "regions_scored", "regions_true",
           "pops_found", "pops_distinct", "pops_candidates",
           "pops_true", "mean_pairs", "mean_within_2sigma", "mean_within_2sigma_sampling",
           "mean_abs_error_nm", "mean_sigma_nm", "mean_wb_part_nm",
           "lobes_found", "lobes_true", "identified", "ndf_w1_deg", "lobe_rms_ratio",
           "censored_fraction", "past_limit_fraction", "height_coverage", "de_mean", "de_floor",
           "de_excess", "masked_fraction", "order_wrong", "order_flagged", "exposure_error",
           "exposure_ambiguous", "wb_true_r",
           "wb_true_b", "wb_err_r", "wb_err_b"] + [f"v_{v}" for v in VARIATIONS]


def per_scene_table(rows) -> str:
    def f(r, k):
        v = r.get(k)
        return "–" if v is None else fmt(v) if isinstance(v, float) else str(v)

    return md_table(
        ["scene", "mode", "world", "variations", "textured", "status", "time (s)",
         "region MAE (nm)", "populations found/true", "lobes found/true", "identified",
         "NDF W1 (°)", "ΔE00", "floor", "ΔE00 − floor"],
        [[r["name"], r["mode"], r.get("world", "–"), r["variations"],
          "yes" if r.get("textured") else "no",
          r["status"] if r["status"] == "done" else f"failed: {r['reason'][:60]}",
          f(r, "analysis_s"), f(r, "region_mae_nm"),
          f"{f(r, 'pops_found')}/{f(r, 'pops_true')}",
          f"{f(r, 'lobes_found')}/{f(r, 'lobes_true')}",
          {True: "yes", False: "no"}.get(r.get("identified"), "–"), f(r, "ndf_w1_deg"),
          f(r, "de_mean"), f(r, "de_floor"), f(r, "de_excess")] for r in rows])


def summary_table(summaries) -> str:
    """Markdown: the issue's targets beside each mode's scores (✓ / ✗ where a target)."""
    from pipelines._scoring import TARGETS

    modes = list(summaries)
    body = [["scenes (failed; textured)", "–"]
            + [f"{s['scenes']} ({s['failed']}; {s['textured']})" for s in summaries.values()]]
    for label, key, target, ok in TARGETS:
        cells = []
        for s in summaries.values():
            v = s[key]
            txt = ("n/a" if not np.isfinite(v) else f"{100 * v:.0f} %" if "%" in target
                   or key.endswith(("_ok", "_all", "_textured", "_candidates", "_distinct",
                                    "_2sigma"))
                   else str(v) if isinstance(v, int) else fmt(v))
            if ok is not None and np.isfinite(v):
                txt += " ✓" if ok(v) else " ✗"
            cells.append(txt)
        body.append([label, target] + cells)
    return md_table(["score", "target"] + modes, body)


#: The camera variations of the per-variation table: label → test of a row (None: off).
CAMERA_VARIATIONS = {
    "JPEG slices (quality 70-95)": lambda r: truthy(r.get("v_jpeg")),
    "16-bit slices": lambda r: "16" in str(r.get("bit_depth", "")),
    "white-balance error": lambda r: truthy(r.get("v_white_balance")),
    "exposure < 0.9": lambda r: row_number(r.get("exposure")) < 0.9,
    "vignetting (10-50 % lost at the corners)": lambda r: truthy(r.get("v_vignetting")),
}


def variation_table(rows) -> str:
    """Markdown: per camera variation (on / off), the scenes, the fraction with the true
    population count (and counting order aliases with their component and reported
    candidates as populations), the median region MAE, the wrong-order scenes the
    analysis says are established and the fraction with the exposure within 5 %, for each
    mode."""
    from pipelines._scoring import summarize

    body = []
    for mode in sorted({r["mode"] for r in rows}):
        done = [r for r in rows if r["mode"] == mode]
        for label, test in CAMERA_VARIATIONS.items():
            for on in (True, False):
                sel = [r for r in done if bool(test(r)) == on]
                if not sel:
                    continue
                s = summarize(sel)
                body.append([mode, label, "on" if on else "off", str(len(sel)),
                             f"{100 * s['populations_ok']:.0f} %",
                             f"{100 * s['populations_ok_candidates']:.0f} %",
                             fmt(s["region_mae_median_nm"]),
                             f"{s['order_wrong_unflagged']} of {s['order_wrong_count']}",
                             "n/a" if not math.isfinite(s["exposure_ok"])
                             else f"{100 * s['exposure_ok']:.0f} %"])
    return md_table(["mode", "variation", "", "scenes", "populations right",
                     "… with aliases and candidates", "region MAE (nm)",
                     "wrong order, said established", "exposure within 5 %"], body)


def plot(rows, path: Path) -> None:
    """Per variation: the median score (the fraction for populations) of the scenes with it
    on (filled) and off (open)."""
    plt = pyplot()
    metrics = (("region_mae_nm", "region thickness MAE (nm)", True),
               ("ndf_w1_deg", "NDF W1 (°)", True),
               ("de_excess", "ΔE00 − noise floor", False),
               ("pops_ok", "fraction with populations\nfound = true", False))
    for r in rows:
        r["pops_ok"] = float(r.get("pops_found") == r.get("pops_true")) \
            if r["status"] == "done" else math.nan
    modes = sorted({r["mode"] for r in rows})
    names = list(VARIATIONS)
    fig, axes = plt.subplots(len(metrics), 1, figsize=(10, 10), sharex=True)
    for ax, (key, label, logy) in zip(axes, metrics):
        for j, mode in enumerate(modes):
            done = [r for r in rows if r["mode"] == mode and r["status"] == "done"]
            for on, style in ((1, dict(marker="o")), (0, dict(marker="o", mfc="none"))):
                y = []
                for v in names:
                    vals = [r[key] for r in done if r[f"v_{v}"] == on and r.get(key) is not None
                            and np.isfinite(r[key])]
                    agg = np.mean if key == "pops_ok" else np.median
                    y.append(agg(vals) if vals else np.nan)
                ax.plot(np.arange(len(names)) + 0.15 * (j - 0.5), y, ls="none",
                        color=f"C{j}", label=f"{mode}, {'on' if on else 'off'}", **style)
        if logy:
            ax.set_yscale("log")
        ax.set_ylabel(label)
        ax.grid(True, alpha=0.3)
    axes[0].legend(fontsize=8, ncol=2 * len(modes))
    axes[-1].set_xticks(np.arange(len(names)), names, rotation=40, ha="right")
    fig.suptitle(f"Generalization sweep: {len({r['name'] for r in rows})} scenes, median score "
                 "with each variation on (filled) and off (open)")
    fig.tight_layout()
    save_figure(fig, path)


def sweep(*, n, seed, size, slices, modes, jobs, scheduler, work: Path, reference="none",
          analysis=""):
    """Draw, generate, analyse and score the scenes: ``(rows, summaries, header)``."""
    from pipelines._scoring import summarize

    plan = [draw_scene(i, seed=seed, size=size, slices=slices) for i in range(n)]
    t0 = time.perf_counter()
    gen = generate(plan, work, modes)
    t_gen = time.perf_counter() - t0
    rows, summaries, t_an = [], {}, {}
    for mode in modes:
        t1 = time.perf_counter()
        mrows = run_mode(mode, plan, gen, work, jobs, scheduler, reference, analysis)
        t_an[mode] = time.perf_counter() - t1
        rows += mrows
        summaries[mode] = summarize(mrows)
        for world in WORLDS:
            wrows = [r for r in mrows if r.get("world") == world]
            if wrows:
                summaries[f"{mode} · {world}"] = summarize(wrows)
    per = [r.get("analysis_s") for r in rows if r.get("analysis_s") is not None]
    worlds = [world_of(p.to_json()) for _, p, _ in plan]
    header = (f"{n} scenes of {size[0]}×{size[1]} px × {slices} slices (seed "
              f"{seed}; worlds: " + ", ".join(f"{w} {worlds.count(w)}" for w in WORLDS)
              + f"), each variation on with probability {P_ON}; generation "
              f"{t_gen:.0f} s; analysis "
              + ", ".join(f"{m} {t:.0f} s" for m, t in t_an.items())
              + f" (batch, jobs={jobs or 'auto'}); analysis per scene: median "
              f"{np.median(per) if per else math.nan:.1f} s, max "
              f"{max(per) if per else math.nan:.1f} s.")
    return rows, summaries, header


def run(*, quick: bool, out: Path, n=30, seed=0, size="256x256", slices=16, mode="both",
        jobs=0, scheduler="", work="", reference="none", analysis="") -> str:
    hw = tuple(int(v) for v in size.lower().split("x"))
    if quick:
        n, hw, slices, jobs = min(n, 2), (64, 64), min(slices, 6), jobs or 1
    modes = ["joint", "seed"] if mode == "both" else [mode]
    work = Path(work) if work else out / "work"
    if reference not in ("none", "substrate"):
        raise SystemExit(f"accuracy-sweep: reference: none or substrate, got {reference!r}")
    from microfacet.analysis.options import AnalysisOptions
    from microfacet.core.errors import InputError
    try:                                   # refuse a misspelt option before any work
        AnalysisOptions().replace(**analysis_changes(analysis))
    except InputError as exc:
        raise SystemExit(f"accuracy-sweep: analysis: {exc}") from None
    rows, summaries, header = sweep(n=n, seed=seed, size=hw, slices=slices, modes=modes,
                                    jobs=jobs, scheduler=scheduler, work=work,
                                    reference=reference, analysis=analysis)
    csv_path = write_csv(out / "generalization.csv", rows, COLUMNS)
    plot(rows, out / "generalization.png")
    note("\n" + per_scene_table(rows) + "\n")
    note(f"{header}\nper-scene rows: {csv_path}; plot: {out / 'generalization.png'}")
    return (summary_table(summaries) + "\n\nPer camera variation (scenes with it on and "
            "off):\n\n" + variation_table(rows))
