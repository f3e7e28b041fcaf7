"""The synthetic scene (microfacet.forward.scene): thickness regions follow the mixture,
facet tilts the lobes and the acceptance angle."""

import numpy as np

from microfacet.forward.scene import render_scene
from microfacet.forward.synth import preset


def test_thickness_regions_follow_the_mixture_and_tilts_the_lobes():
    p = preset("nd", seed=2, height_px=512, width_px=512)
    s = render_scene(p)
    means = np.array([c.mean_nm for c in p.thickness])
    comp_of_region = s.region_component
    # Each region's thickness lies within 4 SD of its component mean.
    sd = np.array([c.sd_nm for c in p.thickness])[comp_of_region]
    assert np.all(np.abs(s.region_thickness_nm - means[comp_of_region]) < 4 * sd + 1e-9)
    # The steepest visible facets are below the NA limit; beyond it pixels are marked dark.
    assert s.tilt_deg[s.visible].max() <= p.max_tilt_deg
    assert not s.visible[s.tilt_deg > p.max_tilt_deg].any()
