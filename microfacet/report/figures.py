"""Figures of angular maps for ``microfacet simulate``: the predicted map, and the measured
and ΔE00 maps when given. Drawn on a matplotlib ``Figure`` (no global backend switch)."""

from __future__ import annotations

from ..core.angular import AngularMap
from ..core.lazy import load
from ..io.angular_map import lab_to_display_srgb

figure = load("matplotlib.figure")

__all__ = ["plot_maps"]


def plot_maps(path, predicted: AngularMap, *, measured: AngularMap | None = None,
              delta_e=None, stats=None, title=None):
    """PDF (or PNG) figure: the predicted map, and the measured and ΔE00 maps if given.

    Axes: view angle across, light angle down (as the seed's Figs. 5, 10, 20).
    """
    panels = [("predicted", predicted)]
    if measured is not None:
        panels.append(("measured", measured))
    ncol = len(panels) + (delta_e is not None)
    fig = figure.Figure(figsize=(3.6 * ncol, 3.6))
    axes = fig.subplots(1, ncol, squeeze=False)
    tl, tv = predicted.theta_light_deg, predicted.theta_view_deg
    ext = [tv[0] - 0.5, tv[-1] + 0.5, tl[-1] + 0.5, tl[0] - 0.5]
    for ax, (name, m) in zip(axes[0], panels):
        img = m.srgb if m.srgb is not None else lab_to_display_srgb(m.lab, m.illuminant, m.observer)
        ax.imshow(img, extent=ext, interpolation="nearest")
        ax.set_title(name)
        ax.set_xlabel("view zenith (deg, + = mirror side)")
        ax.set_ylabel("light zenith (deg)")
    if delta_e is not None:
        ax = axes[0][-1]
        im = ax.imshow(delta_e, extent=ext, cmap="magma", interpolation="nearest")
        fig.colorbar(im, ax=ax, fraction=0.046, label="ΔE00")
        t = "ΔE00"
        if stats:
            t += (f": mean {stats['mean']:.2f}, diffuse "
                  f"{stats['mean_excluding_specular']:.2f}")
        ax.set_title(t, fontsize=9)
        ax.set_xlabel("view zenith (deg)")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
