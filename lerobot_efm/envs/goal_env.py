"""What this plugin's goal-reaching environments share on the LeRobot side: goal images reach the policy
like camera images, and each env has one gym id (the task name travels in ``gym_kwargs``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch
from lerobot.configs import FeatureType, PipelineFeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.processor import ObservationProcessorStep, PolicyProcessorPipeline
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from ..configuration_efm import GOAL_PREFIX, mirror_key

GOAL_STATE_KEY = "goal.state"  # env observation key; reaches the policy as observation.goal.state

# The goal observations a goal env returns, named as the hindsight wrapper names its goals (one source of truth).
OBS_GOAL_STATE = mirror_key(OBS_STATE, GOAL_PREFIX)
OBS_GOAL_ENV_STATE = mirror_key(OBS_ENV_STATE, GOAL_PREFIX)
OBS_GOAL_IMAGES = mirror_key(OBS_IMAGES, GOAL_PREFIX)


def goal_image_key(camera: str) -> str:
    return f"{OBS_GOAL_IMAGES}.{camera}"


@dataclass
class GoalImagesChannelFirstStep(ObservationProcessorStep):
    """Make ``observation.goal.images.*`` look like camera images: (B, 3, H, W) float in [0, 1].

    ``preprocess_observation`` only converts the ``pixels`` entry; other arrays (our goal image)
    pass through as float (B, H, W, 3) in [0, 255].
    """

    prefix: str = OBS_GOAL_IMAGES + "."

    def observation(self, observation):
        for key, img in list(observation.items()):
            if key.startswith(self.prefix) and isinstance(img, torch.Tensor) and img.shape[-1] == 3:
                img = img.unsqueeze(0) if img.ndim == 3 else img
                observation[key] = img.permute(0, 3, 1, 2).float().contiguous() / 255.0
        return observation

    def transform_features(
        self, features: dict[PipelineFeatureType, dict[str, PolicyFeature]]
    ) -> dict[PipelineFeatureType, dict[str, PolicyFeature]]:
        return features


class GoalEnvConfig(EnvConfig):
    """Base of the plugin's ``EnvConfig``s (not registered itself). Subclasses set ``GYM_ID`` and
    ``MODULE``, the module that registers ``GYM_ID`` (LeRobot imports it when the id is unknown)."""

    GYM_ID: ClassVar[str]
    MODULE: ClassVar[str]

    @property
    def package_name(self) -> str:
        return self.MODULE

    @property
    def gym_id(self) -> str:
        return self.GYM_ID

    def get_env_processors(self):
        pre = PolicyProcessorPipeline(steps=[GoalImagesChannelFirstStep()])
        return pre, PolicyProcessorPipeline(steps=[])


def state_goal_features(state_dim: int, action_dim: int) -> dict[str, PolicyFeature]:
    """``EnvConfig.features`` of an env observing ``agent_pos`` with a goal state of the same size."""
    return {
        ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(action_dim,)),
        "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(state_dim,)),
        GOAL_STATE_KEY: PolicyFeature(type=FeatureType.STATE, shape=(state_dim,)),
    }


def state_goal_features_map(camera: str) -> dict[str, str]:
    """``EnvConfig.features_map`` for :func:`state_goal_features` plus an optional camera and its goal image."""
    return {
        ACTION: ACTION,
        "agent_pos": OBS_STATE,
        GOAL_STATE_KEY: OBS_GOAL_STATE,
        f"{OBS_IMAGES}.{camera}": f"{OBS_IMAGES}.{camera}",  # identity: eval recording needs this form
        f"goal.images.{camera}": goal_image_key(camera),
    }


def add_camera_features(features: dict[str, PolicyFeature], camera: str, image_size: int) -> None:
    """Declare the camera ``camera`` and its goal image (square, ``image_size`` pixels)."""
    img = PolicyFeature(type=FeatureType.VISUAL, shape=(image_size, image_size, 3))
    features[f"{OBS_IMAGES}.{camera}"] = img
    features[f"goal.images.{camera}"] = img
