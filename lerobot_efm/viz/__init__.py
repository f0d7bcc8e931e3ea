"""Rerun visualisation of EFM policy rollouts and hindsight-goal samples, written to ``.rrd`` files.

* :mod:`lerobot_efm.viz.rollout_log`: :class:`RolloutLogger` logs episodes (cameras, goals, the agent's
  3-D trajectory, predicted action chunks, critic distances, candidates, planned observations).
* :mod:`lerobot_efm.viz.dataset_log`: logs sampled :class:`~lerobot_efm.hindsight.HindsightGoalDataset` tuples.
* :mod:`lerobot_efm.viz.env_viz`: how an env is drawn (:class:`EnvViz`, :func:`register_env_viz`; each env keeps
  its own next to it, ``envs/<env>/viz.py``; :func:`hand_points` builds one for arms).
* :mod:`lerobot_efm.viz.unnormalize`: model-space tensors back to the env's units (LeRobot's unnormaliser).
* :func:`read_rrd` (:mod:`lerobot_efm.viz.rrd`): reads an ``.rrd`` file back (rerun's own reader).
"""

from .env_viz import EnvViz, get_env_viz, hand_points, register_env_viz
from .rollout_log import RolloutLogger
from .rrd import read_rrd

__all__ = ["EnvViz", "RolloutLogger", "get_env_viz", "hand_points", "read_rrd", "register_env_viz"]
