"""The random baseline: every UAV draws one of its valid actions uniformly at random."""

from __future__ import annotations

import numpy as np

from ipp_toolkit.config.schema import EnvConfig
from ipp_toolkit.planning import AgentView, Planner

__all__ = ["RandomPlanner"]


class RandomPlanner(Planner):
    """Uniform random choice among each UAV's valid actions.

    The stream is ``np.random.default_rng(seed)`` from :meth:`reset`, so a mission replays
    exactly under the same seed. One (N, 6) draw per step keeps it vectorised: the argmax of
    uniform scores restricted to the valid actions is uniform over them.
    """

    name = "random"
    needs_observations = False
    needs_local_maps = False

    def __init__(self) -> None:
        # Usable without reset (seed 0); reset() reseeds for every mission.
        self._rng = np.random.default_rng(0)

    def reset(self, config: EnvConfig, seed: int) -> None:
        """Reseed the action stream for a new mission."""
        self._rng = np.random.default_rng(seed)

    def act(self, views: list[AgentView]) -> np.ndarray:
        """(N,) int64 actions, each uniform over its view's valid actions."""
        masks = np.stack([view.mask for view in views]).astype(bool)  # (N, 6)
        if not masks.any(axis=1).all():
            raise ValueError("an agent has no valid action")
        # Scores in [1, 2) on valid actions and 0 on masked ones: the argmax is a uniform
        # valid action (ties among valid scores have probability zero).
        scores = (1.0 + self._rng.random(masks.shape)) * masks
        return scores.argmax(axis=1).astype(np.int64)
