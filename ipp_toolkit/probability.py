"""Probabilities of a binary cell: the clip, the log-odds and the entropy of one Bernoulli.

The bottom of the toolkit's layers (like :mod:`ipp_toolkit.io`): the camera
(:mod:`ipp_toolkit.world.sensor`) states its readings' log-odds and entropy with these, and
the maps (:mod:`ipp_toolkit.belief.mapping`, the owner of every map entropy) build on them.
"""

from __future__ import annotations

import numpy as np

__all__ = ["PROB_CLIP", "LOGODDS_CLIP", "logit", "binary_entropy"]

PROB_CLIP = 1e-4
"""Probabilities are kept inside [PROB_CLIP, 1 - PROB_CLIP] wherever a logit or log is taken."""

LOGODDS_CLIP = float(np.log((1 - PROB_CLIP) / PROB_CLIP))


def logit(p: np.ndarray | float) -> np.ndarray:
    """Log-odds of probabilities clipped to [PROB_CLIP, 1 - PROB_CLIP]; any shape."""
    p = np.clip(np.asarray(p, dtype=np.float64), PROB_CLIP, 1 - PROB_CLIP)
    return np.log(p / (1 - p))


def binary_entropy(p: np.ndarray | float) -> np.ndarray:
    """Shannon entropy in bits of Bernoulli(p), p clipped to [PROB_CLIP, 1 - PROB_CLIP]."""
    p = np.clip(np.asarray(p, dtype=np.float64), PROB_CLIP, 1 - PROB_CLIP)
    return -(p * np.log2(p) + (1 - p) * np.log2(1 - p))
