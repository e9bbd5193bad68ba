"""Helpers the test modules import (``from helpers import small_config``): small, fast
configurations of the simulator and random valid actions. Fixtures live in conftest.py."""

from __future__ import annotations

import numpy as np

from ipp_toolkit.config import EnvConfig, start_for_team_size


def small_config(n_agents: int = 4, comm_range: float = 25.0, resolution: float = 0.5,
                 **sections) -> EnvConfig:
    """The paper's world at a coarse map resolution (100 x 100 cells), for fast tests; fixed
    starts where the team size has them (2, 4, 8), random ones otherwise."""
    config = EnvConfig().replace(world={"resolution": resolution},
                                 features={"agent_id_scale": max(8, n_agents)})
    config = config.replace(team={"n_agents": n_agents, "comm_range": comm_range,
                                  "start": start_for_team_size("fixed", n_agents,
                                                               config.world)})
    return config.replace(**sections) if sections else config


def random_valid_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) one uniformly drawn valid action per row of an (N, 6) mask."""
    return np.array([rng.choice(np.flatnonzero(row)) for row in masks])
