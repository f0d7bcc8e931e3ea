"""One lerobot-train step in-process, for config-drift checks of the shipped training configs.

It follows ``lerobot.scripts.lerobot_train.train`` up to the first update: parse the config file with CLI
overrides (as ``--config_path`` does), validate, build the datasets through the hindsight hook, the policy, its
processors and the optimiser / scheduler presets, then train one batch and update the EMA. What it skips
(accelerate, logging, checkpoint writing) does not depend on the config and is run by the console-script tests.
"""

import json
import math
from pathlib import Path

import torch
from lerobot.configs.train import TrainPipelineConfig
from lerobot.datasets.factory import make_train_eval_datasets
from lerobot.optim.factory import make_optimizer_and_scheduler
from lerobot.policies.factory import make_policy, make_pre_post_processors
from torch.utils.data import DataLoader

from lerobot_efm.hindsight import HindsightGoalDataset
from lerobot_efm.train_hook import wrap_datasets


def train_one_step(config_file: Path, *cli_args: str):
    """Returns the policy after one update; asserts every policy field of the file reached its config."""
    cfg = TrainPipelineConfig.from_pretrained(config_file, cli_args=list(cli_args))
    cfg.validate()
    expected = json.loads(Path(config_file).read_text())["policy"]
    assert cfg.policy.type == expected["type"]
    overridden = {a.split("=", 1)[0][len("--policy.") :] for a in cli_args if a.startswith("--policy.")}
    for field, value in expected.items():
        if field in ("type", "input_features", "output_features") or field in overridden:
            continue
        actual = getattr(cfg.policy, field)
        assert (list(actual) if isinstance(actual, tuple) else actual) == value, field
    dataset, _ = wrap_datasets(cfg, make_train_eval_datasets(cfg))
    assert isinstance(dataset, HindsightGoalDataset)
    policy = make_policy(cfg=cfg.policy, ds_meta=dataset.meta)
    assert set(expected.get("input_features", {})) <= set(policy.config.input_features)
    preprocessor, _ = make_pre_post_processors(cfg.policy, dataset_stats=dataset.meta.stats)
    optimizer, scheduler = make_optimizer_and_scheduler(cfg, policy)
    policy.train()
    batch = next(iter(DataLoader(dataset, batch_size=cfg.batch_size, shuffle=True)))
    for key in dataset.meta.camera_keys:  # as lerobot-train does
        if key in batch and batch[key].dtype == torch.uint8:
            batch[key] = batch[key].to(dtype=torch.float32) / 255.0
    loss, _ = policy.forward(preprocessor(batch))
    loss.backward()
    optimizer.step()
    scheduler.step()
    policy.update()
    assert math.isfinite(loss.item()) and policy.ema_updates.item() == 1
    return policy
