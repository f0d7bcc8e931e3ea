"""Simulated LeRobot robots and scripted teleoperators (registered on import), for hardware-free
``lerobot-record`` / ``lerobot-rollout`` runs."""

from .sim_planar_push import ScriptedPlanarPush, ScriptedPlanarPushConfig, SimPlanarPush, SimPlanarPushConfig

__all__ = ["ScriptedPlanarPush", "ScriptedPlanarPushConfig", "SimPlanarPush", "SimPlanarPushConfig"]
