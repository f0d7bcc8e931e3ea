"""Rerun visualisation of EFM policy rollouts and hindsight-goal samples, written to ``.rrd`` files.

* :mod:`lerobot_efm.viz.rollout_log`: :class:`RolloutLogger` logs episodes (cameras, goals, the agent's
  3-D trajectory, predicted action chunks, critic distances, candidates, planned observations).
* :mod:`lerobot_efm.viz.dataset_log`: logs sampled :class:`~lerobot_efm.hindsight.HindsightGoalDataset` tuples.
* :func:`read_rrd`: reads an ``.rrd`` file back (rerun's own reader) as ``{entity_path: rows}``.

Env-specific geometry (which observation dims are a 3-D position) goes through :func:`register_env_viz`
(registered: ``efm_point_reach``, ``talos_kitchen``; :func:`hand_points` builds one for arms).
"""

from .rollout_log import EnvViz, RolloutLogger, get_env_viz, hand_points, read_rrd, register_env_viz

__all__ = ["EnvViz", "RolloutLogger", "get_env_viz", "hand_points", "read_rrd", "register_env_viz"]
