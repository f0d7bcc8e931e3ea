"""Pre/post-processors of the EFM policies: LeRobot's default pipeline (rename, batch, device,
normalise; unnormalise, cpu) with the goal keys normalised by the statistics of the observation they
mirror (``observation.goal.state`` uses the stats of ``observation.state``, and so on)."""

from __future__ import annotations

from typing import Any

import torch

from lerobot.processor import PolicyAction, PolicyProcessorPipeline, make_default_pre_post_processors

from .configuration_efm import MIRROR_PREFIXES, EFMConfig, is_mirror_key, mirror_key


def mirror_stats(stats: dict[str, dict[str, Any]] | None) -> dict[str, dict[str, Any]] | None:
    """Add, for every ``observation.<key>`` statistic, the same statistic under each mirrored key
    (goal, RL goal, observation trajectory), so the stock normaliser treats goals like observations."""
    if stats is None:
        return None
    mirrored = dict(stats)
    for key, value in stats.items():
        if key.startswith("observation.") and not is_mirror_key(key):
            for prefix in MIRROR_PREFIXES:
                mirrored.setdefault(mirror_key(key, prefix), value)
    return mirrored


def make_efm_pre_post_processors(
    config: EFMConfig,
    dataset_stats: dict[str, dict[str, torch.Tensor]] | None = None,
) -> tuple[
    PolicyProcessorPipeline[dict[str, Any], dict[str, Any]],
    PolicyProcessorPipeline[PolicyAction, PolicyAction],
]:
    # The goal features must be part of the config before the normaliser reads them.
    config.add_mirror_features()
    return make_default_pre_post_processors(config, mirror_stats(dataset_stats))


# LeRobot resolves processors by policy type: make_<type>_pre_post_processors in the processor_ module.
make_efm_gc_pre_post_processors = make_efm_pre_post_processors
make_efm_ac_pre_post_processors = make_efm_pre_post_processors
make_efm_pc_pre_post_processors = make_efm_pre_post_processors
make_efm_ps_pre_post_processors = make_efm_pre_post_processors
make_efm_as_pre_post_processors = make_efm_pre_post_processors
