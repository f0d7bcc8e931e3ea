"""Auxiliary state loss: a recorded vector the policy does not see, regressed from the latent while training."""

import pytest
import torch
from conftest import tiny_config
from lerobot.configs.types import FeatureType, PolicyFeature

from lerobot_efm.auxiliary import AuxiliaryStateHead
from lerobot_efm.hindsight import HindsightGoalDataset
from lerobot_efm.modeling_efm import EFMPolicy

IMAGE, STATE = "observation.images.top", "observation.state"
GOAL_STATE = "observation.goal.state"


def _image_only_config(**overrides):
    """A camera-only FM-AC that learns the point's recorded state as its auxiliary target."""
    return tiny_config(
        "efm_ac",
        input_features={IMAGE: PolicyFeature(type=FeatureType.VISUAL, shape=(3, 32, 32))},
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(2,))},
        **{"image_encoder_dropout": 0.0, "auxiliary_state_key": STATE, **overrides},
    )


def _batch(dataset, indices):
    items = [dataset[i] for i in indices]
    return {
        k: torch.stack([it[k] for it in items]) for k, v in items[0].items() if isinstance(v, torch.Tensor)
    }


def test_hindsight_rows_carry_the_auxiliary_state_of_observation_and_goal(video_dataset):
    data = HindsightGoalDataset(video_dataset, _image_only_config())
    torch.manual_seed(0)
    item = data[10]
    d = int(item["observation.goal_distance"])
    assert torch.equal(item[STATE], data.vectors[STATE][10])
    assert torch.equal(item[GOAL_STATE], data.vectors[STATE][10 + d])


def test_auxiliary_loss_teaches_the_image_encoder_the_state(video_dataset):
    """Only the auxiliary loss trains: the encoder must learn to read the point's position from the image
    (a frozen encoder, or a loss on the observation alone, cannot fit the goal's state)."""
    torch.manual_seed(0)
    policy = EFMPolicy(_image_only_config(), dataset_stats=video_dataset.meta.stats)
    assert policy.config.auxiliary_state_dim == 2  # read from the statistics, saved with the config
    agent = policy.model
    data = HindsightGoalDataset(video_dataset, policy.config)
    batch = _batch(data, range(0, 96, 2))
    optim = torch.optim.Adam(agent.parameters(), lr=3e-3)

    def loss():
        latents = agent.encode(batch, ("observation.", "observation.goal."))
        return agent.auxiliary_state_loss(batch, tuple(latents))

    with torch.no_grad():
        start = loss().item()
    for _ in range(150):
        optim.zero_grad()
        value = loss()
        value.backward()
        optim.step()
    assert value.item() < 0.1 * start, (start, value.item())
    # the policy's training loss includes it
    optim.zero_grad()
    total, info = agent.compute_loss(batch, policy.ema_model)
    total.backward()
    assert "loss_auxiliary_state" in info
    assert all(p.grad is not None and p.grad.abs().sum() > 0 for p in agent.auxiliary_head.parameters())


def test_targets_are_scaled_to_the_recording_range_and_constant_dimensions_centred():
    head = AuxiliaryStateHead(4, 3, low=torch.tensor([0.0, -2.0, 5.0]), high=torch.tensor([1.0, 2.0, 5.0]))
    scaled = head.scale(torch.tensor([[0.0, -2.0, 5.0], [1.0, 2.0, 6.0]]))
    assert torch.allclose(scaled, torch.tensor([[-1.0, -1.0, 0.0], [1.0, 1.0, 1.0]]))


def test_checkpoint_loads_without_the_dataset_statistics(video_dataset, tmp_path):
    policy = EFMPolicy(_image_only_config(), dataset_stats=video_dataset.meta.stats)
    policy.save_pretrained(tmp_path)
    loaded = EFMPolicy.from_pretrained(tmp_path)
    assert loaded.config.auxiliary_state_dim == 2
    assert torch.equal(loaded.model.auxiliary_head.centre, policy.model.auxiliary_head.centre)


def test_bad_auxiliary_settings_name_the_key(video_dataset):
    with pytest.raises(ValueError, match="auxiliary_state_key='action'"):
        _image_only_config(auxiliary_state_key="action")
    with pytest.raises(ValueError, match="already an input"):
        EFMPolicy(
            tiny_config(
                "efm_ac",
                input_features={STATE: PolicyFeature(type=FeatureType.STATE, shape=(2,))},
                output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(2,))},
                auxiliary_state_key=STATE,
            )
        )
    with pytest.raises(KeyError, match="observation.environment_state"):
        EFMPolicy(
            _image_only_config(auxiliary_state_key="observation.environment_state"),
            dataset_stats=video_dataset.meta.stats,
        )
    with pytest.raises(ValueError, match="needs the dataset statistics"):
        EFMPolicy(_image_only_config())
