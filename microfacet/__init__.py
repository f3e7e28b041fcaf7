"""microfacet: thickness and microfacet-normal distributions of anodized titanium.

From optical-microscope focus stacks of anodized titanium, microfacet estimates the
oxide-film thickness distribution and the microfacet normal distribution (NDF), and
predicts the thin-film interference colour for any light and view direction
(Nagata et al., "Simulation Technology for Titanium Oxide Layer Interference Color").

The entry points below are documented in docs/api.md; they load on first use, so
``import microfacet`` is light. Everything else lives in the subpackages (one per stage:
docs/architecture.md).

=======================  ==============================================================
name                     what it is
=======================  ==============================================================
``analyse_stack``        the whole analysis of a focus stack → an ``AnalysisResult``
``AnalysisOptions``      its options: one typed tree, a section per stage
``write_results``        an analysis → a results folder (docs/results-format.md)
``Results``              a results folder, opened (its summary validated)
``write_report``         a results folder → report.pdf
``analyse_to_folder``    stack → results folder + report, atomically (``microfacet analyze``)
``height_to_folder``     stack → height map folder (``microfacet height``)
``simulate_to_folder``   distributions → angular colour maps (``microfacet simulate``)
``run_batch``            many stacks, in parallel or on a Dask cluster
``reflectance``          Airy reflectance of ambient / film / substrate (seed eqs. 2-4)
``optical_constants``    the bundled optical-constant sets, n + ik
``build_colour_table``   the film's colour over (tilt, thickness)
``FilmColourModel``      the film's colour as a microscope sees it, and ΔE to an image
``delta_e``              CIEDE2000 / CIE94 / CIE76
``ThicknessMixture``     the thickness distribution (Gaussian mixture, nm)
``NDFMixture``           the normal distribution (zero-mean Gaussian-slope lobes)
``microfacet_brdf``      the thin-film microfacet BRDF of the two distributions
``generate_stack``       a synthetic focus stack with its ground truth
``InputError``           what every user error raises (it names the file, key or option)
=======================  ==============================================================
"""

__version__ = "0.1.0"

from .core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
__all__ = ["__version__", *__all__]
