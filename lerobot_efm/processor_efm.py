"""Pre/post-processors of the EFM policies: LeRobot's default pipeline (rename, batch, device,
normalise; unnormalise, cpu) with the goal keys batched like, and normalised by the statistics of, the
observation they mirror (``observation.goal.state`` uses the stats of ``observation.state``, and so on)."""

from __future__ import annotations

import logging
from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from lerobot.configs import PipelineFeatureType, PolicyFeature
from lerobot.processor import (
    ObservationProcessorStep,
    PolicyAction,
    PolicyProcessorPipeline,
    ProcessorStepRegistry,
)
from lerobot.processor.factory import make_default_policy_processor_steps, make_policy_processor_pipelines

from .configuration_efm import GOAL_PREFIX, MIRROR_PREFIXES, EFMConfig, is_mirror_key, mirror_key
from .goal_source import deploy_goal, fit_live_images

GOAL_BATCH_STEP = "efm_goal_batch_processor"
# A feature that never changed in the recording (e.g. an object nobody touched during hand-only play) has a zero
# range, which LeRobot's normaliser replaces by eps = 1e-8: a 4 mm nudge at deployment then reads as 4e5. Such a
# feature is only centred instead (range 2, i.e. scale 1).
CONSTANT_RANGE = 1e-6


@dataclass
@ProcessorStepRegistry.register(name=GOAL_BATCH_STEP)
class AddBatchDimensionToGoalsStep(ObservationProcessorStep):
    """Adds the batch dimension to the goal keys (``observation.goal.state``, ``observation.goal.images.*``),
    which LeRobot's batch step leaves alone: it only knows ``observation.state`` and ``observation.images.*``.
    An unbatched robot observation then reaches the policy with its goal batched the same way.

    A robot's observation has no goal at all: when the deployed policy was given one (``--policy.goal_path`` or
    ``--policy.goal_dataset_root``, see :mod:`lerobot_efm.goal_source`), it is inserted here, before the device
    step and the normaliser, and camera frames of another resolution than the checkpoint's are resized. The step
    is saved in every checkpoint's pipeline, so old checkpoints get both too."""

    def observation(self, observation: dict[str, Any]) -> dict[str, Any]:
        observation = fit_live_images(dict(observation))
        goal = deploy_goal()
        missing = [k for k in goal if k not in observation]
        if missing:
            batch = _batch_size(observation)
            for key in missing:
                value = goal[key]
                observation[key] = value if batch is None else value.unsqueeze(0).expand(batch, *value.shape)
        for key, value in observation.items():
            if (
                isinstance(value, torch.Tensor)
                and key.startswith(GOAL_PREFIX)
                and value.dim() == _unbatched_rank(key)
            ):
                observation[key] = value.unsqueeze(0)
        return observation

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        return features


def _unbatched_rank(key: str) -> int:
    return 3 if ".images." in key else 1  # (C, H, W) images, (D,) vectors


def _batch_size(observation: dict[str, Any]) -> int | None:
    """Batch size of a batched observation (from its state or first image), None when unbatched."""
    for key, value in observation.items():
        if key == "observation.state" or key.startswith("observation.images."):
            return int(value.shape[0]) if value.dim() == _unbatched_rank(key) + 1 else None
    return None


def widen_constant_features(stats: dict[str, dict[str, Any]] | None) -> dict[str, dict[str, Any]] | None:
    """Statistics in which every constant dimension (max - min or std under CONSTANT_RANGE) gets min/max = value
    -/+ 1 and std = 1, with a warning naming it: the normaliser then centres it instead of dividing by eps."""
    if stats is None:
        return None
    out = {}
    for key, entry in stats.items():
        entry = dict(entry)
        if "min" in entry and "max" in entry:
            lo, hi = (np.asarray(entry[k], dtype=np.float64) for k in ("min", "max"))
            flat = (hi - lo) < CONSTANT_RANGE
            if flat.any():
                centre = (lo + hi) / 2
                entry["min"] = _like(entry["min"], np.where(flat, centre - 1.0, lo))
                entry["max"] = _like(entry["max"], np.where(flat, centre + 1.0, hi))
            if flat.any() and (key == "action" or key.startswith("observation.")) and not is_mirror_key(key):
                logging.warning(
                    "%s: dimension(s) %s never change in the dataset (range 0); normalised as value "
                    "minus %s instead of divided by 1e-8",
                    key,
                    np.flatnonzero(flat).tolist(),
                    np.round(centre[flat], 4).tolist(),
                )
        if "std" in entry:
            std = np.asarray(entry["std"], dtype=np.float64)
            if (std < CONSTANT_RANGE).any():
                entry["std"] = _like(entry["std"], np.where(std < CONSTANT_RANGE, 1.0, std))
        out[key] = entry
    return out


def _like(reference: Any, values: np.ndarray) -> Any:
    """``values`` in the container type and dtype of ``reference`` (tensor, array or list)."""
    if isinstance(reference, torch.Tensor):
        return torch.as_tensor(values, dtype=reference.dtype)
    if isinstance(reference, np.ndarray):
        return values.astype(reference.dtype)
    return values.tolist()


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
    s = make_default_policy_processor_steps(config, mirror_stats(widen_constant_features(dataset_stats)))
    return make_policy_processor_pipelines(
        input_steps=[
            s.rename_observations,
            s.add_batch_dim,
            AddBatchDimensionToGoalsStep(),
            s.to_device,
            s.normalize,
        ],
        output_steps=[s.unnormalize, s.to_cpu],
    )


# LeRobot resolves processors by policy type: make_<type>_pre_post_processors in the processor_ module.
make_efm_gc_pre_post_processors = make_efm_pre_post_processors
make_efm_ac_pre_post_processors = make_efm_pre_post_processors
make_efm_pc_pre_post_processors = make_efm_pre_post_processors
make_efm_ps_pre_post_processors = make_efm_pre_post_processors
make_efm_as_pre_post_processors = make_efm_pre_post_processors
