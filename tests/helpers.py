"""Helpers the test modules import (``from helpers import small_config``): small, fast
configurations of the simulator and of COMA training, random valid actions, and the page
faults of a process set up by some code. Fixtures live in conftest.py."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from coma.config import COMAConfig
from ipp_toolkit.config.schema import EnvConfig, start_for_team_size


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


def tiny_coma(**changes) -> COMAConfig:
    """COMA networks and a schedule small enough for a test: two updates of two missions."""
    values = dict(width=8, hidden=16, missions=4, missions_per_update=2, minibatch_size=40,
                  epochs=1, eval_every=1, eval_missions=2, checkpoint_every=1,
                  target_update_transitions=100, warm_start="")
    values.update(changes)
    return COMAConfig(**values)


def tiny_env(n_agents: int = 2) -> EnvConfig:
    """A mission for :func:`tiny_coma`: 2 UAVs, 4 steps, 1 m cells."""
    return small_config(n_agents=n_agents, resolution=1.0, team={"budget": 4})


def random_valid_actions(masks: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N,) one uniformly drawn valid action per row of an (N, 6) mask."""
    return np.array([rng.choice(np.flatnonzero(row)) for row in masks])


_CHURN = """
import resource
import numpy as np
def churn():
    planes = np.ones((3000, 17, 11, 11), np.float32)
    activation = np.ones((600, 64, 7, 7), np.float32)
    gradient = np.ones((600, 64, 4, 4), np.float32)
    del planes, activation, gradient
churn()
before = resource.getrusage(resource.RUSAGE_SELF).ru_minflt
for _ in range(10):
    churn()
print(resource.getrusage(resource.RUSAGE_SELF).ru_minflt - before)
"""


def page_faults_of_reallocation(setup: str = "") -> int:
    """Page faults of a fresh interpreter that runs ``setup`` (Python code), then frees and
    allocates again ten times arrays the size of a rollout's planes, an activation and a
    gradient (25, 7.5 and 2.5 MB): about 0 where freed memory is kept for reuse
    (:func:`ipp_toolkit.runs.process_pool.retain_freed_memory`), about 1,800 with glibc's defaults.
    """
    done = subprocess.run([sys.executable, "-c", setup + "\n" + _CHURN], capture_output=True,
                          text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-2000:]
    return int(done.stdout.split()[-1])


def zero_residual_coma(path) -> str:
    """A gain-prior COMA policy at its untrained start on ``ig_learned``'s planes (the learned
    prior with the false-positive term in the last 10 steps), saved at ``path``: its greedy
    choice is the planes' best option, so the ``coma`` planner flying it must fly
    ``ig_learned``'s choices. Returns the path as a string."""
    import torch

    from coma.config import preset
    from coma.persistence import build_networks, save_policy

    coma_config = preset("cpu", warm_start="", gain_prior=50.0)
    env = EnvConfig().replace(world={"resolution": 0.5}, terrain={"kind": "mixture"},
                              features={"own_position": True, "gain": True,
                                        "gain_interest": "learned",
                                        "gain_false_positive": 0.5,
                                        "gain_false_positive_steps": 10})
    torch.manual_seed(0)
    save_policy(path, build_networks(coma_config, env))
    return str(path)
