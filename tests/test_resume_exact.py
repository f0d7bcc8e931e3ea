"""lerobot-train and the EMA, and an exact resume (issue 11, items 2 and 7).

One uninterrupted 4-step lerobot-train run (checkpoints at steps 2 and 4) and one run resumed from a copy of
its step-2 checkpoint. Both go through ``tests/resume_probe.py``: LeRobot's own ``lerobot-train`` main, with
the two RNG-order effects that make a stock resume inexact removed (accelerate's one-batch look-ahead draws the
next batch's hindsight goals before a checkpoint saves the RNG; the DataLoader iterator draws a base seed from
the global RNG when created). With those gone, weights, EMA weights, the EMA counter, the optimiser, scheduler
and RNG state after the resume must equal the uninterrupted run's bit for bit.
"""

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import torch
from conftest import REPO_ID
from lerobot.configs.policies import PreTrainedConfig
from lerobot.policies.factory import get_policy_class
from safetensors.torch import load_file

REPO = Path(__file__).resolve().parents[1]
FLAGS = [
    "--policy.type=efm_pc",
    "--policy.use_rl=true",
    "--policy.device=cpu",
    "--policy.push_to_hub=false",
    "--policy.max_goal_distance=40",
    "--policy.obs_traj_stride=4",
    "--policy.mlp_hidden_dims=[32,32]",
    "--policy.unet_down_dims=[8,16,16]",
    "--policy.unet_n_groups=4",
    "--policy.num_inference_steps=3",
    "--policy.reached_augment_size=4",
    "--wandb.enable=false",
    "--num_workers=0",
    "--batch_size=8",
    "--log_freq=1",
]


def probe(*args):
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1", "PYTHONUNBUFFERED": "1"}
    proc = subprocess.run(
        [sys.executable, str(REPO / "tests" / "resume_probe.py"), *args],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
        cwd=REPO,
    )
    assert proc.returncode == 0, (
        f"lerobot-train failed ({proc.returncode}):\n{proc.stdout[-3000:]}\n{proc.stderr[-6000:]}"
    )
    return proc.stdout + proc.stderr


@pytest.fixture(scope="module")
def runs(tmp_path_factory, state_dataset_root):
    base = tmp_path_factory.mktemp("resume")
    straight, resumed = base / "straight", base / "resumed"
    probe(
        *FLAGS,
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={state_dataset_root}",
        f"--output_dir={straight}",
        "--steps=4",
        "--save_freq=2",
    )
    shutil.copytree(straight / "checkpoints" / "000002", resumed / "checkpoints" / "000002")
    log = probe(
        f"--config_path={resumed / 'checkpoints' / '000002' / 'pretrained_model' / 'train_config.json'}",
        "--resume=true",
        "--steps=4",
        f"--output_dir={resumed}",
    )
    assert "Resuming" in log
    return straight / "checkpoints", resumed / "checkpoints"


def test_lerobot_train_updates_the_ema_once_per_step(runs):
    """The checkpoint's EMA has seen one update() per optimiser step, and its weights differ both from the
    online weights and from their initial values (parameters with a seed-independent initialisation: norms)."""
    checkpoints, _ = runs
    for step in (2, 4):
        weights = load_file(checkpoints / f"{step:06d}" / "pretrained_model" / "model.safetensors")
        assert weights["ema_updates"].item() == step
    ckpt = checkpoints / "000004" / "pretrained_model"
    config = PreTrainedConfig.from_pretrained(ckpt)
    fresh = []
    for seed in (0, 1):
        torch.manual_seed(seed)
        fresh.append(get_policy_class(config.type)(config))
    names = [n[len("model.") :] for n, _ in fresh[0].named_parameters() if n.startswith("model.")]
    init0, init1 = fresh[0].model.state_dict(), fresh[1].model.state_dict()
    fixed_init = [n for n in names if torch.equal(init0[n], init1[n])]
    assert len(fixed_init) > 20  # GroupNorm / LayerNorm weights and biases
    differs_from_online = [
        n for n in names if not torch.equal(weights["ema_model." + n], weights["model." + n])
    ]
    assert len(differs_from_online) == len(names), sorted(set(names) - set(differs_from_online))
    for n in fixed_init:
        assert not torch.equal(weights["ema_model." + n], init0[n]), f"EMA {n} still at its initial value"


def test_resume_equals_the_uninterrupted_run(runs):
    straight, resumed = runs
    for rel in (
        "pretrained_model/model.safetensors",
        "training_state/optimizer_state.safetensors",
        "training_state/rng_state.safetensors",
    ):
        a, b = load_file(straight / "000004" / rel), load_file(resumed / "000004" / rel)
        assert a.keys() == b.keys(), rel
        different = [k for k in a if not torch.equal(a[k], b[k])]
        assert not different, f"{rel}: {len(different)} tensors differ, e.g. {different[:5]}"
    for rel in (
        "training_state/optimizer_param_groups.json",
        "training_state/scheduler_state.json",
        "training_state/training_step.json",
    ):
        assert json.loads((straight / "000004" / rel).read_text()) == json.loads(
            (resumed / "000004" / rel).read_text()
        ), rel
