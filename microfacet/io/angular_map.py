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
illuminant        str             default ``DEFAULT_ILLUMINANT`` (for Lab from spectra)
observer          str             ``"2"`` or ``"10"``, default ``DEFAULT_OBSERVER``
================  ==============  ====================================================

If both ``lab`` and ``spectra`` are present, ``lab`` is used for comparisons. NaN
marks cells not measured. ``xyz`` and ``srgb`` may also be stored (ignored on read).

Reading checks every array's shape and type from its header before any of it is decompressed
(a compressed file of a few kilobytes can claim gigabytes): at most :data:`MAX_ANGLES` angles
per axis, :data:`MAX_WAVELENGTHS` wavelengths, text values of at most
:data:`MAX_TEXT_CHARS` characters, and the memory the spectra need checked against what the
machine has free (:func:`microfacet.io.limits.check_memory`).
"""

from __future__ import annotations

import math
import zipfile

import numpy as np

from ..colour.colorimetry import lab_to_xyz, white_xyz
from ..colour.srgb import colours_from_spectra, model_xyz_to_linear_srgb, srgb_encode
from ..core.angular import AngularMap
from ..core.defaults import DEFAULT_ILLUMINANT, DEFAULT_OBSERVER
from ..core.errors import InputError, one_line
from .images import write_image
from .limits import check_memory

__all__ = ["MAP_FORMAT", "MAX_ANGLES", "MAX_TEXT_CHARS", "MAX_WAVELENGTHS",
           "lab_to_display_srgb", "load_map", "save_map", "save_png"]

MAP_FORMAT = "microfacet-angular/1"
#: Most angles per axis of a map read: one per 0.05° over (−90°, 90°) (goniometers step 1-5°).
MAX_ANGLES = 3600
#: Most wavelengths of a map's spectra: one per 0.1 nm over 380-780 nm.
MAX_WAVELENGTHS = 4001
#: Longest text value (``format``, ``illuminant``, ``observer``).
MAX_TEXT_CHARS = 64
#: Bytes per spectral sample that reading spectra and their colours takes at most.
_SPECTRA_BYTES_PER_SAMPLE = 8 * 6


def lab_to_display_srgb(lab, illuminant=DEFAULT_ILLUMINANT, observer=DEFAULT_OBSERVER):
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


def _header(z, key: str, shown: str):
    """``(shape, dtype)`` of the array ``key`` of the open ``.npz`` ``z``, from its header
    only (nothing is decompressed)."""
    readers = {(1, 0): np.lib.format.read_array_header_1_0,
               (2, 0): np.lib.format.read_array_header_2_0}
    try:
        with z.zip.open(f"{key}.npy") as fh:
            version = np.lib.format.read_magic(fh)
            if version not in readers:
                raise ValueError(f"unsupported .npy version {version}")
            shape, _, dtype = readers[version](fh)
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        raise InputError(f"{shown}: key {key!r}: cannot read ({one_line(exc)})") from None
    return shape, dtype


def _check_headers(z, keys: set, shown: str) -> dict:
    """Every key's shape and type from the headers (see the module notes): ``{key: shape}``
    of the arrays."""
    shapes = {}
    for key in sorted(keys):
        shape, dtype = _header(z, key, shown)
        if key in ("format", "illuminant", "observer"):
            if dtype.kind not in "US" or shape != () or dtype.itemsize > 4 * MAX_TEXT_CHARS:
                raise InputError(f"{shown}: key {key!r}: expected a short text, got {dtype} "
                                 f"of shape {shape}")
            continue
        if dtype.kind not in "biuf":
            raise InputError(f"{shown}: key {key!r}: expected numbers, got dtype {dtype}")
        shapes[key] = tuple(shape)
    for key, most in (("theta_light_deg", MAX_ANGLES), ("theta_view_deg", MAX_ANGLES),
                      ("wavelength_nm", MAX_WAVELENGTHS)):
        shape = shapes.get(key)
        if shape is not None and (len(shape) > 1 or math.prod(shape) > most):
            raise InputError(f"{shown}: key {key!r}: shape {shape}; at most {most:,} values "
                             f"in one dimension")
    return shapes


def _expect_shape(shapes: dict, key: str, want: tuple, shown: str) -> None:
    if key in shapes and shapes[key] != want:
        raise InputError(f"{shown}: {key} shape {shapes[key]}, expected {want}")


def load_map(path) -> AngularMap:
    """Read a ``microfacet-angular/1`` map (.npz); Lab from spectra if no ``lab`` key.

    Raises
    ------
    InputError
        Naming the file and the missing, oversized or inconsistent key.
    """
    shown = one_line(path)
    try:
        z = np.load(path, allow_pickle=False, mmap_mode="r")
    except FileNotFoundError:
        raise
    except (OSError, ValueError, zipfile.BadZipFile) as exc:
        raise InputError(f"{shown}: not a readable .npz angular map ({exc})") from None
    if not isinstance(z, np.lib.npyio.NpzFile):
        raise InputError(f"{shown}: not a readable .npz angular map (a single array, not an "
                         f".npz archive)")
    with z:
        keys = set(z.files)
        shapes = _check_headers(z, keys, shown)
        fmt = str(z["format"]) if "format" in keys else MAP_FORMAT
        if fmt != MAP_FORMAT:
            raise InputError(f"{shown}: format {fmt!r}, expected {MAP_FORMAT!r}")
        for k in ("theta_light_deg", "theta_view_deg"):
            if k not in keys:
                raise InputError(f"{shown}: missing key {k!r}")
        n_l, n_v = math.prod(shapes["theta_light_deg"]), math.prod(shapes["theta_view_deg"])
        _expect_shape(shapes, "lab", (n_l, n_v, 3), shown)
        if "spectra" in keys:
            if "wavelength_nm" not in keys:
                raise InputError(f"{shown}: 'spectra' needs 'wavelength_nm'")
            n_wl = math.prod(shapes["wavelength_nm"])
            _expect_shape(shapes, "spectra", (n_l, n_v, n_wl), shown)
            check_memory(_SPECTRA_BYTES_PER_SAMPLE * n_l * n_v * n_wl,
                         f"{shown}: spectra of {n_l} x {n_v} angles x {n_wl} wavelengths")
        elif "lab" not in keys:
            raise InputError(f"{shown}: needs 'lab' or 'spectra' + 'wavelength_nm'")
        try:
            return _read_map(z, keys, shown, path)
        except (OSError, EOFError, zipfile.BadZipFile) as exc:
            raise InputError(f"{shown}: cannot read ({one_line(exc)})") from None
        except InputError:
            raise
        except ValueError as exc:  # an array shorter than its header says
            raise InputError(f"{shown}: cannot read ({one_line(exc)})") from None


def _read_map(z, keys: set, shown: str, path) -> AngularMap:
    """The map of the open ``.npz`` ``z``, whose headers :func:`load_map` has checked."""
    tl, tv = z["theta_light_deg"], z["theta_view_deg"]
    try:
        tl = check_angles(tl, f"{shown}: key 'theta_light_deg'")
        tv = check_angles(tv, f"{shown}: key 'theta_view_deg'")
    except ValueError as exc:
        raise InputError(str(exc)) from None
    ill = str(z["illuminant"]) if "illuminant" in keys else DEFAULT_ILLUMINANT
    obs = str(z["observer"]) if "observer" in keys else DEFAULT_OBSERVER
    spectra = wl = None
    if "spectra" in keys:
        spectra = np.asarray(z["spectra"], np.float64)
        wl = np.asarray(z["wavelength_nm"], np.float64).reshape(-1)
    if "lab" in keys:
        lab = np.asarray(z["lab"], np.float32)
        xyz = srgb = None
    else:
        xyz, lab, srgb, _ = colours_from_spectra(spectra, wl, illuminant=ill, observer=obs)
    return AngularMap(tl, tv, lab, xyz, srgb, spectra, wl, ill, obs, {"source": str(path)})


def save_png(path, m: AngularMap, *, scale=4):
    """Write the map's sRGB image, each cell ``scale`` × ``scale`` pixels, light angle down."""
    img = m.srgb if m.srgb is not None else lab_to_display_srgb(m.lab, m.illuminant, m.observer)
    write_image(path, np.repeat(np.repeat(img, int(scale), axis=0), int(scale), axis=1))
