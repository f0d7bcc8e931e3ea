"""Extremum Flow Matching for LeRobot: the ``efm_gc``, ``efm_ac``, ``efm_pc``, ``efm_ps`` and ``efm_as``
policies, hindsight-goal datasets and goal-reaching environments.

Importing this package registers the policy types with LeRobot (and is what LeRobot's plugin discovery
does through the ``lerobot_policy_efm`` distribution).
"""

from . import (  # noqa: F401 (envs, ogbench, robots register their types; lazy simulators)
    envs,
    ogbench,
    robots,
    train_hook,
)
from .configuration_efm import EFMACConfig, EFMASConfig, EFMConfig, EFMGCConfig, EFMPCConfig, EFMPSConfig
from .hindsight import HindsightGoalDataset, HindsightSpec
from .processor_efm import make_efm_pre_post_processors

train_hook.install()

__all__ = [
    "EFMConfig",
    "EFMGCConfig",
    "EFMACConfig",
    "EFMPCConfig",
    "EFMPSConfig",
    "EFMASConfig",
    "HindsightGoalDataset",
    "HindsightSpec",
    "make_efm_pre_post_processors",
]
