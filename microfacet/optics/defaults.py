"""The default optical-constant sets of the film and the substrate (no numpy: the command
line's help shows them).

Defaults
--------
``DEFAULT_FILM = "TiO2_Jolivet2023_amorphous"``
    Anodic TiO2 grown at the voltages that give interference colours (tens of volts) is
    amorphous or at most partly crystalline (Diamanti et al. 2008; structure reviews cited
    in ``docs/optical-constants.md``). Of the measured TiO2 sets only Jolivet et al. (2023)
    state an amorphous phase explicitly; its index (n = 2.45 at 550 nm, k = 0 above 362 nm)
    lies inside the 2.2-2.5 span reported for anodic films, and with it the computed colour
    sequence (gold 20-30 nm, purple ~40 nm, blue ~50 nm, ...) follows the vendor charts.
``DEFAULT_SUBSTRATE = "Ti_JohnsonChristy1974"``
    The standard measured optical constants of titanium. With it the blue of the seed's
    sample 2 falls at ~51 nm, matching the seed's Table 1 estimate (50.8 nm); Palm (2018) is an
    annealed evaporated film with markedly lower n and k, the Rakic sets are model fits.

The illuminant and observer (:data:`DEFAULT_ILLUMINANT`, :data:`DEFAULT_OBSERVER`) are
:mod:`microfacet.core.defaults`' (core code needs them too), named here for convenience.
"""

from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER

__all__ = ["DEFAULT_FILM", "DEFAULT_ILLUMINANT", "DEFAULT_OBSERVER", "DEFAULT_SUBSTRATE"]

DEFAULT_FILM = "TiO2_Jolivet2023_amorphous"
DEFAULT_SUBSTRATE = "Ti_JohnsonChristy1974"
#: Numerical aperture of the objective when ``stack.json`` does not give one.
DEFAULT_NUMERICAL_APERTURE = 0.8
