"""Validated configuration shared by the workspace's nodes (ROS-free except :mod:`cnr_params.ros`, which reads a node's private namespace)."""
from cnr_params.config import (ConfigError, Section, load_yaml, exit_on_config_error)  # noqa: F401
