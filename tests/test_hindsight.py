"""Hindsight-goal relabelling (paper Sec. II-B) over the generated state and video LeRobot datasets."""

import pickle

import numpy as np
import pytest
import torch
from conftest import REPO_ID, tiny_config
from lerobot.datasets import video_utils
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from torch.utils.data import DataLoader

from lerobot_efm.hindsight import HindsightGoalDataset, HindsightSpec


def spec(**overrides) -> HindsightSpec:
    base = dict(
        obs_traj_len=3, obs_traj_stride=2, action_traj_len=8, action_traj_stride=1, max_goal_distance=10
    )
    return HindsightSpec(**{**base, **overrides})


def columns(dataset) -> dict[str, torch.Tensor]:
    """The dataset's rows read through LeRobot's own item access (independent of the wrapper's arrow reads)."""
    items = [dataset[i] for i in range(len(dataset))]
    return {
        k: torch.stack([torch.as_tensor(it[k]) for it in items])
        for k in ("observation.state", "action", "episode_index")
    }


@pytest.fixture(scope="module")
def rows(state_dataset):
    return columns(state_dataset)


def episode_end(episodes: torch.Tensor, k: int) -> int:
    """Exclusive end row of the episode holding row k."""
    return int(torch.nonzero(episodes == episodes[k]).max()) + 1


def test_goal_is_a_future_frame_of_the_same_episode(state_dataset, rows):
    """o_k is row k, g is row k+d of the same episode, 0 <= d <= min(L_g, frames left)."""
    wrapped = HindsightGoalDataset(state_dataset, tiny_config("efm_pc"))  # L_g = 40, episodes of 60
    assert wrapped.spec.max_goal_distance == 40
    for k in torch.randint(0, len(state_dataset), (300,)).tolist():
        item = wrapped[k]
        d = int(item["observation.goal_distance"])
        assert d == item["observation.goal_distance"] and 0 <= d <= min(
            40, episode_end(rows["episode_index"], k) - 1 - k
        )
        assert (
            rows["episode_index"][k + d] == rows["episode_index"][k] == item["episode_index"]
            and item["index"] == k
        )
        assert torch.equal(item["observation.state"], rows["observation.state"][k])
        assert torch.equal(item["observation.goal.state"], rows["observation.state"][k + d])


def test_goal_distance_covers_zero_to_min_of_horizon_and_frames_left(state_dataset):
    """d reaches every value of {0..min(L_g, left)} about uniformly, and never beyond the episode end."""
    wrapped = HindsightGoalDataset(state_dataset, spec(max_goal_distance=3))
    counts = np.bincount([int(wrapped[5]["observation.goal_distance"]) for _ in range(400)], minlength=4)
    assert len(counts) == 4 and counts.min() > 60, counts  # 100 expected each
    near_end = {
        int(wrapped[57]["observation.goal_distance"]) for _ in range(60)
    }  # 2 frames left in episode 0
    assert near_end == {0, 1, 2}
    assert {int(wrapped[59]["observation.goal_distance"]) for _ in range(20)} == {0}  # last frame


def test_observation_trajectory_is_clamped_at_the_goal(state_dataset, rows):
    """tau^o[j] is o at row k + min(j*S_o, d): it starts at o_k and stays on the goal once reached."""
    wrapped = HindsightGoalDataset(
        state_dataset, spec(obs_traj_len=4, obs_traj_stride=3, with_obs_trajectory=True)
    )
    clamped = 0
    for k in torch.randint(0, len(state_dataset), (150,)).tolist():
        item = wrapped[k]
        d = int(item["observation.goal_distance"])
        expected = rows["observation.state"][[k + min(j * 3, d) for j in range(4)]]
        assert torch.equal(item["observation.traj.state"], expected)
        clamped += d < 9
    assert clamped > 0  # the clamping was exercised


@pytest.mark.parametrize("stride", [1, 2])
@pytest.mark.parametrize("mode", ["absolute", "velocity"])
def test_action_chunk_past_the_goal_is_held_or_zero(state_dataset, rows, mode, stride):
    """tau^a[j] = a[k + j*S_a] before the goal; past it, a[k+d] (absolute) or exactly 0 (velocity)."""
    wrapped = HindsightGoalDataset(state_dataset, spec(action_traj_stride=stride, action_mode=mode))
    a, past = rows["action"], 0
    for k in torch.randint(0, len(state_dataset), (150,)).tolist():
        item = wrapped[k]
        d = int(item["observation.goal_distance"])
        assert item["action"].shape == (8, 2)
        for j in range(8):
            if j * stride < d:
                assert torch.equal(item["action"][j], a[k + j * stride])
            else:
                past += 1
                assert torch.equal(item["action"][j], a[k + d] if mode == "absolute" else torch.zeros(2))
    assert past > 0


def test_rl_goal_and_trajectory_keys_follow_the_agent(state_dataset, rows):
    """use_rl adds observation.rl_goal.* (a dataset row); FM-AC gets no observation.traj.* keys."""
    item = HindsightGoalDataset(state_dataset, tiny_config("efm_pc", use_rl=True))[3]
    assert any(torch.equal(item["observation.rl_goal.state"], s) for s in rows["observation.state"])
    assert "observation.traj.state" in item
    plain = HindsightGoalDataset(state_dataset, tiny_config("efm_ac"))[3]
    assert not any(k.startswith(("observation.rl_goal.", "observation.traj.")) for k in plain)
    with_rl = HindsightGoalDataset(state_dataset, spec(use_rl=True))
    rl_goals = {tuple(with_rl[3]["observation.rl_goal.state"].tolist()) for _ in range(20)}
    assert len(rl_goals) > 10  # drawn anew for each item, over the whole dataset


@pytest.fixture
def decode_counter(monkeypatch):
    """Records, per decode_video_frames call, how many timestamps were requested."""
    calls = []
    original = video_utils.decode_video_frames

    def counting(path, timestamps, *args, **kwargs):
        calls.append(len(timestamps))
        return original(path, timestamps, *args, **kwargs)

    monkeypatch.setattr(video_utils, "decode_video_frames", counting)
    return calls


def test_video_goal_frame_matches_the_dataset_frame(video_dataset):
    """Camera keys are (3, 32, 32) floats in [0, 1]; the goal image is the dataset's frame at row k+d."""
    wrapped = HindsightGoalDataset(video_dataset, tiny_config("efm_ac"))
    for k in (0, 12, 49, 63):
        item = wrapped[k]
        d = int(item["observation.goal_distance"])
        img = item["observation.images.top"]
        assert img.shape == (3, 32, 32) and img.dtype == torch.float32 and 0 <= img.min() and img.max() <= 1
        assert torch.allclose(img, video_dataset[k]["observation.images.top"], atol=1e-4)
        assert torch.allclose(
            item["observation.goal.images.top"], video_dataset[k + d]["observation.images.top"], atol=1e-4
        )
    assert not torch.allclose(wrapped[0]["observation.images.top"], wrapped[63]["observation.images.top"])


@pytest.mark.parametrize("policy_type", ["efm_ac", "efm_pc"])
def test_video_decodes_only_the_frames_it_uses(video_dataset, decode_counter, policy_type):
    """One decode call per item for o_k, g (and tau^o), asking for each distinct frame once."""
    wrapped = HindsightGoalDataset(video_dataset, tiny_config(policy_type))  # L_o = 3, S_o = 4
    for k in (0, 20, 47):
        decode_counter.clear()
        d = int(wrapped[k]["observation.goal_distance"])
        used = {k, k + d} | ({k + min(4 * j, d) for j in range(3)} if policy_type == "efm_pc" else set())
        assert decode_counter == [len(used)] and len(used) <= (2 if policy_type == "efm_ac" else 2 + 3)


def test_cached_frames_are_the_decoded_frames(video_dataset, decode_counter):
    """``cache_frames`` decodes every frame once, in order, then serves items without decoding: same images."""
    plain = HindsightGoalDataset(video_dataset, tiny_config("efm_pc"))
    decode_counter.clear()
    cached = HindsightGoalDataset(video_dataset, tiny_config("efm_pc", cache_frames=True))
    assert sum(decode_counter) == len(video_dataset)  # each frame once, at construction
    decode_counter.clear()
    for k in (0, 20, 47, 99):
        torch.manual_seed(k)
        a = plain[k]
        torch.manual_seed(k)
        b = cached[k]
        for key in ("observation.images.top", "observation.goal.images.top", "observation.traj.images.top"):
            assert torch.allclose(a[key], b[key], atol=1e-6), key
    assert len(decode_counter) == 4  # the plain wrapper's calls only


def test_frames_are_resized_to_the_policy_image_shape(video_dataset):
    """A policy taking 16x16 frames from a 32x32 recording gets 2x2 box averages, cached or not."""
    keys = dict(
        observation_keys=("observation.images.top", "observation.state"),
        image_shapes=(("observation.images.top", (3, 16, 16)),),
    )
    plain = HindsightGoalDataset(video_dataset, spec(**keys))
    cached = HindsightGoalDataset(video_dataset, spec(**keys, cache_frames=True))
    box = video_dataset[5]["observation.images.top"].reshape(3, 16, 2, 16, 2).mean((2, 4))
    torch.manual_seed(0)
    a = plain[5]["observation.images.top"]
    torch.manual_seed(0)
    b = cached[5]["observation.images.top"]
    assert a.shape == b.shape == (3, 16, 16)
    assert torch.allclose(a, box, atol=1e-5)
    assert torch.allclose(b, box, atol=0.5 / 255 + 1e-6)  # the cache keeps uint8


def test_short_episode_is_refused_with_its_index(state_dataset):
    """Episodes of 60 frames are not longer than a 6 x 10 trajectory window: ValueError names them."""
    with pytest.raises(ValueError, match=r"\(0, 60\).*trajectory window"):
        HindsightGoalDataset(state_dataset, spec(obs_traj_len=6, obs_traj_stride=10))
    HindsightGoalDataset(state_dataset, spec(obs_traj_len=59, obs_traj_stride=1))  # 59 < 60 is fine


def test_missing_observation_key_is_named(state_dataset):
    """A policy observation key absent from the dataset raises KeyError naming it."""
    with pytest.raises(KeyError, match="observation.missing"):
        HindsightGoalDataset(state_dataset, spec(observation_keys=("observation.missing",)))


def test_meta_mirrors_stats_and_delegates(state_dataset):
    """meta.stats covers observation.goal.state with observation.state's stats; other attributes delegate."""
    wrapped = HindsightGoalDataset(state_dataset, tiny_config("efm_ac"))
    stats = wrapped.meta.stats
    assert stats["observation.goal.state"].keys() == state_dataset.meta.stats["observation.state"].keys()
    for name, value in state_dataset.meta.stats["observation.state"].items():
        assert np.array_equal(stats["observation.goal.state"][name], value), name
    assert "observation.goal.state" not in state_dataset.meta.stats  # the base metadata is left untouched
    assert (
        wrapped.meta.fps == state_dataset.meta.fps == 20
        and wrapped.num_frames == state_dataset.num_frames == 180
    )
    assert len(wrapped) == len(state_dataset) and wrapped.meta.repo_id == state_dataset.meta.repo_id


@pytest.mark.filterwarnings("ignore:This process .* is multi-threaded:DeprecationWarning")
def test_wrapper_pickles_and_loads_in_worker_processes(state_dataset, rows):
    """The wrapper survives pickle (after meta was read) and collates in a 2-worker DataLoader."""
    wrapped = HindsightGoalDataset(state_dataset, tiny_config("efm_pc"))
    wrapped.meta.stats  # noqa: B018  (caches the metadata view, which must pickle too)
    clone = pickle.loads(pickle.dumps(wrapped))
    item = clone[7]
    assert torch.equal(item["observation.state"], rows["observation.state"][7]) and clone.meta.fps == 20
    batches = list(DataLoader(wrapped, batch_size=30, shuffle=True, num_workers=2))
    assert len(batches) == 6 and sorted(torch.cat([b["index"] for b in batches]).tolist()) == list(range(180))
    b = batches[0]
    assert (
        b["action"].shape == (30, 8, 2)
        and b["observation.traj.state"].shape == (30, 3, 2)
        and len(b["task"]) == 30
    )
    assert torch.equal(b["observation.state"], rows["observation.state"][b["index"]])


def test_index_key_matches_lerobot_on_an_episode_subset(state_dataset_root):
    """item["index"] is the dataset's absolute frame index, as in LeRobotDataset items."""
    subset = LeRobotDataset(REPO_ID, root=state_dataset_root, episodes=[1, 2])
    wrapped = HindsightGoalDataset(subset, tiny_config("efm_ac"))
    assert torch.equal(wrapped[0]["observation.state"], subset[0]["observation.state"])
    assert wrapped[0]["index"] == subset[0]["index"]


def test_lerobot_image_transforms_apply_to_every_frame_used(video_dataset_root):
    """--dataset.image_transforms (LeRobot's augmentation) reaches o, g and tau^o frames, shapes unchanged."""
    from lerobot.transforms.transforms import ImageTransforms, ImageTransformsConfig

    plain = HindsightGoalDataset(LeRobotDataset(REPO_ID, root=video_dataset_root), tiny_config("efm_pc"))
    jitter = ImageTransforms(ImageTransformsConfig(enable=True, max_num_transforms=3))
    augmented = HindsightGoalDataset(
        LeRobotDataset(REPO_ID, root=video_dataset_root, image_transforms=jitter), tiny_config("efm_pc")
    )
    torch.manual_seed(0)
    a = plain[5]
    torch.manual_seed(0)
    b = augmented[5]
    for key in ("observation.images.top", "observation.goal.images.top", "observation.traj.images.top"):
        assert a[key].shape == b[key].shape
        assert not torch.allclose(a[key], b[key]), key
