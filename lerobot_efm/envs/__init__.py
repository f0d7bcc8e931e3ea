"""Environments of the plugin; importing this package registers them with gymnasium and LeRobot.

Neither module imports MuJoCo at import time (the Talos kitchen does when an env is built)."""

from .planar_push import PlanarPushEnv, PlanarPushEnvConfig
from .point_reach import GYM_ID as POINT_REACH_GYM_ID
from .point_reach import PointReachEnv, PointReachEnvConfig
from .talos_kitchen.env import GYM_ID as TALOS_KITCHEN_GYM_ID
from .talos_kitchen.env import TalosKitchenEnv, TalosKitchenEnvConfig

__all__ = [
    "PlanarPushEnv",
    "PlanarPushEnvConfig",
    "POINT_REACH_GYM_ID",
    "PointReachEnv",
    "PointReachEnvConfig",
    "TALOS_KITCHEN_GYM_ID",
    "TalosKitchenEnv",
    "TalosKitchenEnvConfig",
]
