"""How much of the facets' slopes planes through the focus evidence keep, against the sweep's
true facets: planes through the heights as measured, and unmixed (docs/accuracy.md, "Heights
unmixed at the creases").

    python -m pipelines.facet_gain [--max N] OUT:WORK [OUT:WORK ...]

Each ``OUT:WORK`` is one ``accuracy-sweep --set mode=joint --set work=WORK --out OUT`` run;
of its textured scenes of the faceted world (``OUT/generalization.csv``) the first ``N``
(default 5) are taken. Per scene: the height from focus of ``WORK/stacks/NAME`` with the
default focus options, the evidence window's heights (:func:`~microfacet.analysis.joint.
focus_heights`) on the scene's **true** facets (``truth/facet_id.npy``), planes fitted by
:func:`~microfacet.analysis.planes.fit_facet_planes` and by :func:`~microfacet.analysis.
planes.fit_unmixed_planes` (the dense combined height as the surround), against the planes
of the true heights. Printed: the slope gain (Σ s·s_true / Σ |s_true|² over the facets with
a usable slope, σ below ``MAX_SLOPE_SIGMA``, and a true slope above 0.02) and the RMS of
the x-slope errors in units of their σ, per scene and as medians.
"""

from __future__ import annotations

import csv
import sys
from pathlib import Path

import numpy as np


def facet_gains(stack: Path) -> dict:
    """``{"plain": (gain, z_rms, n), "unmixed": (...)}`` of one stack folder."""
    from microfacet.analysis.joint import focus_heights
    from microfacet.analysis.options import JointOptions
    from microfacet.analysis.planes import MAX_SLOPE_SIGMA, fit_facet_planes, fit_unmixed_planes
    from microfacet.focus.height import height_from_focus
    from microfacet.focus.options import FocusOptions
    from microfacet.io.stack import read_stack

    jo = JointOptions()
    st = read_stack(stack)
    foc = height_from_focus(st, FocusOptions())
    hi = focus_heights(foc, jo)
    true_h = np.load(stack / "truth" / "height_um.npy").astype(np.float64)
    _, lab = np.unique(np.load(stack / "truth" / "facet_id.npy"), return_inverse=True)
    lab = lab.reshape(true_h.shape).astype(np.int32)
    kw = dict(height_sigma_um=hi.sigma_um, reliable=hi.reliable, pixel_size_um=st.pixel_size_um,
              min_pixels=jo.min_plane_pixels, correlation_px=hi.correlation_px)
    true = fit_facet_planes(lab, true_h, height_sigma_um=1.0, reliable=np.ones(lab.shape, bool),
                            pixel_size_um=st.pixel_size_um, min_pixels=3, robust_rounds=0)
    fits = {"plain": fit_facet_planes(lab, hi.height_um, **kw),
            "unmixed": fit_unmixed_planes(lab, hi.height_um, mixing_px=hi.mixing_px,
                                          surround_um=np.asarray(foc.height_fit_um,
                                                                 dtype=np.float64), **kw)[0]}
    tx, ty = true.slope_x, true.slope_y
    out = {}
    for name, q in fits.items():
        ok = (q.fitted & true.fitted & (q.slope_sigma < MAX_SLOPE_SIGMA)
              & (np.hypot(tx, ty) > 0.02))
        gain = float(np.sum(q.slope_x[ok] * tx[ok] + q.slope_y[ok] * ty[ok])
                     / np.sum(tx[ok] ** 2 + ty[ok] ** 2))
        z = (q.slope_x[ok] - tx[ok]) / q.slope_sigma[ok]
        out[name] = (gain, float(np.sqrt(np.mean(z * z))), int(ok.sum()))
    return out


def main(argv=None) -> None:
    args = list(sys.argv[1:] if argv is None else argv)
    most = 5
    if args[:1] == ["--max"]:
        most, args = int(args[1]), args[2:]
    rows = []
    for pair in args:
        out, _, work = pair.partition(":")
        with open(Path(out) / "generalization.csv", newline="") as fh:
            names = [r["name"] for r in csv.DictReader(fh)
                     if r["textured"] == "True" and r["world"] == "faceted"][:most]
        for name in names:
            g = facet_gains(Path(work) / "stacks" / name)
            rows.append(g)
            print(f"{out} {name}: " + " | ".join(
                f"{k} gain {v[0]:.3f}, z RMS {v[1]:.2f} ({v[2]} facets)" for k, v in g.items()),
                flush=True)
    for k in ("plain", "unmixed"):
        print(f"median over {len(rows)} scenes, {k}: gain "
              f"{np.median([r[k][0] for r in rows]):.3f}, z RMS "
              f"{np.median([r[k][1] for r in rows]):.2f}")


if __name__ == "__main__":
    main()
