"""Which Mitsuba 3 spectral variants work on this machine, and which one to render with.

The film's colours are computed per wavelength, so microfacet renders in Mitsuba's
unpolarized *spectral* variants only: ``llvm_ad_spectral`` (vectorised, JIT-compiled by
LLVM; the fast one) and ``scalar_spectral`` (one ray at a time; a BSDF written in Python is
called per sample: the thin-film BSDF renders ~2000x slower per sample there, see
docs/rendering.md). CUDA variants are never chosen automatically (they may be requested).

Probing (:func:`variant_probes`)
    A variant is known to work only once it has rendered: an LLVM variant can *abort the
    process* (SIGABRT, ``LLVM ERROR: Cannot select: … fminimum``) when Dr.Jit loads an
    old libLLVM — Debian 12's default LLVM 15 does; LLVM 19 works. So each candidate renders
    a 4×4-pixel, 1-spp scene in a child process (``sys.executable``), the children run side
    by side, and the result is cached for the process (about 2 s the first time, nothing
    after).

libLLVM fallback
    When an LLVM variant fails with the library Dr.Jit finds by itself, every other libLLVM
    on the machine with a newer major version (:func:`find_libllvm`) is tried through the
    ``DRJIT_LIBLLVM_PATH`` environment variable, newest first. If one works it is set in
    ``os.environ`` for this process. Dr.Jit reads that variable, and loads libLLVM, when
    ``drjit`` is *imported* (``import mitsuba`` imports it) — not when a variant is set — so
    the fallback takes effect only if neither has been imported yet in this process; when
    ``drjit`` was imported first, the probes reproduce the libLLVM this process has loaded
    and the message says what to set before starting Python.

Examples
--------
>>> v = available_variants()          # doctest: +SKIP
>>> v                                 # doctest: +SKIP
('llvm_ad_spectral', 'scalar_spectral')
>>> choose_variant()                  # doctest: +SKIP
('llvm_ad_spectral', None)
"""

from __future__ import annotations

import ast
import functools
import glob
import importlib.util
import json
import os
import re
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from ..core.errors import InputError, one_line

__all__ = ["AUTO_VARIANTS", "PROBE_TIMEOUT_S", "VariantProbe", "available_variants",
           "choose_variant", "find_libllvm", "probe_variant", "variant_probes"]

#: The variants chosen automatically, fastest first (those this Mitsuba build has).
AUTO_VARIANTS = ("llvm_ad_spectral", "llvm_spectral", "scalar_spectral")
#: Longest a probe may take (its first LLVM compile included), s.
PROBE_TIMEOUT_S = 60.0
#: Unpolarized spectral variants, the only ones microfacet can render with.
_SPECTRAL = re.compile(r"^(scalar|llvm|cuda)(_ad)?_spectral$")
#: Where libLLVM may be, besides the one Dr.Jit finds itself.
_LIBLLVM_GLOBS = (
    "/usr/lib/x86_64-linux-gnu/libLLVM*.so*", "/usr/lib/aarch64-linux-gnu/libLLVM*.so*",
    "/usr/lib/llvm-*/lib/libLLVM*.so*", "/usr/lib64/libLLVM*.so*", "/usr/lib/libLLVM*.so*",
    "/usr/local/lib/libLLVM*.so*", "/opt/homebrew/opt/llvm/lib/libLLVM*.dylib",
    "/usr/local/opt/llvm/lib/libLLVM*.dylib",
)
_ENV = "DRJIT_LIBLLVM_PATH"

# The child: set the variant, report the libLLVM it mapped (before rendering, so that an abort
# still says which one), render a diffuse sphere under a D65 environment, report the mean.
_PROBE_SCRIPT = r"""
import json, math, sys
import mitsuba as mi
mi.set_variant(sys.argv[1])
lib = ""
try:
    with open("/proc/self/maps") as f:
        lib = next((ln.split()[-1] for ln in f if "libLLVM" in ln), "")
except OSError:
    pass
print(json.dumps({"libllvm": lib}), flush=True)
T = mi.ScalarTransform4f
scene = mi.load_dict({
    "type": "scene", "integrator": {"type": "path", "max_depth": 3},
    "ball": {"type": "sphere", "bsdf": {"type": "roughconductor", "alpha": 0.2}},
    "sky": {"type": "constant", "radiance": {"type": "d65", "scale": 1.0}},
    "camera": {"type": "perspective", "fov": 45.0,
               "to_world": T().look_at(origin=[0, 0, 4], target=[0, 0, 0], up=[0, 1, 0]),
               "film": {"type": "hdrfilm", "width": 4, "height": 4},
               "sampler": {"type": "independent", "sample_count": 1}}})
import numpy as np
mean = float(np.mean(np.asarray(mi.render(scene, spp=1))))
print(json.dumps({"mean": mean, "ok": math.isfinite(mean) and mean > 0}), flush=True)
"""


@dataclass(frozen=True)
class VariantProbe:
    """What one probe of a Mitsuba variant found.

    Attributes
    ----------
    variant : str
    works : bool
        It rendered a finite, positive image in a child process (and, for an LLVM variant,
        can in this process: see ``reason``).
    reason : str
        One line: why it does not work ("" when it does).
    libllvm : str
        The libLLVM the child loaded ("" when none or unknown).
    libllvm_path : str or None
        The ``DRJIT_LIBLLVM_PATH`` it was probed with (None: Dr.Jit's own search).
    seconds : float
        Wall time of the probe(s), s.
    """

    variant: str
    works: bool
    reason: str = ""
    libllvm: str = ""
    libllvm_path: str | None = None
    seconds: float = 0.0


def libllvm_major(path: str) -> int | None:
    """The major version in a libLLVM path (``libLLVM-15.so.1``, ``libLLVM.so.19.1``,
    ``/usr/lib/llvm-19/lib/libLLVM.so``), or None.

    >>> libllvm_major("/usr/lib/x86_64-linux-gnu/libLLVM-15.so.1"), libllvm_major(
    ...     "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"), libllvm_major("libLLVM.so")
    (15, 19, None)
    """
    name = os.path.basename(path)
    m = (re.match(r"libLLVM-(\d+)", name) or re.match(r"libLLVM\.so\.(\d+)", name)
         or re.search(r"llvm[-@](\d+)", path))
    return int(m.group(1)) if m else None


def find_libllvm() -> list[str]:
    """The shared libLLVM libraries on this machine, newest major version first, one path per
    library file (symbolic links resolved; unversioned ones last)."""
    seen, found = set(), []
    for pattern in _LIBLLVM_GLOBS:
        for p in sorted(glob.glob(pattern)):
            real = os.path.realpath(p)
            if real in seen or not os.path.isfile(real):
                continue
            seen.add(real)
            found.append(real)
    return sorted(found, key=lambda p: -(libllvm_major(p) or -1))


def _mitsuba_variants() -> tuple[str, ...] | None:
    """The variants this Mitsuba build has, read from its ``config.py`` without importing it
    (importing Mitsuba imports Dr.Jit, which loads libLLVM); None when Mitsuba is not
    installed, all of :data:`AUTO_VARIANTS` when the file cannot be read."""
    spec = importlib.util.find_spec("mitsuba")
    if spec is None:
        return None
    for folder in spec.submodule_search_locations or ():
        try:
            tree = ast.parse((Path(folder) / "config.py").read_text(encoding="utf-8"))
        except (OSError, SyntaxError, ValueError):
            continue
        for node in tree.body:
            if (isinstance(node, ast.Assign) and len(node.targets) == 1
                    and getattr(node.targets[0], "id", "") == "MI_VARIANTS"):
                try:
                    return tuple(ast.literal_eval(node.value))
                except ValueError:
                    break
    return AUTO_VARIANTS


def _loaded_libllvm() -> str | None:
    """The libLLVM this process has mapped (Linux), "" when Dr.Jit is imported without one,
    None when Dr.Jit is not imported yet or the maps cannot be read."""
    if "drjit" not in sys.modules:
        return None
    try:
        with open("/proc/self/maps", encoding="utf-8") as f:
            return next((ln.split()[-1] for ln in f if "libLLVM" in ln), "")
    except OSError:
        return None


def _start(variant: str, libllvm_path: str | None):
    env = dict(os.environ)
    if libllvm_path is not None:
        env[_ENV] = libllvm_path
    return subprocess.Popen([sys.executable, "-c", _PROBE_SCRIPT, variant], env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True)


def _failure(proc, stderr: str) -> str:
    """One line: how a probe child failed."""
    lines = [ln.strip() for ln in stderr.splitlines() if ln.strip()]
    llvm = next((ln for ln in lines if ln.startswith("LLVM ERROR")), None)
    if llvm is not None:   # "Cannot select: 0x55…: f32 = fminimum 0x55…, 0x55…"
        llvm = re.sub(r"\s*0x[0-9a-fA-F]+:?,?", "", llvm)
    what = (llvm or (lines[-1] if lines else "no output"))[:160]
    if proc.returncode is not None and proc.returncode < 0:
        try:
            name = signal.Signals(-proc.returncode).name
        except ValueError:
            name = f"signal {-proc.returncode}"
        return one_line(f"aborted ({name}): {what}")
    return one_line(f"failed: {what}")


def _finish(variant: str, proc, libllvm_path: str | None, t0: float,
            timeout_s: float) -> VariantProbe:
    try:
        out, err = proc.communicate(timeout=max(timeout_s - (time.perf_counter() - t0), 0.1))
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.communicate()
        return VariantProbe(variant, False, f"timed out after {timeout_s:g} s", "",
                            libllvm_path, time.perf_counter() - t0)
    info = {}
    for line in out.splitlines():
        try:
            info.update(json.loads(line))
        except ValueError:
            continue
    lib = info.get("libllvm", "")
    seconds = time.perf_counter() - t0
    if proc.returncode == 0 and info.get("ok"):
        return VariantProbe(variant, True, "", lib, libllvm_path, seconds)
    reason = (_failure(proc, err) if proc.returncode != 0
              else f"rendered an invalid image (mean {info.get('mean')!r})")
    return VariantProbe(variant, False, reason, lib, libllvm_path, seconds)


def probe_variant(variant: str, *, libllvm_path: str | None = None,
                  timeout_s: float = PROBE_TIMEOUT_S) -> VariantProbe:
    """Render a 4×4-pixel, 1-spp scene in ``variant`` in a child process.

    Parameters
    ----------
    variant : str
        A Mitsuba variant name.
    libllvm_path : str, optional
        ``DRJIT_LIBLLVM_PATH`` for the child (default: this process's environment).
    timeout_s : float
        The child is killed after this long, s.

    Returns
    -------
    VariantProbe
        Not cached (see :func:`variant_probes`).
    """
    t0 = time.perf_counter()
    return _finish(variant, _start(variant, libllvm_path), libllvm_path, t0, timeout_s)


def _describe(probe: VariantProbe) -> str:
    lib = probe.libllvm or probe.libllvm_path or ""
    major = libllvm_major(lib) if lib else None
    return (f"with libLLVM {major}: " if major else "") + probe.reason


def _with_fallback(first: VariantProbe, pinned: str | None) -> VariantProbe:
    """``first`` (a failed LLVM probe) retried with every newer libLLVM on the machine; the
    first that works is set in ``os.environ`` unless Dr.Jit is already loaded (``pinned``)."""
    failed_lib = first.libllvm or first.libllvm_path or ""
    major = libllvm_major(failed_lib) if failed_lib else None
    tried = {os.path.realpath(failed_lib)} if failed_lib else set()
    seconds, notes = first.seconds, [_describe(first)]
    for lib in find_libllvm():
        m = libllvm_major(lib)
        if lib in tried or (major is not None and (m is None or m <= major)):
            continue
        p = probe_variant(first.variant, libllvm_path=lib)
        seconds += p.seconds
        if p.works:
            if pinned is not None:
                return VariantProbe(first.variant, False, one_line(
                    f"{notes[0]}; drjit was imported before microfacet could switch to "
                    f"{lib}: set {_ENV}={lib} before starting Python"), first.libllvm,
                    first.libllvm_path, seconds)
            os.environ[_ENV] = lib
            return VariantProbe(first.variant, True, "", p.libllvm, lib, seconds)
        notes.append(_describe(p))
    found = [f"{libllvm_major(x) or '?'} ({x})" for x in find_libllvm()]
    hint = (f"found only libLLVM {', '.join(found)}; " if len(notes) == 1 and found
            else "" if found else "found no other libLLVM; ") + (
        f"install a newer libLLVM (19 works; e.g. Debian's libllvm19) or set {_ENV}")
    return VariantProbe(first.variant, False, one_line("; ".join(notes) + "; " + hint),
                        first.libllvm, first.libllvm_path, seconds)


def _survey(candidates) -> tuple[VariantProbe, ...]:
    pinned = _loaded_libllvm()
    path = pinned or None   # a process with Dr.Jit loaded: probe the library it has
    t0 = time.perf_counter()
    procs = [(v, None if pinned == "" and v.startswith("llvm") else _start(v, path))
             for v in candidates]
    probes = []
    for v, proc in procs:
        if proc is None:
            probes.append(VariantProbe(v, False, f"drjit, imported before microfacet chose a "
                                       f"variant, found no libLLVM: set {_ENV} before "
                                       f"starting Python"))
            continue
        p = _finish(v, proc, path, t0, PROBE_TIMEOUT_S)
        if not p.works and v.startswith("llvm"):
            p = _with_fallback(p, pinned)
        probes.append(p)
    return tuple(probes)


@functools.cache
def variant_probes() -> tuple[VariantProbe, ...]:
    """The probes of :data:`AUTO_VARIANTS` this Mitsuba build has, in that order; cached for
    the process (``variant_probes.cache_clear()`` forgets them). Empty when Mitsuba is not
    installed. May set ``DRJIT_LIBLLVM_PATH`` in ``os.environ`` (see the module notes)."""
    built = _mitsuba_variants()
    if built is None:
        return ()
    return _survey([v for v in AUTO_VARIANTS if v in built])


@functools.cache
def _requested_probe(variant: str) -> VariantProbe:
    for p in variant_probes():
        if p.variant == variant:
            return p
    return _survey([variant])[0]


def available_variants() -> tuple[str, ...]:
    """The Mitsuba spectral variants that render on this machine, fastest first
    (``llvm_ad_spectral`` before ``scalar_spectral``; never CUDA). Cached for the process.

    Returns
    -------
    tuple of str
        Empty when Mitsuba is not installed or no variant works.
    """
    return tuple(p.variant for p in variant_probes() if p.works)


def _scalar_note(chosen: str) -> str | None:
    """The one-line message when only the slow scalar variant works (None otherwise)."""
    if not chosen.startswith("scalar"):
        return None
    failed = [p for p in variant_probes() if not p.variant.startswith("scalar")]
    if not failed or any(p.works for p in failed):
        return None
    why = "; ".join(f"{p.variant} unavailable ({p.reason})" for p in failed)
    return one_line(f"{why}: using {chosen}, ~2000x slower per sample (docs/rendering.md)")


def choose_variant(requested: str | None = None) -> tuple[str, str | None]:
    """The Mitsuba variant to render with, and a note when it is the slow one.

    Parameters
    ----------
    requested : str, optional
        A variant name; default: the fastest of :func:`available_variants`.

    Returns
    -------
    variant : str
        Pass it to ``mitsuba.set_variant`` (after this call: a libLLVM fallback is set in the
        environment before Mitsuba is imported).
    note : str or None
        One line, when only the scalar variant works: which faster variant failed and why,
        and what to install.

    Raises
    ------
    InputError
        ``param="variant"``: Mitsuba is not installed (``pip install "microfacet[render]"``),
        the requested variant is not an unpolarized spectral one or does not work here (the
        reason), or no variant works.
    """
    built = _mitsuba_variants()
    if built is None:
        raise InputError('Mitsuba 3 is not installed: pip install "microfacet[render]"',
                         param="variant")
    works = available_variants()
    if requested is None:
        if not works:
            why = "; ".join(f"{p.variant}: {p.reason}" for p in variant_probes()) or (
                "this Mitsuba build has none of " + ", ".join(AUTO_VARIANTS))
            raise InputError(one_line(f"no Mitsuba spectral variant works here ({why})"),
                             param="variant")
        return works[0], _scalar_note(works[0])
    requested = str(requested)
    listed = ", ".join(works) or "none"
    if requested not in built:
        raise InputError(one_line(f"{requested!r} is not a variant of this Mitsuba build; "
                                  f"working here: {listed}"), param="variant")
    if not _SPECTRAL.match(requested):
        raise InputError(one_line(
            f"{requested!r} is not an unpolarized spectral Mitsuba variant (the film's colours "
            f"are computed per wavelength); working here: {listed}"), param="variant")
    p = _requested_probe(requested)
    if not p.works:
        raise InputError(one_line(f"{requested} does not work here ({p.reason}); working "
                                  f"here: {listed}"), param="variant")
    return requested, _scalar_note(requested)
