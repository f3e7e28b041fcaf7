"""Rendering the measured material in Mitsuba 3 (optional extra ``render``; seed §2.6).

==================  ==========================================================
module              concern
==================  ==========================================================
``bsdf``            the thin-film microfacet BSDF as a Mitsuba plugin (spectral variants)
``scene``           the photographic set-up: D65 light, camera, plate / sheet / sphere / mesh
``scene_xml``       a scene dictionary written as self-contained Mitsuba XML
``variants``        which Mitsuba variants work here (LLVM probed in a child process)
==================  ==========================================================

Mitsuba is imported on first use, never by ``import microfacet``.
"""

from ..core.lazy import attach_stub

__getattr__, __dir__, __all__ = attach_stub(__name__, __file__)
