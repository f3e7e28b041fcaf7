"""Real instrument height maps through ``microfacet analyze`` (docs/real-data.md).

For each file of fixtures/instrument-heights (an Alicona .al3d, a Sensofar .plu and a
MountainsMap .mnt, measured by real instruments):

1. read it with ``microfacet.io.instruments.read_height_map`` and with SurfaceTopography, and
   compare RMS height and RMS gradient (forward differences over the grid);
2. make a microscope-export stack: ``height_um`` names the instrument file itself (so the
   reader, its units, orientation and pixel size are what the analysis uses; ``stack.json``
   has no ``pixel_size_um``) and ``image`` is the colour a uniform TiO2 film of
   ``--thickness-nm`` shows at each pixel's tilt (the normals of that height map, no noise);
3. run ``microfacet analyze`` on it and report the pixel size it used, the RMS slope of its
   height tilts, the thickness it found and its NDF.

The film colour is synthetic (these instruments image no anodized titanium); the relief,
units, pixel sizes and slopes are the instruments'. The figure (``out/real-instruments.png``;
``--docs`` copies it to docs/img/) shows, per file, the colour image, the height and the
per-pixel tilt histogram with the fitted NDF. The stacks are made in ``out`` (the instrument
file copied into each): the fixtures are only read. Needs the ``instruments`` extra.
"""

from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np

from pipelines import ROOT, Study
from pipelines._shared import md_table, note, pyplot, save_figure

STUDY = Study(
    name="gallery-instruments",
    question="Do real instrument height maps read as SurfaceTopography reads them, and what "
             "does `microfacet analyze` make of them?",
    doc=("docs/real-data.md", "gallery-instruments"),
    run_time="30 s",
    quick_time="10 s",
    options={"thickness_nm": (70.0, "thickness of the synthetic uniform film, nm")},
    doc_files={"real-instruments.png": "docs/img/real-instruments.png"},
)

FILES = ROOT / "fixtures" / "instrument-heights"
NAMES = ("al3d-1.al3d", "plu-1.plu", "mnt-1.mnt")


def rms_gradient(h, pixel_yx):
    """sqrt(mean((∂h/∂x)² + (∂h/∂y)²)), forward differences where both exist."""
    h = np.asarray(h, np.float64)
    dy = np.diff(h, axis=0)[:, :-1] / pixel_yx[0]
    dx = np.diff(h, axis=1)[:-1, :] / pixel_yx[1]
    return float(np.sqrt(np.nanmean(dx ** 2 + dy ** 2)))


def surface_topography_values(path):
    """RMS height (µm) and RMS gradient as SurfaceTopography computes them."""
    from SurfaceTopography import read_topography
    t = read_topography(str(path))
    unit = t.unit
    to_um = {"m": 1e6, "mm": 1e3, "µm": 1.0, "um": 1.0, "nm": 1e-3}[unit]
    return float(t.rms_height_from_area()) * to_um, float(t.rms_gradient())


def colour_image(h, pixel_yx, thickness_nm):
    """8-bit sRGB of a uniform film at each pixel's tilt (normals of the height map)."""
    from microfacet.colour.srgb import srgb_encode
    from microfacet.colour.table import build_colour_table
    from microfacet.focus.normals import normals_from_height, tilt_azimuth_deg

    tilt, _ = tilt_azimuth_deg(normals_from_height(h, pixel_size_um=pixel_yx))
    table = build_colour_table(thickness_range_nm=(thickness_nm - 5, thickness_nm + 5),
                               theta_range_deg=(0.0, 40.0))
    t = np.clip(np.nan_to_num(tilt, nan=0.0), 0.0, 40.0)
    rgb = table.linear_rgb_at(t, np.full(t.shape, thickness_nm))
    rgb = rgb / max(float(np.percentile(rgb, 99.5)), 1e-6) * 0.8
    return srgb_encode(np.clip(rgb, 0, 1), dtype=np.uint8), tilt


def run_one(name, work, thickness_nm):
    from microfacet.cli import main as cli_main
    from microfacet.io.images import write_image
    from microfacet.io.instruments import read_height_map
    from microfacet.io.results import Results

    src = FILES / name
    m = read_height_map(src)
    h = m.height_um.astype(np.float64)
    st_rms, st_grad = surface_topography_values(src)
    ours_rms = float(np.sqrt(np.nanmean((h - np.nanmean(h)) ** 2)))
    ours_grad = rms_gradient(h, m.pixel_size_um)
    img, tilt = colour_image(h, m.pixel_size_um, thickness_nm)
    stack = work / name.replace(".", "_")
    shutil.rmtree(stack, ignore_errors=True)
    stack.mkdir(parents=True)
    shutil.copy(src, stack / name)
    write_image(stack / "image.png", img)
    (stack / "stack.json").write_text(json.dumps({
        "format": "microfacet-stack/1", "height_um": name, "image": "image.png"}))
    out = work / f"{stack.name}-results"
    facet_um = 10 * float(np.sqrt(np.prod(m.pixel_size_um)))  # facets of ~10 pixels
    t0 = time.perf_counter()
    status = cli_main(["analyze", str(stack), "--out", str(out), "-q", "--no-report",
                       "--overwrite",
                       "--facet-size-um", f"{facet_um:.3g}"])
    wall = time.perf_counter() - t0
    res = Results(out)
    s = res.summary
    t_h = res.map("tilt_height_deg")
    slope = np.tan(np.radians(t_h[np.isfinite(t_h)].astype(np.float64)))
    th = res.map("thickness_nm")
    return dict(
        name=name, shape=h.shape, pixel=m.pixel_size_um, source=m.source, status=status,
        wall_s=wall, st_rms=st_rms, ours_rms=ours_rms, st_grad=st_grad, ours_grad=ours_grad,
        used_pixel=s["inputs"]["pixel_size_um"],
        tilt_rms_slope=float(np.sqrt(np.mean(slope ** 2))),
        thickness_median=float(np.nanmedian(th)),
        ndf=s.get("ndf", {}), plane_tilt=s["ndf"].get("mean_plane_tilt_deg"),
        warnings=s.get("warnings", []), img=img, height=h, tilt=tilt, tilt_h=t_h, res=res)


def figure(rows, path):
    plt = pyplot()
    fig, axes = plt.subplots(len(rows), 3, figsize=(11, 3.3 * len(rows)))
    for ax_row, r in zip(np.atleast_2d(axes), rows):
        py, px = r["pixel"]
        H, W = r["shape"]
        ext = (0, W * px, H * py, 0)
        ax_row[0].imshow(r["img"], extent=ext)
        ax_row[0].set_title(f"{r['name']}: film colour at the tilt", fontsize=9)
        hm = ax_row[1].imshow(r["height"], extent=ext, cmap="viridis")
        fig.colorbar(hm, ax=ax_row[1], label="height (µm)", shrink=0.8)
        ax_row[1].set_title(f"height ({r['source']})", fontsize=9)
        for ax in ax_row[:2]:
            ax.set_xlabel("x (µm)")
            ax.set_ylabel("y (µm)")
        t = r["tilt_h"][np.isfinite(r["tilt_h"])]
        hi = max(float(np.percentile(t, 99.5)), 0.5)
        ax_row[2].hist(t, bins=80, range=(0, hi), density=True, color="0.6",
                       label="height tilt per pixel")
        ndf = r["res"].ndf_mixture()
        if ndf is not None and r["ndf"].get("identified", True):
            th = np.linspace(0, hi, 300)
            ax_row[2].plot(th, ndf.tilt_pdf(th), "C3", label="fitted NDF")
        ax_row[2].set_xlabel("tilt (deg)")
        ax_row[2].set_ylabel("density (1/deg)")
        ax_row[2].legend(fontsize=7)
        ax_row[2].set_title("tilt distribution", fontsize=9)
    fig.tight_layout()
    save_figure(fig, path)


def run(*, quick: bool, out: Path, thickness_nm=70.0) -> str:
    names = NAMES[:1] if quick else NAMES
    rows = [run_one(n, out / "stacks", thickness_nm) for n in names]
    table = []
    for r in rows:
        py, px = r["pixel"]
        table.append([
            r["name"], f"{r['shape'][0]} × {r['shape'][1]}", f"{py:.5g} × {px:.5g}",
            f"{r['ours_rms']:.6g} / {r['st_rms']:.6g}",
            f"{r['ours_grad']:.6g} / {r['st_grad']:.6g}",
            f"{r['tilt_rms_slope']:.4g}",
            f"{r['thickness_median']:.1f}",
            f"{r['plane_tilt']:.3g}",
            "; ".join(w.split(":")[0] for w in r["warnings"]) or "—",
            ("identified" if r["ndf"].get("identified") else "not identified: "
             + str(r["ndf"].get("reason", "")))[:70],
            f"{r['wall_s']:.1f}"])
        note(" | ".join(table[-1]))
    figure(rows, out / "real-instruments.png")
    note(f"wrote {out / 'real-instruments.png'}")
    return md_table(
        ["file", "rows × cols", "pixel y × x (µm)", "RMS height µm (ours / ST)",
         "RMS gradient (ours / ST)", "RMS slope of the analysis' height tilts",
         f"thickness median (nm; true {thickness_nm:g})", "mean-plane tilt (deg)",
         "warnings", "NDF", "analyze (s)"], table)
