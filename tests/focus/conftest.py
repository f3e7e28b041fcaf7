"""Fixtures of the focus tests: focus stacks of analytic surfaces with a controlled texture
contrast (the renderer of the accuracy-focus-coverage study, independent of microfacet)."""

from __future__ import annotations

import numpy as np
import pytest


@pytest.fixture(scope="session")
def render_contrast():
    """``render_contrast(height, z, *, contrast, chroma=0.0, noise=0.01, blur=1.55, seed=0,
    rgb=False)``: float32 slices in [0, 1], 8-bit quantised, of band-limited random texture
    (luma SD ``contrast``, isoluminant chroma SD ``chroma`` when ``rgb``) on ``height`` (in z
    steps, ``z`` in the same unit): each pixel blurred by its own Gaussian defocus
    σ = √(0.67² + (blur·|z − h|)²) px, Gaussian noise of SD ``noise``."""
    import cv2

    def render(height, z, *, contrast, chroma=0.0, noise=0.01, blur=1.55, seed=0, rgb=False):
        rng = np.random.default_rng(seed)
        hgt = np.asarray(height, np.float32)

        def field():
            f = cv2.GaussianBlur(rng.standard_normal(hgt.shape).astype(np.float32), (0, 0),
                                 0.8)
            return (f - f.mean()) / f.std()

        if rgb:
            tex = np.full(hgt.shape + (3,), 0.5, np.float32) + contrast * field()[..., None]
            axis = np.array([1.0, -0.509, 0.0], np.float32)
            tex += chroma * field()[..., None] * (axis / np.linalg.norm(axis))
        else:
            tex = 0.5 + contrast * field()
        step = 0.25
        smax = float(np.sqrt(0.67 ** 2 + (blur * (np.ptp(z) + np.ptp(hgt) + 1)) ** 2))
        levels = np.arange(0.0, smax + 2 * step, step)
        ladder = [tex] + [cv2.GaussianBlur(tex, (0, 0), s) for s in levels[1:]]
        out = []
        for zk in z:
            pos = np.sqrt(0.67 ** 2 + (blur * (zk - hgt)) ** 2) / step
            lo = np.floor(pos).astype(int)
            t = (pos - lo).astype(np.float32)
            if rgb:
                t = t[..., None]
            img = np.zeros_like(tex)
            for li in np.unique(lo):
                m = lo == li
                img[m] = (1 - t[m]) * ladder[li][m] + t[m] * ladder[li + 1][m]
            img = img + rng.normal(0.0, noise, img.shape).astype(np.float32)
            out.append((np.round(np.clip(img, 0, 1) * 255) / 255).astype(np.float32))
        return out

    return render
