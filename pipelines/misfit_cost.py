"""The cost of the colour rule's misfit at the white-balance estimate
(``analysis.joint.delta_e_rebalanced``), beside ``gain_thickness_shifts`` and the whole
analysis of the same stack, in one process.

    python -m pipelines.misfit_cost STACK [--repeat N]

Prints one line per repeat: the facets, both timings (s) and the analysis' own total
(``timings_s``). Used for docs/accuracy.md ("Misfit that is the camera's, and regions by
their means", issue 23).
"""

from __future__ import annotations

import argparse
import time

from microfacet.analysis import AnalysisOptions, analyse_stack
from microfacet.analysis import joint as J
from microfacet.analysis.planes import facet_edge_distance


def main(stack: str, repeat: int = 2) -> None:
    r = analyse_stack(stack, AnalysisOptions(mode="joint"))
    j, opts, il = r.joint, r.options.joint, r.scene.illuminant
    g = J.FacetGeometry(j.facets, j.planes, j.evidence_planes, j.area_px,
                        facet_edge_distance(j.facets), j.prior_deg, j.prior_sigma_deg,
                        j.dome_ms_slope)
    cols = J.facet_image(g, r.colour, r.roi, opts).colours()
    d = j.thickness.thickness_nm
    for _ in range(repeat):
        t0 = time.perf_counter()
        J.gain_thickness_shifts(cols, d, j.prior_deg, r.model, opts, log_gain_rb=(0.02, 0.02),
                                illuminant=il)
        t1 = time.perf_counter()
        J.delta_e_rebalanced(cols, d, j.prior_deg, r.model, opts, log_gain_rb=(0.05, -0.05),
                             illuminant=il)
        t2 = time.perf_counter()
        print(f"facets {d.size}: gain_thickness_shifts {t1 - t0:.2f} s, delta_e_rebalanced "
              f"{t2 - t1:.2f} s, analysis total {r.timings_s['total']:.2f} s", flush=True)


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("stack")
    p.add_argument("--repeat", type=int, default=2)
    a = p.parse_args()
    main(a.stack, a.repeat)
