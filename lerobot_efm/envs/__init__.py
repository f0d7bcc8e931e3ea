"""Environments of the plugin; importing this package registers them with gymnasium and LeRobot."""

from .point_reach import GYM_ID as POINT_REACH_GYM_ID
from .point_reach import PointReachEnv, PointReachEnvConfig

__all__ = ["POINT_REACH_GYM_ID", "PointReachEnv", "PointReachEnvConfig"]
