"""``VecNormalize`` observation statistics beside an SB3 zip, as JSON (never a pickle).

SB3's ``model.save`` leaves ``VecNormalize`` out of the zip, and ``VecNormalize.save`` writes
a pickle, which the ``sb3`` planner does not read. :func:`save_vec_normalize` writes the
statistics the policy's inputs need (running mean and variance of the observations, the clip
and epsilon) to ``PATH.vecnormalize.json`` beside ``PATH.zip``; the planner applies them to
the planes before the policy sees them (:class:`ObsNormalization`) and refuses a zip trained
under ``VecNormalize`` whose statistics are missing (:func:`zip_normalization`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ipp_toolkit.io import CheckpointError, write_json

__all__ = ["NORMALIZATION_KIND", "ObsNormalization", "normalization_path", "save_vec_normalize",
           "zip_normalization"]

NORMALIZATION_KIND = "ipp-toolkit/vec-normalize"


@dataclass(frozen=True)
class ObsNormalization:
    """``VecNormalize``'s observation transform: ``clip((obs - mean) / sqrt(var + eps))``.

    Attributes:
        mean, var: (C, G, G) float64 running statistics of the training observations.
        clip: the bound of the normalised values (``clip_obs``).
        epsilon: added to the variance.
        enabled: False when the model was trained with ``norm_obs=False`` (nothing to apply).
    """

    mean: np.ndarray
    var: np.ndarray
    clip: float
    epsilon: float
    enabled: bool = True

    def apply(self, observations: np.ndarray) -> np.ndarray:
        """(B, C, G, G) planes as the policy saw them in training, float32."""
        if not self.enabled:
            return observations
        scaled = (observations - self.mean) / np.sqrt(self.var + self.epsilon)
        return np.clip(scaled, -self.clip, self.clip).astype(np.float32)


def normalization_path(zip_path: str | Path) -> Path:
    """Where the statistics of ``zip_path`` live: ``mine.zip`` -> ``mine.vecnormalize.json``."""
    return Path(zip_path).with_suffix(".vecnormalize.json")


def save_vec_normalize(vec_normalize: Any, zip_path: str | Path) -> Path:
    """Write ``vec_normalize``'s observation statistics beside the model zip ``zip_path``.

    Args:
        vec_normalize: SB3's ``VecNormalize`` the model was trained under (e.g.
            ``model.get_vec_normalize_env()``).
        zip_path: the model's zip (``model.save(zip_path)``).

    Returns:
        the JSON file written (:func:`normalization_path`).

    Raises:
        ValueError: ``vec_normalize`` has no Box observation statistics (a Dict observation
            space, or not a ``VecNormalize``).
    """
    obs_rms = getattr(vec_normalize, "obs_rms", None)
    if not hasattr(obs_rms, "mean") or not hasattr(obs_rms, "var"):
        raise ValueError(f"expected SB3's VecNormalize over Box observations, got "
                         f"{type(vec_normalize).__name__}")
    record = {"format": NORMALIZATION_KIND, "norm_obs": bool(vec_normalize.norm_obs),
              "clip_obs": float(vec_normalize.clip_obs), "epsilon": float(vec_normalize.epsilon),
              "shape": list(np.shape(obs_rms.mean)),
              "mean": np.asarray(obs_rms.mean, dtype=np.float64).tolist(),
              "var": np.asarray(obs_rms.var, dtype=np.float64).tolist()}
    path = normalization_path(zip_path)
    write_json(path, record)
    return path


def _read(path: Path, obs_shape: tuple[int, ...]) -> ObsNormalization:
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
        if record.get("format") != NORMALIZATION_KIND:
            raise ValueError(f"format {record.get('format')!r} is not {NORMALIZATION_KIND}")
        mean = np.asarray(record["mean"], dtype=np.float64)
        var = np.asarray(record["var"], dtype=np.float64)
        clip, epsilon = float(record["clip_obs"]), float(record["epsilon"])
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as error:
        raise CheckpointError(f"VecNormalize statistics {str(path)!r} cannot be read: "
                              f"{error}") from None
    if mean.shape != obs_shape or var.shape != obs_shape:
        raise CheckpointError(f"VecNormalize statistics {str(path)!r} are of shape "
                              f"{mean.shape}; the model observes {obs_shape}")
    if not (np.isfinite(mean).all() and np.isfinite(var).all() and (var >= 0).all()
            and clip > 0 and math.isfinite(epsilon) and epsilon >= 0):
        raise CheckpointError(f"VecNormalize statistics {str(path)!r} hold non-finite or "
                              "negative values")
    return ObsNormalization(mean, var, clip, epsilon, bool(record.get("norm_obs", True)))


def zip_normalization(path: Path, data: dict[str, Any],
                      obs_shape: tuple[int, ...]) -> ObsNormalization | None:
    """The observation statistics a zip needs, or None when it was not trained under
    ``VecNormalize``. An on-policy algorithm's zip records ``_last_original_obs`` only under
    it; an off-policy one (DQN, QRDQN) always does, so its statistics are applied when they
    are beside it and cannot be asked for.

    Raises:
        CheckpointError: trained under ``VecNormalize`` and no readable statistics beside it
            (the message names the file expected and how to write it).
    """
    stats = normalization_path(path)
    off_policy = "learning_starts" in data
    if off_policy or data.get("_last_original_obs") is None:
        return _read(stats, obs_shape) if stats.is_file() else None
    if not stats.is_file():
        raise CheckpointError(
            f"SB3 zip {str(path)!r} was trained under VecNormalize, and its statistics "
            f"{str(stats)!r} are missing: the policy would see raw planes instead of the "
            "normalised ones it learnt on. Write them with baselines.sb3.normalization."
            "save_vec_normalize(model.get_vec_normalize_env(), PATH.zip), or train with "
            "norm_obs=False")
    return _read(stats, obs_shape)
