"""The hindsight hook into LeRobot's lerobot-train: it must apply on every launch path and fail loudly
when a LeRobot upgrade removes the name it patches."""

import logging
import os
import subprocess
import sys
import types
from pathlib import Path

import lerobot.scripts.lerobot_train as lerobot_train
from conftest import REPO_ID, tiny_config

from lerobot_efm import train_hook
from lerobot_efm.hindsight import HindsightGoalDataset

REPO = Path(__file__).resolve().parents[1]


def test_lerobot_train_still_calls_the_hooked_name():
    """Guards the assumption the hook rests on (a LeRobot upgrade that breaks it fails here)."""
    import inspect

    assert callable(getattr(lerobot_train, train_hook.HOOKED_NAME))
    assert f"{train_hook.HOOKED_NAME}(cfg)" in inspect.getsource(lerobot_train.train)


def test_install_wraps_only_efm_policies(state_dataset, monkeypatch):
    monkeypatch.setattr(lerobot_train, train_hook.HOOKED_NAME, lambda cfg: (state_dataset, None))
    assert train_hook.install()
    hooked = getattr(lerobot_train, train_hook.HOOKED_NAME)
    assert train_hook.install() and getattr(lerobot_train, train_hook.HOOKED_NAME) is hooked  # idempotent

    efm_cfg = types.SimpleNamespace(policy=tiny_config("efm_ac"))
    train, evaluation = hooked(efm_cfg)
    assert isinstance(train, HindsightGoalDataset) and evaluation is None
    other_cfg = types.SimpleNamespace(policy=object())
    assert hooked(other_cfg)[0] is state_dataset


def test_missing_name_is_reported(monkeypatch, caplog):
    monkeypatch.delattr(lerobot_train, train_hook.HOOKED_NAME)
    with caplog.at_level(logging.ERROR):
        assert not train_hook.install()
    assert train_hook.HOOKED_NAME in caplog.text


def test_python_dash_m_launch_is_hooked(state_dataset_root, tmp_path):
    """`python -m lerobot.scripts.lerobot_train` runs the script as __main__, which must be patched too."""
    env = {**os.environ, "HF_HUB_OFFLINE": "1"}
    args = [
        sys.executable,
        "-m",
        "lerobot.scripts.lerobot_train",
        "--policy.type=efm_gc",
        f"--dataset.repo_id={REPO_ID}",
        f"--dataset.root={state_dataset_root}",
        f"--output_dir={tmp_path / 'run'}",
        "--policy.device=cpu",
        "--policy.push_to_hub=false",
        "--policy.max_goal_distance=40",
        "--policy.mlp_hidden_dims=[32,32]",
        "--policy.unet_down_dims=[8,16,16]",
        "--policy.unet_n_groups=4",
        "--steps=1",
        "--batch_size=4",
        "--num_workers=0",
        "--wandb.enable=false",
        "--log_freq=1",
    ]
    proc = subprocess.run(args, capture_output=True, text=True, timeout=300, env=env, cwd=REPO)
    assert proc.returncode == 0, proc.stderr[-4000:]
    assert "loss_actor" in proc.stderr + proc.stdout
