"""Multi-process training goes through LeRobot's own path: `accelerate launch ... lerobot-train`, here two
CPU processes with DDP over gloo. accelerate 1.x's `--cpu` flag starts a single process unless MPI is set up,
so the two processes come from its torchrun launcher (`--multi_gpu`) while `--policy.device=cpu` makes
LeRobot's Accelerator run on CPU. Each process must train on different samples, both must end with the same
weights."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import REPO_ID

REPO = Path(__file__).resolve().parents[1]


@pytest.mark.slow
def test_two_cpu_processes_share_weights_not_samples(state_dataset_root, tmp_path):
    accelerate = Path(sys.executable).parent / "accelerate"
    env = {**os.environ, "HF_HUB_OFFLINE": "1", "EFM_PROBE_DIR": str(tmp_path)}
    cmd = [
        str(accelerate),
        "launch",
        "--multi_gpu",
        "--num_processes",
        "2",
        "--num_machines",
        "1",
        "--mixed_precision",
        "no",
        "--dynamo_backend",
        "no",
        str(REPO / "tests" / "ddp_probe.py"),
        "--policy.type=efm_ac",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={state_dataset_root}",
        f"--output_dir={tmp_path / 'run'}",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--policy.max_goal_distance=40",
        "--policy.use_rl=true",
        "--policy.mlp_hidden_dims=[32,32]",
        "--policy.unet_down_dims=[8,16,16]",
        "--policy.unet_n_groups=4",
        "--steps=4",
        "--batch_size=8",
        "--num_workers=0",
        "--wandb.enable=false",
        "--save_freq=4",
    ]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env=env, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-5000:]
    ranks = [json.loads((tmp_path / f"rank{r}.json").read_text()) for r in (0, 1)]
    assert len(ranks[0]["indices"]) == len(ranks[1]["indices"]) == 4
    for step, (a, b) in enumerate(zip(ranks[0]["indices"], ranks[1]["indices"], strict=True)):
        assert not set(a) & set(b), f"both processes trained on the same samples at step {step}"
    assert (
        ranks[0]["fingerprints"] == ranks[1]["fingerprints"]
    )  # gradients are all-reduced: identical weights
    assert ranks[0]["fingerprints"][0] != ranks[0]["fingerprints"][-1]  # and they did change
    assert (tmp_path / "run" / "checkpoints" / "000004" / "pretrained_model" / "model.safetensors").exists()
