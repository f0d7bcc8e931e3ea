"""The Talos kitchen end to end with LeRobot's own tools: ``lerobot-efm-record`` records scripted play
(video), ``lerobot-dataset-viz`` shows it, ``lerobot-train`` trains ``efm_ac`` on it, ``lerobot-eval`` runs
the checkpoint on a task of the suite."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("mujoco")

from lerobot.datasets.lerobot_dataset import LeRobotDataset  # noqa: E402

BIN = Path(sys.executable).parent
PROJECT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "MUJOCO_GL": "egl", "OMP_NUM_THREADS": "1"}
REPO = "local/talos_play_test"


def run(*args, timeout=400):
    proc = subprocess.run([str(a) for a in args], env=ENV, capture_output=True, text=True, timeout=timeout)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return proc


def eval_one_episode(ckpt: Path, out: Path, *extra: str) -> dict:
    """lerobot-eval of ``ckpt`` on one short open_door episode; its eval_info.json."""
    run(
        BIN / "lerobot-eval",
        f"--policy.path={ckpt}",
        "--env.type=talos_kitchen",
        "--env.task=open_door",
        "--env.episode_length=8",
        "--eval.n_episodes=1",
        "--eval.batch_size=1",
        "--policy.device=cpu",
        f"--output_dir={out}",
        *extra,
    )
    return json.loads((out / "eval_info.json").read_text())


@pytest.fixture(scope="module")
def talos_play(tmp_path_factory):
    root = tmp_path_factory.mktemp("talos") / "play"
    run(
        BIN / "lerobot-efm-record",
        "--env.type=talos_kitchen",
        f"--dataset.root={root}",
        f"--dataset.repo_id={REPO}",
        "--dataset.num_episodes=2",
        "--dataset.episode_time_s=2.8",  # 70 frames at the kitchen's 25 fps
        "--dataset.push_to_hub=false",
        "--seed=5",
    )
    return root


def test_recording_is_a_lerobot_video_dataset(talos_play):
    ds = LeRobotDataset(REPO, root=talos_play)
    assert ds.num_episodes == 2 and ds.num_frames == 140 and ds.fps == 25
    feats = ds.meta.features
    assert feats["observation.images.front"]["dtype"] == "video"
    assert feats["observation.state"]["names"][:3] == ["cmd_x", "cmd_y", "cmd_z"]
    assert feats["observation.environment_state"]["names"][:2] == ["door", "tray"]
    assert tuple(feats["action"]["shape"]) == (10,)
    item = ds[100]
    assert item["observation.images.front"].shape == (3, 128, 128)  # the env's default camera
    actions = np.stack([ds[i]["action"].numpy() for i in range(70)])
    state = np.stack([ds[i]["observation.state"].numpy() for i in range(70)])
    assert (
        np.isfinite(actions).all() and np.ptp(actions[:, :3], axis=0).max() > 0.01
    )  # the operator moves the hand
    np.testing.assert_allclose(
        state[1:, :3], np.clip(actions[:-1, :3], -10, 10), atol=1e-5
    )  # state holds the last command


def test_dataset_viz_shows_the_recording(talos_play, tmp_path):
    run(
        BIN / "lerobot-dataset-viz",
        f"--repo-id={REPO}",
        f"--root={talos_play}",
        "--episode-index=1",
        "--save=1",
        f"--output-dir={tmp_path}",
        "--num-workers=0",
    )
    rrd = list(tmp_path.glob("*.rrd"))
    assert rrd and rrd[0].stat().st_size > 10_000


def test_train_and_eval_efm_ac_on_the_recording(talos_play, tmp_path):
    out = tmp_path / "train"
    run(
        BIN / "lerobot-train",
        "--policy.type=efm_ac",
        f"--dataset.repo_id={REPO}",
        f"--dataset.root={talos_play}",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--policy.max_goal_distance=60",
        "--policy.obs_traj_stride=5",
        "--policy.mlp_hidden_dims=[32,32]",
        "--policy.unet_down_dims=[8,16,16]",
        "--policy.unet_n_groups=4",
        "--policy.image_encoder_channels=[4,8,8]",
        "--policy.image_encoder_hidden_dim=16",
        "--policy.image_latent_dim=8",
        "--policy.num_inference_steps=2",
        "--steps=3",
        "--batch_size=4",
        "--num_workers=0",
        "--save_freq=3",
        "--wandb.enable=false",
        f"--output_dir={out}",
    )
    ckpt = out / "checkpoints" / "last" / "pretrained_model"
    cfg = json.loads((ckpt / "config.json").read_text())
    assert {"observation.images.front", "observation.goal.images.front", "observation.goal.state"} <= set(
        cfg["input_features"]
    )
    info = eval_one_episode(ckpt, tmp_path / "eval")
    assert info["overall"]["n_episodes"] == 1 and 0.0 <= info["overall"]["pc_success"] <= 100.0


def tiny_shipped_config_run(play: Path, out: Path) -> list[str]:
    """lerobot-train flags that run a shipped Talos config for 2 steps on the test recording, small networks."""
    return [
        f"--dataset.repo_id={REPO}",
        f"--dataset.root={play}",
        "--policy.max_goal_distance=60",
        "--policy.mlp_hidden_dims=[32,32]",
        "--policy.unet_down_dims=[8,16,16]",
        "--policy.unet_n_groups=4",
        "--policy.num_inference_steps=2",
        "--steps=2",
        "--batch_size=4",
        "--save_freq=2",
        "--log_freq=1",
        f"--output_dir={out}",
    ]


def test_state_policy_evaluates_on_the_camera_free_env(talos_play, tmp_path):
    """The shipped state config trained by lerobot-train runs in lerobot-eval on ``--env.obs_type=state`` with a
    video frame every 4th step (what benchmarks/talos_kitchen_suite.py uses for state policies: nothing rendered
    for the policy, few frames for the videos)."""
    out = tmp_path / "train"
    run(
        BIN / "lerobot-train",
        f"--config_path={PROJECT / 'train_configs' / 'talos_kitchen_efm_ac_state.json'}",
        *tiny_shipped_config_run(talos_play, out),
    )
    ckpt = out / "checkpoints" / "last" / "pretrained_model"
    info = eval_one_episode(ckpt, tmp_path / "eval", "--env.obs_type=state", "--env.video_frame_stride=4")
    assert info["overall"]["n_episodes"] == 1 and Path(info["overall"]["video_paths"][0]).stat().st_size > 0


def test_image_config_trains_with_the_object_state_as_auxiliary_target(talos_play, tmp_path):
    """The shipped CPU image config (``auxiliary_state_key=observation.environment_state``): lerobot-train learns
    the recorded object state from the camera latent (logged loss), and lerobot-eval runs the checkpoint, which
    acts without it."""
    out = tmp_path / "train"
    proc = run(
        BIN / "lerobot-train",
        f"--config_path={PROJECT / 'train_configs' / 'talos_kitchen_efm_ac_image_cpu.json'}",
        *tiny_shipped_config_run(talos_play, out),
    )
    assert "loss_auxiliary_state:" in proc.stdout + proc.stderr
    ckpt = out / "checkpoints" / "last" / "pretrained_model"
    cfg = json.loads((ckpt / "config.json").read_text())
    assert cfg["auxiliary_state_dim"] == 9 and "observation.environment_state" not in cfg["input_features"]
    assert eval_one_episode(ckpt, tmp_path / "eval")["overall"]["n_episodes"] == 1


@pytest.mark.parametrize(
    "config_file", sorted(p.name for p in (PROJECT / "train_configs").glob("talos_kitchen_*.json"))
)
def test_shipped_talos_train_configs(talos_play, tmp_path, config_file):
    """The shipped Talos configs (state-only CPU configs, the paper's image config) train on a recording:
    config drift checked in-process (tests/inprocess_train.py), lerobot-train itself runs in the test above."""
    from inprocess_train import train_one_step

    policy = train_one_step(
        PROJECT / "train_configs" / config_file,
        f"--dataset.repo_id={REPO}",
        f"--dataset.root={talos_play}",
        "--policy.device=cpu",
        "--batch_size=4",
        "--num_workers=0",
        f"--output_dir={tmp_path / 'run'}",
    )
    expected = json.loads((PROJECT / "train_configs" / config_file).read_text())["policy"]
    assert policy.config.type == expected["type"] and set(expected["input_features"]) <= set(
        policy.config.input_features
    )
