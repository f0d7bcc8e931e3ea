"""Planar push in a maze (MuJoCo): :mod:`.maze` geometry and shortest paths, :mod:`.env` the gym env and the
LeRobot ``planar_push`` env type, :mod:`.demonstrators` the scripted operators and dataset recorder.

Importing this package registers the env but does not import MuJoCo (that happens when an env is built)."""

from .env import GYM_ID, PlanarPushEnv, PlanarPushEnvConfig

__all__ = ["GYM_ID", "PlanarPushEnv", "PlanarPushEnvConfig"]
