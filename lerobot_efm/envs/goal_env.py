"""What this plugin's goal-reaching environments share on the LeRobot side: goal images reach the policy
like camera images, and each env has one gym id (the task name travels in ``gym_kwargs``)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import torch

from lerobot.configs import PipelineFeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.processor import ObservationProcessorStep, PolicyProcessorPipeline


@dataclass
class GoalImagesChannelFirstStep(ObservationProcessorStep):
    """Make ``observation.goal.images.*`` look like camera images: (B, 3, H, W) float in [0, 1].

    ``preprocess_observation`` only converts the ``pixels`` entry; other arrays (our goal image)
    pass through as float (B, H, W, 3) in [0, 255].
    """

    prefix: str = "observation.goal.images."

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
