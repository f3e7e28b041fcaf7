"""The angular-map file (format ``microfacet-angular/1``): the one module that writes and
reads it, and its PNG picture.

    One NumPy ``.npz`` with

================  ==============  ====================================================
key               shape / type    meaning
================  ==============  ====================================================
format            str             ``"microfacet-angular/1"``
theta_light_deg   (L,) float      light zenith angles, degrees, −90 < θ < 90
theta_view_deg    (V,) float      view zenith angles, positive on the mirror side
lab               (L, V, 3)       CIELAB; required unless ``spectra`` is given
spectra           (L, V, N)       reflectance factor (1 = white diffuser), optional
wavelength_nm     (N,)            required with ``spectra``
illuminant        str             default ``"D65"`` (for Lab from spectra)
observer          str             ``"2"`` or ``"10"``, default ``"2"``
================  ==============  ====================================================

If both ``lab`` and ``spectra`` are present, ``lab`` is used for comparisons. NaN
marks cells not measured. ``xyz`` and ``srgb`` may also be stored (ignored on read).
"""

from __future__ import annotations

import zipfile

import numpy as np

from ..colour.colorimetry import lab_to_xyz, white_xyz
from ..colour.srgb import colours_from_spectra, model_xyz_to_linear_srgb, srgb_encode
from ..core.angular import AngularMap
from ..core.errors import InputError, one_line
from .images import write_image

__all__ = ["MAP_FORMAT", "lab_to_display_srgb", "load_map", "save_map", "save_png"]

MAP_FORMAT = "microfacet-angular/1"


def lab_to_display_srgb(lab, illuminant="D65", observer="2"):
    """uint8 sRGB of CIELAB relative to the perfect white diffuser (NaN shown black)."""
    xyz = lab_to_xyz(np.nan_to_num(np.asarray(lab, np.float64)),
                           white=white_xyz(illuminant=illuminant, observer=observer))
    rgb = model_xyz_to_linear_srgb(xyz, white=white_xyz(illuminant=illuminant,
                                                                    observer=observer),
                                         illuminant=illuminant, observer=observer)
    return srgb_encode(rgb, dtype=np.uint8)


def check_angles(x, name):
    """A non-empty 1-D array of finite angles in (-90, 90) degrees; ValueError names ``name``."""
    a = np.atleast_1d(np.asarray(x, dtype=np.float64))
    if a.ndim != 1 or a.size == 0:
        raise ValueError(f"{name}: expected a non-empty 1-D array of angles")
    if not np.all(np.isfinite(a)) or np.any(np.abs(a) >= 90):
        raise ValueError(f"{name}: angles must be finite and in (-90, 90) degrees")
    return a


def save_map(path, m: AngularMap):
    """Write ``m`` in the ``microfacet-angular/1`` .npz format (see the module docstring)."""
    data = {"format": np.array(MAP_FORMAT), "theta_light_deg": m.theta_light_deg,
            "theta_view_deg": m.theta_view_deg, "lab": np.asarray(m.lab, np.float32),
            "illuminant": np.array(m.illuminant), "observer": np.array(str(m.observer))}
    if m.spectra is not None:
        data["spectra"] = np.asarray(m.spectra, np.float32)
        data["wavelength_nm"] = np.asarray(m.wavelength_nm, np.float64)
    if m.xyz is not None:
        data["xyz"] = np.asarray(m.xyz, np.float32)
    with open(path, "wb") as fh:
        np.savez_compressed(fh, **data)


def load_map(path) -> AngularMap:
    """Read a ``microfacet-angular/1`` map (.npz); Lab from spectra if no ``lab`` key.

    Raises
    ------
    InputError
        Naming the file and the missing or inconsistent key.
    """
    try:
        z = np.load(path, allow_pickle=False)
    except FileNotFoundError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"{one_line(path)}: not a readable .npz angular map ({exc})") from None
    with z:
        keys = set(z.files)
        fmt = str(z["format"]) if "format" in keys else MAP_FORMAT
        if fmt != MAP_FORMAT:
            raise InputError(f"{one_line(path)}: format {fmt!r}, expected {MAP_FORMAT!r}")
        for k in ("theta_light_deg", "theta_view_deg"):
            if k not in keys:
                raise InputError(f"{one_line(path)}: missing key {k!r}")
        tl = check_angles(z["theta_light_deg"], f"{one_line(path)}: key 'theta_light_deg'")
        tv = check_angles(z["theta_view_deg"], f"{one_line(path)}: key 'theta_view_deg'")
        ill = str(z["illuminant"]) if "illuminant" in keys else "D65"
        obs = str(z["observer"]) if "observer" in keys else "2"
        spectra = wl = None
        if "spectra" in keys:
            if "wavelength_nm" not in keys:
                raise InputError(f"{one_line(path)}: 'spectra' needs 'wavelength_nm'")
            spectra = np.asarray(z["spectra"], np.float64)
            wl = np.asarray(z["wavelength_nm"], np.float64)
            if spectra.shape != (tl.size, tv.size, wl.size):
                raise InputError(f"{one_line(path)}: spectra shape {spectra.shape}, expected "
                                 f"{(tl.size, tv.size, wl.size)}")
        if "lab" in keys:
            lab = np.asarray(z["lab"], np.float32)
            if lab.shape != (tl.size, tv.size, 3):
                raise InputError(f"{one_line(path)}: lab shape {lab.shape}, expected "
                                 f"{(tl.size, tv.size, 3)}")
            xyz = srgb = None
        elif spectra is not None:
            xyz, lab, srgb, _ = colours_from_spectra(spectra, wl, illuminant=ill, observer=obs)
        else:
            raise InputError(f"{one_line(path)}: needs 'lab' or 'spectra' + 'wavelength_nm'")
    return AngularMap(tl, tv, lab, xyz, srgb, spectra, wl, ill, obs, {"source": str(path)})




def save_png(path, m: AngularMap, *, scale=4):
    """Write the map's sRGB image, each cell ``scale`` × ``scale`` pixels, light angle down."""
    img = m.srgb if m.srgb is not None else lab_to_display_srgb(m.lab, m.illuminant, m.observer)
    write_image(path, np.repeat(np.repeat(img, int(scale), axis=0), int(scale), axis=1))
