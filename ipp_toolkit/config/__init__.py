"""Mission configuration: the dataclasses and their validation (:mod:`.schema`), YAML
files (:mod:`.files`) and the one builder from flags, files and keywords (:mod:`.settings`)."""

from .files import config_from_dict, config_to_dict, load_config, read_config_file, save_config
from .schema import (
    ACTOR_PLANES,
    EnvConfig,
    FeatureConfig,
    RewardConfig,
    SensorConfig,
    TeamConfig,
    TerrainConfig,
    WorldConfig,
)

__all__ = [
    "ACTOR_PLANES",
    "EnvConfig",
    "FeatureConfig",
    "RewardConfig",
    "SensorConfig",
    "TeamConfig",
    "TerrainConfig",
    "WorldConfig",
    "config_from_dict",
    "config_to_dict",
    "load_config",
    "read_config_file",
    "save_config",
]
