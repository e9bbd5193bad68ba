"""ipp-toolkit: multi-UAV adaptive informative path planning with multi-agent RL.

The simulator core (config, terrain, sensor, mapping, team, mission, features) and its
PettingZoo view (:class:`IPPEnv`). Learners, planners and reports build on this package;
it imports none of them.
"""

from .config import EnvConfig
from .config_io import load_config, save_config
from .env import IPPEnv, parallel_env
from .mission import InvalidActionError, MissionState, reset_mission, step_mission

__version__ = "0.1.0"

__all__ = [
    "EnvConfig",
    "IPPEnv",
    "InvalidActionError",
    "MissionState",
    "load_config",
    "parallel_env",
    "reset_mission",
    "save_config",
    "step_mission",
    "__version__",
]
