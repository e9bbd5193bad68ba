"""ipp-toolkit: multi-UAV adaptive informative path planning with multi-agent RL.

The simulator and everything a planner or learner builds on; it imports none of them. Its
subpackages are its layers, and imports flow down this list only:

- :mod:`ipp_toolkit.config`: the mission's settings (dataclasses, YAML files, the builder);
- :mod:`ipp_toolkit.world`: terrains and their families, the camera, random streams;
- :mod:`ipp_toolkit.belief`: occupancy maps, entropy, expected gain, the prior of interest;
- :mod:`ipp_toolkit.sim`: the mission core (team rules, reset, step, driver), feature planes,
  rendering;
- :mod:`ipp_toolkit.env`, :mod:`ipp_toolkit.vec`, :mod:`ipp_toolkit.team_env` and
  :mod:`ipp_toolkit.uav_env`: the PettingZoo view, its SB3 view, the team as one Gymnasium
  agent and one UAV at a time as a Gymnasium agent (registered on import as
  ``ipp_toolkit/UAVTeam-v0`` and ``ipp_toolkit/UAV-v0``);
- :mod:`ipp_toolkit.planning`: the planner interface, the per-UAV view and the registry;
- :mod:`ipp_toolkit.runs`: the evaluation runner, result store, process pool and Ray backend.

``ipp_toolkit._native`` holds the compiled (Numba) inner loops, ``ipp_toolkit.io`` the files
that must never be half-written, ``ipp_toolkit.probability`` the log-odds and entropy of
one cell, ``ipp_toolkit.extras`` the import of an optional package (Ray, RLlib, TorchRL)
with its install command and ``ipp_toolkit.plugins`` the entry points the planner and terrain
registries read (``IPP_TOOLKIT_NO_PLUGINS=1``: the toolkit's own only); they are used at every
layer (``ipp_toolkit.io`` and ``ipp_toolkit.plugins`` import nothing of the toolkit). One
import still goes up the list, lazily: the config checks terrain names against the world's
terrain registry (:mod:`ipp_toolkit.world.registry`, which imports nothing of the toolkit
but ``ipp_toolkit.plugins``, so no import circle) when a config is built.
"""

from .config.files import load_config, save_config
from .config.schema import EnvConfig
from .env import IPPEnv, parallel_env
from .sim.mission import InvalidActionError, MissionState, reset_mission, step_mission
from .team_env import IPPTeamEnv, register_envs
from .uav_env import IPPUAVEnv

register_envs()  # gymnasium.make("ipp_toolkit/UAVTeam-v0" or "ipp_toolkit/UAV-v0")

# The one definition of the version: setup.cfg reads it (``attr:``), which needs a plain string
# literal here, as setuptools reads it from this file without importing the package.
__version__ = "0.1.0"

__all__ = [
    "EnvConfig",
    "IPPEnv",
    "IPPTeamEnv",
    "IPPUAVEnv",
    "InvalidActionError",
    "MissionState",
    "load_config",
    "parallel_env",
    "reset_mission",
    "save_config",
    "step_mission",
    "__version__",
]
