"""Whether the summaries agree with the maps they summarize.

The thickness mixture is fitted to the facets; the per-pixel thickness map is what a user
looks at. :func:`mixture_map_check` assigns every mapped pixel to the component most likely
to have produced it (each component widened by the map's own error floor) and compares the
area fractions and means with the mixture's: a mixture that reads two close components where
the map holds three populations, or leaves a fifth of the map unexplained, says so.

A region of interest's single least-ΔE thickness is one number for all its pixels; where
the ROI spans several populations it can land on another interference order altogether
while its pixels read the right one. :func:`roi_pixel_check` flags a ROI whose single fit
lies further from the median of its own pixels' thicknesses than their spread allows.

Examples
--------
>>> from microfacet.core.distributions import ThicknessMixture
>>> t = np.concatenate([np.full(700, 130.0), np.full(300, 150.0)])
>>> c = mixture_map_check(t, ThicknessMixture([(0.7, 130.0, 1.0), (0.3, 150.0, 1.0)]))
>>> c.consistent, [round(f, 2) for f in c.map_fractions]
(True, [0.7, 0.3])
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["MapCheck", "mixture_map_check", "roi_pixel_check"]

#: The per-pixel map's error floor (nm) each component is widened by: the thickness per true
#: region errs by a median 0.6-0.8 nm on the generalization sweep (docs/accuracy.md).
MAP_FLOOR_NM = 1.0
#: A pixel further than this many (widened) SDs from every component is unexplained.
UNEXPLAINED_SD = 4.0
#: Largest differences for a mixture that agrees with its map: area fraction per component,
#: mean per component (nm), unexplained area fraction.
MAX_FRACTION_DIFFERENCE = 0.1
MAX_MEAN_DIFFERENCE_NM = 2.0
MAX_UNEXPLAINED = 0.15
#: A ROI's single fit disagrees with its pixels beyond max(3 × their robust SD, this) (nm).
ROI_MIN_GAP_NM = 5.0


@dataclass(frozen=True)
class MapCheck:
    """The mixture against the per-pixel thickness map (:func:`mixture_map_check`).

    Attributes
    ----------
    map_fractions, map_means_nm : list of float
        Per component: the area fraction of the explained pixels it is most likely for, and
        their mean thickness (NaN without pixels).
    unexplained_fraction : float
        Mapped pixels further than :data:`UNEXPLAINED_SD` widened SDs from every component.
    max_fraction_difference, max_mean_difference_nm : float
        Against the mixture's weights and means.
    consistent : bool
        Within :data:`MAX_FRACTION_DIFFERENCE`, :data:`MAX_MEAN_DIFFERENCE_NM` and
        :data:`MAX_UNEXPLAINED`.
    """

    map_fractions: list
    map_means_nm: list
    unexplained_fraction: float
    max_fraction_difference: float
    max_mean_difference_nm: float
    consistent: bool

    def to_json(self) -> dict:
        return {"map_fractions": [float(v) for v in self.map_fractions],
                "map_means_nm": [float(v) for v in self.map_means_nm],
                "unexplained_fraction": float(self.unexplained_fraction),
                "max_fraction_difference": float(self.max_fraction_difference),
                "max_mean_difference_nm": float(self.max_mean_difference_nm),
                "consistent": bool(self.consistent)}


def mixture_map_check(thickness_nm, mixture) -> MapCheck | None:
    """The mixture's components against the map's pixels (module notes).

    Parameters
    ----------
    thickness_nm : ndarray, any shape
        The per-pixel thickness map, nm (NaN: not mapped).
    mixture : ThicknessMixture

    Returns
    -------
    MapCheck or None
        None without mapped pixels or components.
    """
    t = np.asarray(thickness_nm, dtype=np.float64).ravel()
    t = t[np.isfinite(t)]
    comps = np.asarray(mixture.components, dtype=np.float64) if mixture is not None else ()
    if t.size == 0 or len(comps) == 0:
        return None
    w, mu, sd = comps[:, 0], comps[:, 1], np.hypot(comps[:, 2], MAP_FLOOR_NM)
    z = (t[:, None] - mu[None, :]) / sd[None, :]
    explained = np.min(np.abs(z), axis=1) <= UNEXPLAINED_SD
    logp = np.log(np.maximum(w, 1e-300))[None, :] - np.log(sd)[None, :] - 0.5 * z * z
    k = np.argmax(logp, axis=1)[explained]
    te = t[explained]
    n = max(te.size, 1)
    frac = np.bincount(k, minlength=len(w)) / n
    means = np.array([te[k == j].mean() if np.any(k == j) else np.nan for j in range(len(w))])
    dfrac = float(np.max(np.abs(frac - w / w.sum())))
    dmean = float(np.nanmax(np.abs(means - mu))) if np.isfinite(means).any() else np.inf
    unexplained = 1.0 - float(explained.mean())
    ok = (dfrac <= MAX_FRACTION_DIFFERENCE and dmean <= MAX_MEAN_DIFFERENCE_NM
          and unexplained <= MAX_UNEXPLAINED)
    return MapCheck([float(f) for f in frac], [float(m) for m in means], unexplained, dfrac,
                    dmean, bool(ok))


def roi_pixel_check(roi, thickness_nm) -> tuple[np.ndarray, np.ndarray]:
    """Per ROI: the median of its pixels' thicknesses, and whether its single fit lies
    further from it than max(3 × their robust SD, :data:`ROI_MIN_GAP_NM`).

    Parameters
    ----------
    roi : RoiFit
        The ROIs (their fits and :meth:`~.roi.RoiFit.pixel_values`).
    thickness_nm : ndarray (H, W)
        The per-pixel thickness map.

    Returns
    -------
    pixel_median_nm : ndarray (R,)
        NaN where the ROI has no mapped pixel.
    disagrees : ndarray of bool (R,)
    """
    n = roi.thickness_nm.size
    med, gap = np.full(n, np.nan), np.full(n, np.inf)
    for i, v in roi.pixel_values(thickness_nm):
        med[i] = np.median(v)
        gap[i] = max(3.0 * 1.4826 * np.median(np.abs(v - med[i])), ROI_MIN_GAP_NM)
    fit = np.asarray(roi.thickness_nm, dtype=np.float64)
    with np.errstate(invalid="ignore"):
        disagrees = np.isfinite(fit) & np.isfinite(med) & (np.abs(fit - med) > gap)
    return med, disagrees
