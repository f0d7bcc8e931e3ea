"""``--policy.image_crop``: the policy takes one region of the camera, cropped before the resize, the same region
in training (decoded or cached frames) and at deployment (live frames, goal images that come with them or from a
dataset frame)."""

import pytest
import torch
from conftest import tiny_config
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.factory import make_policy, make_pre_post_processors
from test_goal_source import deploy
from test_hindsight import spec

from lerobot_efm.frames import fit_frames
from lerobot_efm.goal_source import read_dataset_frame, set_deploy_goal, to_goal_keys
from lerobot_efm.hindsight import HindsightGoalDataset

KEY = "observation.images.top"
CROP = (0.25, 0.5, 0.5, 0.5)  # rows 8-24, columns 16-32 of the 32x32 recording
SHAPE = (3, 8, 8)  # the policy's image size: 2x2 box averages of the 16x16 region


def crop_config(**overrides):
    """A tiny FM-AC taking the crop at 8x8 (the image size must be given: see the refusal test below)."""
    features = {
        KEY: PolicyFeature(FeatureType.VISUAL, SHAPE),
        "observation.state": PolicyFeature(FeatureType.STATE, (2,)),
    }
    return tiny_config("efm_ac", input_features=features, image_crop=list(CROP), **overrides)


def deployed_crop_policy(video_dataset, tmp_path):
    """A checkpoint of the untrained crop policy, loaded back as lerobot-rollout does: (policy, pre-processor)."""
    cfg = crop_config()
    wrapped = HindsightGoalDataset(video_dataset, cfg)
    policy = make_policy(cfg, ds_meta=wrapped.meta)
    pre, post = make_pre_post_processors(cfg, dataset_stats=wrapped.meta.stats)
    path = tmp_path / "pretrained_model"
    for part in (policy, pre, post):
        part.save_pretrained(path)
    policy, pre, _ = deploy(path)
    return policy, pre


@pytest.fixture(autouse=True)
def _no_goal_left_behind():
    yield
    set_deploy_goal(None)


def region_box_average(frame: torch.Tensor) -> torch.Tensor:
    """The crop's 16x16 region of a 32x32 frame as 2x2 box averages (8x8), computed by hand."""
    return frame[:, 8:24, 16:32].reshape(3, 8, 2, 8, 2).mean((2, 4))


def test_training_frames_are_the_crop_region_resized(video_dataset):
    keys = dict(
        observation_keys=(KEY, "observation.state"), image_shapes=((KEY, (3, 8, 8)),), image_crop=CROP
    )
    plain = HindsightGoalDataset(video_dataset, spec(**keys))
    cached = HindsightGoalDataset(video_dataset, spec(**keys, cache_frames=True))
    expected = region_box_average(video_dataset[5][KEY])
    torch.manual_seed(0)
    a = plain[5][KEY]
    torch.manual_seed(0)
    b = cached[5][KEY]
    assert a.shape == b.shape == (3, 8, 8)
    assert torch.allclose(a, expected, atol=1e-5)
    assert torch.allclose(b, expected, atol=0.5 / 255 + 1e-6)  # the cache keeps uint8


def test_a_deployed_policy_crops_live_frames_and_goal_images_as_in_training(video_dataset, tmp_path):
    """A checkpoint trained on the crop gets the same crop of a camera at twice the recording's resolution."""
    policy, pre = deployed_crop_policy(video_dataset, tmp_path)
    camera, goal = torch.rand(2, 1, 3, 64, 64)
    processed = pre(
        {
            "observation.state": torch.zeros(1, 2),
            KEY: camera,
            "observation.goal.images.top": goal,
            "observation.goal.state": torch.zeros(1, 2),
        }
    )
    assert torch.allclose(processed[KEY][0], fit_frames(camera, SHAPE, CROP)[0], atol=1e-6)
    assert torch.allclose(processed["observation.goal.images.top"][0], fit_frames(goal, SHAPE, CROP)[0])
    assert not torch.allclose(processed[KEY][0], fit_frames(camera, SHAPE)[0], atol=0.05)
    assert policy.select_action(processed).shape == (1, 2)


def test_training_batches_are_not_cropped_twice(video_dataset, tmp_path):
    """lerobot-train runs the same pre-processor on batches the hindsight dataset has cropped and resized already:
    frames at the policy's size pass through it unchanged."""
    cfg = crop_config()
    wrapped = HindsightGoalDataset(video_dataset, cfg)  # built before the policy, as lerobot-train does
    make_policy(cfg, ds_meta=wrapped.meta)
    pre, _ = make_pre_post_processors(cfg, dataset_stats=wrapped.meta.stats)
    item = wrapped[5]
    assert torch.allclose(item[KEY], region_box_average(video_dataset[5][KEY]), atol=0.5 / 255 + 1e-6)
    batch = {k: v.unsqueeze(0) for k, v in item.items() if isinstance(v, torch.Tensor)}
    processed = pre(batch)
    for key in (KEY, "observation.goal.images.top"):
        assert processed[key].shape == (1, *SHAPE)
        assert torch.equal(processed[key][0], item[key]), key


def test_a_goal_from_a_dataset_frame_is_cropped(video_dataset_root):
    frame = read_dataset_frame(video_dataset_root, episode=1, frame=-1)
    features = {"observation.goal.images.top": PolicyFeature(FeatureType.VISUAL, SHAPE)}
    goal = to_goal_keys(frame, features, CROP)["observation.goal.images.top"]
    assert torch.allclose(goal, region_box_average(frame[KEY]), atol=1e-5)


@pytest.mark.parametrize("crop", [(0.5, 0.0, 0.6, 0.5), (0.0, 0.0, 0.5), (0.1, -0.1, 0.5, 0.5), (0, 0, 0, 1)])
def test_a_crop_outside_the_frame_is_refused_by_name(crop):
    with pytest.raises(ValueError, match="image_crop="):
        tiny_config("efm_ac", image_crop=list(crop))


def test_a_crop_without_the_policy_image_size_is_refused(video_dataset):
    with pytest.raises(ValueError, match=r"image_crop=.*observation.images.top.*input_features"):
        HindsightGoalDataset(video_dataset, tiny_config("efm_ac", image_crop=list(CROP)))


def test_a_camera_too_small_for_the_crop_is_warned_about_once(video_dataset, tmp_path, caplog):
    """A crop region smaller than the policy's input is upsampled (detail the policy never saw): the user is told
    to raise the camera's resolution; a camera large enough is not warned about."""
    _, pre = deployed_crop_policy(video_dataset, tmp_path)

    def frames_of(size: int) -> dict:
        return {"observation.state": torch.zeros(1, 2), KEY: torch.rand(1, 3, size, size)}

    with caplog.at_level("WARNING", logger="lerobot_efm.goal_source"):
        pre(frames_of(32))  # the crop is 16x16, twice the policy's 8x8
        assert "smaller than the checkpoint's" not in caplog.text
        pre(frames_of(12))  # the crop is 6x6
        pre(frames_of(12))
    warnings = [r for r in caplog.records if "smaller than the checkpoint's" in r.getMessage()]
    assert len(warnings) == 1 and "(6, 6)" in warnings[0].getMessage()
