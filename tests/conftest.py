"""Shared fixtures: small, fast configurations of the simulator."""

from __future__ import annotations

import numpy as np
import pytest

from ipp_toolkit.config import EnvConfig


def small_config(n_agents: int = 4, comm_range: float = 25.0, resolution: float = 0.5,
                 **sections) -> EnvConfig:
    """The paper's world at a coarse map resolution (100 x 100 cells), for fast tests."""
    start = "fixed" if n_agents in (2, 4, 8) else "random"
    config = EnvConfig().replace(world={"resolution": resolution},
                                 features={"agent_id_scale": max(8, n_agents)},
                                 team={"n_agents": n_agents, "comm_range": comm_range,
                                       "start": start})
    return config.replace(**sections) if sections else config


@pytest.fixture
def config() -> EnvConfig:
    return small_config()


def random_valid_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) one uniformly drawn valid action per row of an (N, 6) mask."""
    return np.array([rng.choice(np.flatnonzero(row)) for row in masks])
