"""Readers and writers of data files: MATLAB (IK data-set layout), HuG-MP, joint-angle recordings,
simulation configs.

This face holds what other families use; they import the family through it only."""

from .joint_angles import JointRecording as JointRecording
from .simulation_config import CONFIG_HELP as CONFIG_HELP
from .simulation_config import ConfigError as ConfigError
from .simulation_config import build_simulation as build_simulation
from .simulation_config import read_config as read_config
