"""microfacet: thickness and microfacet-normal distributions of anodized titanium.

From optical-microscope focus stacks of anodized titanium, microfacet estimates the
oxide-film thickness distribution and the microfacet normal distribution (NDF), and
predicts the thin-film interference colour for any light and view direction
(Nagata et al., "Simulation Technology for Titanium Oxide Layer Interference Color").

The package import is light: subpackages (``microfacet.optics``, ``microfacet.colour``,
``microfacet.optics`` ...) are imported on demand.
"""

__version__ = "0.1.0"

__all__ = ["__version__"]
