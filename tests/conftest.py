"""Shared fixtures: tiny generated LeRobot datasets (state and video) and tiny EFM configs."""

import os

os.environ.setdefault("HF_HUB_OFFLINE", "1")
os.environ.setdefault("MUJOCO_GL", "egl")

import pytest  # noqa: E402
import torch  # noqa: E402
from lerobot.configs.policies import PreTrainedConfig  # noqa: E402
from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

import lerobot_efm  # noqa: E402,F401  (registers the efm_* types)
from lerobot_efm.synthetic import make_point_play_dataset  # noqa: E402

EFM_TYPES = ["efm_gc", "efm_ac", "efm_pc", "efm_ps", "efm_as"]
REPO_ID = "local/efm_point_play"

# Small networks so that every agent trains in milliseconds on 2 CPU cores.
TINY = dict(
    device="cpu",
    max_goal_distance=40,
    obs_traj_len=3,
    obs_traj_stride=4,
    mlp_hidden_dims=(32, 32),
    unet_down_dims=(8, 16, 16),
    unet_n_groups=4,
    num_candidates=5,
    num_inference_steps=3,
    image_encoder_channels=(4, 8, 8),
    image_encoder_hidden_dim=16,
    image_latent_dim=8,
    reached_augment_size=4,
)


def tiny_config(policy_type: str, **overrides):
    return PreTrainedConfig.get_choice_class(policy_type)(**{**TINY, **overrides})


@pytest.fixture(scope="session")
def state_dataset_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("data") / "state"
    make_point_play_dataset(root, repo_id=REPO_ID, num_episodes=3, episode_length=60, seed=0)
    return root


@pytest.fixture(scope="session")
def video_dataset_root(tmp_path_factory):
    root = tmp_path_factory.mktemp("data") / "video"
    make_point_play_dataset(
        root, repo_id=REPO_ID, num_episodes=2, episode_length=50, seed=1, with_images=True, image_size=32
    )
    return root


@pytest.fixture(scope="session")
def state_dataset(state_dataset_root):
    return LeRobotDataset(REPO_ID, root=state_dataset_root)


@pytest.fixture(scope="session")
def video_dataset(video_dataset_root):
    return LeRobotDataset(REPO_ID, root=video_dataset_root)


@pytest.fixture(autouse=True)
def _seed():
    torch.manual_seed(0)


@pytest.fixture(autouse=True, scope="session")
def _one_thread():
    """The tests' tiny networks run much faster on one thread than on two competing with other processes
    (the CLI tests' subprocesses keep their own settings)."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
