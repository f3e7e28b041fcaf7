"""The one mechanism for deferred imports: heavy libraries and subpackages load on first use.

``import microfacet`` and ``microfacet --help`` import neither numpy's heavy companions
(colour-science, scikit-learn, scikit-image, matplotlib, OpenCV, SciPy's submodules) nor the
subpackages; a module that needs one names it once, at its top::

    from ..core.lazy import load

    cv2 = load("cv2")                 # imported when cv2.<anything> is first used
    ndimage = load("scipy.ndimage")

and a package exposes its public names without importing its modules, declared in an
``__init__.pyi`` beside its ``__init__.py`` (scikit-image's ``lazy_loader.attach_stub``
pattern: type checkers and IDEs read the stub, the runtime reads the same stub)::

    __getattr__, __dir__, __all__ = attach_stub(__name__, __file__)

numpy is imported normally: it is what every module computes with.

Examples
--------
>>> import sys
>>> m = load("json")          # already imported by the standard library: returned as is
>>> m is sys.modules["json"]
True
>>> proxy = load("this_module_does_not_exist_xyz")
>>> try:
...     proxy.anything
... except ModuleNotFoundError as exc:
...     print(exc.name)
this_module_does_not_exist_xyz
"""

from __future__ import annotations

import importlib
import sys
import types

import lazy_loader

__all__ = ["attach", "attach_stub", "load"]


class _LazyModule(types.ModuleType):
    """A stand-in for a module that imports it on the first attribute access."""

    def __init__(self, name: str, keep: bool = True):
        super().__init__(name)
        self.__dict__["_lazy_target"] = name
        self.__dict__["_lazy_keep"] = keep

    def __getattr__(self, attr):
        module = importlib.import_module(self.__dict__["_lazy_target"])
        value = getattr(module, attr)
        if self.__dict__["_lazy_keep"] and not attr.startswith("__"):
            self.__dict__[attr] = value  # the next access is a plain attribute lookup
        return value

    def __repr__(self):
        return f"<lazy module {self.__dict__['_lazy_target']!r}>"


def load(name: str, *, keep: bool = True) -> types.ModuleType:
    """The module ``name``, imported when one of its attributes is first used.

    Parameters
    ----------
    name : str
        Absolute module name (``"cv2"``, ``"scipy.ndimage"``, ``"sklearn.mixture"``).
    keep : bool
        Keep each attribute once looked up (the next access is a plain lookup). False for a
        module whose attributes change at run time: Mitsuba's ``mi.BSDF``, ``mi.Float`` …
        are those of the variant set when they are looked up.

    Returns
    -------
    module
        The module itself if it is already imported, else a proxy.
    """
    module = sys.modules.get(name)
    return module if module is not None else _LazyModule(name, keep)


def attach(package_name: str, submodules=(), submod_attrs=None):
    """``(__getattr__, __dir__, __all__)`` for a package whose names load on first use.

    Parameters
    ----------
    package_name : str
        The package's ``__name__``.
    submodules : iterable of str
        Submodules reachable as attributes (``microfacet.optics.thinfilm``).
    submod_attrs : dict of str to list of str
        Names exported from each submodule (``{"thinfilm": ["reflectance"]}``).
    """
    return lazy_loader.attach(package_name, submodules=list(submodules),
                              submod_attrs=submod_attrs or {})


def attach_stub(package_name: str, filename: str):
    """``(__getattr__, __dir__, __all__)`` for a package whose public names are the imports of
    the ``.pyi`` stub beside ``filename`` (``from .module import name``), loaded on first use.

    Parameters
    ----------
    package_name : str
        The package's ``__name__``.
    filename : str
        The package's ``__file__``; its ``.pyi`` holds the names.
    """
    return lazy_loader.attach_stub(package_name, filename)
