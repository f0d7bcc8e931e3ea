"""Random-shift augmentation: each image a shifted copy of itself, only while training, goal images too."""

import pytest
import torch
import torch.nn.functional as F
from conftest import tiny_config
from lerobot.configs.types import FeatureType, PolicyFeature

from lerobot_efm.agents import make_agent
from lerobot_efm.augment import random_shift

IMAGE = "images.top"


def _offset_of(shifted: torch.Tensor, image: torch.Tensor, pad: int) -> tuple[int, int] | None:
    """The (row, col) crop of the edge-padded ``image`` that equals ``shifted``, None if there is none."""
    padded = F.pad(image[None], (pad, pad, pad, pad), mode="replicate")[0]
    h, w = image.shape[-2:]
    for dy in range(2 * pad + 1):
        for dx in range(2 * pad + 1):
            if torch.equal(padded[:, dy : dy + h, dx : dx + w], shifted):
                return dy, dx
    return None


def test_random_shift_is_a_per_image_crop_of_the_edge_padded_image():
    g = torch.Generator().manual_seed(0)
    images = torch.rand(2, 8, 3, 12, 10, generator=g)
    out = random_shift(images, pad=2, generator=torch.Generator().manual_seed(1))
    assert out.shape == images.shape
    offsets = [_offset_of(s, i, 2) for s, i in zip(out.flatten(0, 1), images.flatten(0, 1), strict=True)]
    assert None not in offsets
    assert len(set(offsets)) > 3, "every image must draw its own shift"
    assert torch.equal(random_shift(images, pad=0), images)


def _image_config(shift: int):
    return tiny_config(
        "efm_ac",
        input_features={"observation." + IMAGE: PolicyFeature(type=FeatureType.VISUAL, shape=(3, 8, 8))},
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(2,))},
        image_random_shift=shift,
        image_encoder_dropout=0.0,
    )


@pytest.mark.parametrize("shift", [0, 2])
def test_agent_shifts_observation_and_goal_images_only_while_training(shift):
    cfg = _image_config(shift)
    agent = make_agent(cfg)
    g = torch.Generator().manual_seed(0)
    batch = {p + IMAGE: torch.rand(4, 3, 8, 8, generator=g) for p in ("observation.", "observation.goal.")}
    prefixes = ("observation.", "observation.goal.")

    agent.train()
    torch.manual_seed(0)
    trained = agent.augment_images(batch, prefixes)
    for key, image in batch.items():
        changed = not torch.equal(trained[key], image)
        assert changed == (shift > 0), key
        if shift:
            assert all(_offset_of(s, i, shift) for s, i in zip(trained[key], image, strict=True)), key
    agent.eval()
    assert all(torch.equal(agent.augment_images(batch, prefixes)[k], v) for k, v in batch.items())


def test_negative_shift_is_refused_by_name():
    with pytest.raises(ValueError, match="image_random_shift=-1"):
        _image_config(-1)
