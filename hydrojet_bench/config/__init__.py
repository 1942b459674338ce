"""The rig configuration: one typed tree for every profile table (`schema`) and its
loader (`loading`)."""

from .loading import PROFILES_DIR, config_from_mapping, convert, load_config, read_toml, resolve_profile_path
from .schema import PTY, SIM, RigConfig, SensorNoise

__all__ = ["PROFILES_DIR", "PTY", "SIM", "RigConfig", "SensorNoise", "config_from_mapping", "convert",
           "load_config", "read_toml", "resolve_profile_path"]
