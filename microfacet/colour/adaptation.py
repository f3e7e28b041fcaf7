"""Chromatic adaptation: the Bradford transform, as colour-science computes it.

A white-balanced image under an illuminant other than D65 is mapped from the sRGB white to
that illuminant's white by a Bradford (von Kries in sharpened cone space) adaptation; the
(3, 3) matrix is built once per illuminant with the operations of colour-science's
``colour.adaptation.matrix_chromatic_adaptation_VonKries(..., transform="Bradford")`` (the
same numbers, tests/colour/test_adaptation.py), written out so that the analysis does not
import colour-science for it (~0.7 s; :mod:`microfacet.colour.snapshot`).

References
----------
.. [1] N. Nagata, M. Kamei, K. Takahashi, K. Tobitani, T. Akagi, S. Yamamura, "Simulation
   Technology for Titanium Oxide Layer Interference Color", Technical Report (the seed paper),
   §2.2.1 and §2.6 (measured colours as RGB; a D65 light source).
.. [2] K. M. Lam, "Metamerism and colour constancy", PhD thesis, University of Bradford (1985)
   (the Bradford transform).

Examples
--------
>>> import numpy as np
>>> A = bradford_matrix([0.9505, 1.0, 1.089], [1.0985, 1.0, 0.3558])   # D65 -> A
>>> np.allclose(A @ [0.9505, 1.0, 1.089], [1.0985, 1.0, 0.3558])
True
"""

from __future__ import annotations

from typing import Any

import numpy as np

__all__ = ["BRADFORD", "bradford_matrix"]

#: Bradford cone-response matrix (Lam 1985); colour-science's ``CAT_BRADFORD``.
BRADFORD = np.array(
    [
        [0.8951, 0.2664, -0.1614],
        [-0.7502, 1.7135, 0.0367],
        [0.0389, -0.0685, 1.0296],
    ]
)
BRADFORD.flags.writeable = False


def bradford_matrix(source_white: Any, target_white: Any) -> np.ndarray:
    """Bradford (linear, von Kries in sharpened cone space) adaptation matrix.

    colour-science's ``colour.adaptation.matrix_chromatic_adaptation_VonKries(...,
    transform="Bradford")`` (cone matrix :data:`BRADFORD`), computed by the same operations:
    a (3, 3) matrix built once per illuminant, not a hot path.

    Parameters
    ----------
    source_white, target_white : array_like, shape (3,)
        XYZ of the source and target whites (finite, ``Y > 0``, any common scale).

    Returns
    -------
    numpy.ndarray, shape (3, 3), float64
        ``A`` with ``xyz_target = xyz_source @ A.T`` and ``A @ source_white ==
        target_white``.

    Raises
    ------
    ValueError
        A white that is not a finite XYZ triple with ``Y > 0`` (the message names it).

    Examples
    --------
    >>> d65, a = [0.9505, 1.0, 1.089], [1.0985, 1.0, 0.3558]
    >>> np.allclose(bradford_matrix(d65, d65), np.eye(3), atol=1e-12)
    True
    >>> (bradford_matrix(d65, a) @ d65).round(12).tolist()
    [1.0985, 1.0, 0.3558]
    """
    src = np.asarray(source_white, dtype=np.float64)
    dst = np.asarray(target_white, dtype=np.float64)
    for name, w in (("source_white", src), ("target_white", dst)):
        if w.shape != (3,):
            raise ValueError(f"{name} must have shape (3,), got {w.shape}")
        if not (np.all(np.isfinite(w)) and w[1] > 0):
            raise ValueError(f"{name} must be a finite XYZ triple with Y > 0, got {w.tolist()}")
    # colour-science's von Kries matrix, computed as it computes it (the same operations
    # in the same order, so the same float64 numbers): inv(M) @ diag(M w_t / M w_s) @ M.
    # Written out because importing colour-science takes ~0.7 s (microfacet.colour.snapshot)
    # and the analysis needs it for nothing else; tests/colour/test_adaptation.py compares.
    m = np.array(BRADFORD)
    d = np.matmul(m, dst[:, None]).squeeze(-1) / np.matmul(m, src[:, None]).squeeze(-1)
    return np.matmul(np.matmul(np.linalg.inv(m), np.diag(d)), m)
