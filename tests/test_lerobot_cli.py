"""End to end through LeRobot's own console scripts (lerobot-train, lerobot-eval) in subprocesses,
plus LeRobot's Hub push path with a recording stand-in for the (unreachable) Hub, and the shipped training
configs parsed and trained for one step in-process, the way lerobot-train builds its run."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import EFM_TYPES, REPO_ID
from inprocess_train import train_one_step
from lerobot.policies.factory import get_policy_class
from safetensors.torch import load_file

BIN = Path(sys.executable).parent
REPO = Path(__file__).resolve().parents[1]
TINY_FLAGS = [
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--policy.max_goal_distance=40",
    "--policy.obs_traj_stride=4",
    "--policy.mlp_hidden_dims=[32,32]",
    "--policy.unet_down_dims=[8,16,16]",
    "--policy.unet_n_groups=4",
    "--policy.num_candidates=4",
    "--policy.num_inference_steps=3",
    "--policy.reached_augment_size=4",
    "--wandb.enable=false",
    "--num_workers=0",
    "--batch_size=8",
    "--log_freq=1",
]


def run(cli: str, *args: str, timeout: int = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "PYTHONUNBUFFERED": "1"}
    proc = subprocess.run(
        [str(BIN / cli), *args], capture_output=True, text=True, timeout=timeout, env=env, cwd=REPO
    )
    assert proc.returncode == 0, (
        f"{cli} failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-6000:]}"
    )
    return proc


def train(root, out, policy_type, *extra):
    return run(
        "lerobot-train",
        f"--policy.type={policy_type}",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={root}",
        f"--output_dir={out}",
        *TINY_FLAGS,
        *extra,
    )


@pytest.fixture(scope="module")
def trained(tmp_path_factory, state_dataset_root):
    """One tiny lerobot-train run per agent type (RL bootstrap on for the critic-based ones)."""
    runs = {}
    for policy_type in EFM_TYPES:
        out = tmp_path_factory.mktemp("runs") / policy_type
        rl = [] if policy_type == "efm_gc" else ["--policy.use_rl=true"]
        workers = (
            ["--num_workers=2"] if policy_type == "efm_pc" else []
        )  # worker processes pickle the wrapper
        proc = train(state_dataset_root, out, policy_type, "--steps=3", "--save_freq=3", *rl, *workers)
        runs[policy_type] = (out / "checkpoints" / "last" / "pretrained_model", proc.stderr + proc.stdout)
    return runs


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_lerobot_train_checkpoint(trained, policy_type):
    ckpt, log = trained[policy_type]
    assert "loss_actor" in log  # the policy's own loss terms reached LeRobot's logger
    config = json.loads((ckpt / "config.json").read_text())
    assert config["type"] == policy_type and "observation.goal.state" in config["input_features"]
    weights = load_file(ckpt / "model.safetensors")
    assert any(k.startswith("ema_model.") for k in weights) and any(k.startswith("model.") for k in weights)
    assert (
        weights["ema_updates"].item() == 3
    )  # lerobot-train called policy.update() after each of the 3 steps
    stats = load_file(next(ckpt.glob("policy_preprocessor_step_*_normalizer_processor.safetensors")))
    assert torch.equal(
        stats["observation.goal.state.min"], stats["observation.state.min"]
    )  # goals use obs stats
    policy = get_policy_class(policy_type).from_pretrained(ckpt)
    assert policy.config.use_rl == (policy_type != "efm_gc")
    for key, value in policy.state_dict().items():
        assert torch.equal(value, weights[key]), key


def test_lerobot_eval_takes_the_goal_from_the_env(trained, tmp_path):
    ckpt, _ = trained["efm_ac"]
    run(
        "lerobot-eval",
        f"--policy.path={ckpt}",
        "--env.type=efm_point_reach",
        "--eval.n_episodes=2",
        "--eval.batch_size=2",
        "--policy.device=cpu",
        f"--output_dir={tmp_path}",
    )
    info = json.loads((tmp_path / "eval_info.json").read_text())
    assert "pc_success" in info["overall"] and info["overall"]["n_episodes"] == 2


def test_resume_continues_the_run(trained, tmp_path):
    """The stock console script resumes a copy of the fixture's 3-step FM-AC run to 5 steps: the EMA counter
    and every parameter's Adam step count continue from the checkpoint (re-initialised EMA or optimiser state
    would restart them). tests/test_resume_exact.py shows the resumed state is bit-exact."""
    import shutil

    ckpt, _ = trained["efm_ac"]
    out = tmp_path / "run"
    shutil.copytree(ckpt.parent, out / "checkpoints" / "000003")
    cfg = out / "checkpoints" / "000003" / "pretrained_model" / "train_config.json"
    proc = run("lerobot-train", f"--config_path={cfg}", "--resume=true", "--steps=5", f"--output_dir={out}")
    assert "Resuming" in proc.stderr + proc.stdout
    final = out / "checkpoints" / "000005"
    assert json.loads((final / "training_state" / "training_step.json").read_text())["step"] == 5
    assert load_file(final / "pretrained_model" / "model.safetensors")["ema_updates"].item() == 5
    optimizer = load_file(final / "training_state" / "optimizer_state.safetensors")
    adam_steps = {v.item() for k, v in optimizer.items() if k.endswith("/step")}
    assert adam_steps == {5.0}


@pytest.fixture(scope="module")
def long_state_dataset_root(tmp_path_factory):
    """Episodes longer than every shipped config's trajectory window (OGBench's is 4 x 16 frames)."""
    from lerobot_efm.synthetic import make_point_play_dataset

    root = tmp_path_factory.mktemp("data") / "long"
    make_point_play_dataset(root, repo_id=REPO_ID, num_episodes=2, episode_length=100, seed=2)
    return root


# The Talos configs name the Talos features: tests/test_talos_record.py trains them on a Talos recording.
GENERIC_CONFIGS = sorted(
    p.name for p in (REPO / "train_configs").glob("*.json") if not p.name.startswith("talos_")
)


@pytest.mark.parametrize("config_file", GENERIC_CONFIGS)
def test_shipped_train_configs(long_state_dataset_root, tmp_path, config_file):
    """Config drift, in-process (tests/inprocess_train.py): each shipped config is parsed with CLI overrides,
    validated and trains one step the way lerobot-train builds its run; the console script itself is
    exercised by the runs above."""
    policy = train_one_step(
        REPO / "train_configs" / config_file,
        f"--dataset.root={long_state_dataset_root}",
        f"--dataset.repo_id={REPO_ID}",
        "--policy.device=cpu",
        f"--output_dir={tmp_path / 'run'}",
        "--batch_size=8",
        "--num_workers=0",
    )
    assert (
        policy.config.type == json.loads((REPO / "train_configs" / config_file).read_text())["policy"]["type"]
    )


def test_push_to_hub_goes_through_lerobots_path_with_an_efm_card(trained, tmp_path, monkeypatch):
    """LeRobot's push_model_to_hub, with HfApi replaced by a stand-in that keeps the uploaded folder."""
    import shutil

    import lerobot.policies.pretrained as pretrained
    from lerobot.configs.train import TrainPipelineConfig

    uploaded = tmp_path / "uploaded"

    class RecordingHfApi:
        def create_repo(self, repo_id, **kwargs):
            return type("Repo", (), {"repo_id": repo_id})()

        def upload_folder(self, repo_id, folder_path, **kwargs):
            shutil.copytree(folder_path, uploaded)
            return type("Commit", (), {"repo_url": type("Url", (), {"url": f"https://hub/{repo_id}"})()})()

    monkeypatch.setattr(pretrained, "HfApi", RecordingHfApi)
    ckpt, _ = trained["efm_ac"]
    policy = get_policy_class("efm_ac").from_pretrained(ckpt)
    policy.config.repo_id = "someone/efm_ac_point"
    cfg = TrainPipelineConfig.from_pretrained(ckpt)
    policy.push_model_to_hub(cfg)
    card = (uploaded / "README.md").read_text()
    assert "FM-AC-use-RL" in card and "Extremum Flow Matching" in card and REPO_ID in card
    assert (uploaded / "model.safetensors").exists() and (uploaded / "config.json").exists()


def test_lerobot_train_on_a_video_dataset(video_dataset_root, tmp_path):
    """Camera frames (o, g and tau^o) are decoded from the videos inside lerobot-train's DataLoader workers."""
    out = tmp_path / "run"
    proc = train(
        video_dataset_root,
        out,
        "efm_pc",
        "--steps=2",
        "--save_freq=2",
        "--num_workers=1",
        "--policy.image_encoder_channels=[4,8,8]",
        "--policy.image_encoder_hidden_dim=16",
        "--policy.image_latent_dim=8",
    )
    assert "loss_planner" in proc.stderr + proc.stdout
    config = json.loads((out / "checkpoints" / "last" / "pretrained_model" / "config.json").read_text())
    assert config["input_features"]["observation.goal.images.top"]["type"] == "VISUAL"


def test_an_invalid_option_reaches_the_user_with_its_reason(tmp_path):
    """draccus reports only "Couldn't instantiate class EFMACConfig"; the reason must be printed too."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    proc = subprocess.run(
        [
            str(BIN / "lerobot-train"),
            "--policy.type=efm_ac",
            "--policy.action_traj_len=7",
            f"--dataset.repo_id={REPO_ID}",
            f"--output_dir={tmp_path / 'out'}",
        ],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=REPO,
    )
    assert proc.returncode != 0
    assert "action_traj_len=7 must be divisible by 8" in proc.stdout + proc.stderr, proc.stderr[-3000:]
