"""Log hindsight-goal samples of a LeRobot dataset to a rerun ``.rrd`` file, to check goals and strides.

    lerobot-efm-log-dataset --dataset.repo_id=local/efm_point_play --dataset.root=data/play \\
        --policy.type=efm_ps --policy.obs_traj_len=3 --policy.obs_traj_stride=10 --policy.max_goal_distance=600 \\
        --num_samples=16 --output=samples.rrd
    rerun samples.rrd

The sampling parameters (L_o, S_o, L_a, S_a, L_g, action_mode, whether tau^o is sampled) come from the
policy config: ``--policy.type=<efm_*>`` plus ``--policy.<field>`` flags, or a checkpoint's
``--policy.path=...``. What is logged is described in :mod:`lerobot_efm.viz.dataset_log`.
"""

import logging
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from lerobot.configs import parser
from lerobot.configs.default import DatasetConfig
from lerobot.configs.policies import PreTrainedConfig

import lerobot_efm  # noqa: F401  (registers the efm_* policies)
from lerobot_efm.scripts import run_cli

logger = logging.getLogger(__name__)


@dataclass
class LogDatasetConfig:
    dataset: DatasetConfig  # LeRobot's --dataset.repo_id / --dataset.root / --dataset.video_backend
    # Hindsight sampling parameters: --policy.type=efm_ps --policy.obs_traj_stride=... or --policy.path=<ckpt>.
    policy: PreTrainedConfig | None = None
    # Which env's geometry hook draws states/actions (lerobot_efm.viz.register_env_viz); default: first 3 dims.
    env_type: str | None = "efm_point_reach"
    num_samples: int = 8
    seed: int = 0
    output: Path = Path("outputs/hindsight_samples.rrd")
    application_id: str = "lerobot_efm_hindsight"

    def __post_init__(self) -> None:
        policy_path = parser.get_path_arg("policy")
        if policy_path:
            overrides = parser.get_yaml_overrides("policy") + (parser.get_cli_overrides("policy") or [])
            self.policy = PreTrainedConfig.from_pretrained(policy_path, cli_overrides=overrides)
        if self.policy is None:
            self.policy = PreTrainedConfig.get_choice_class("efm_ps")(device="cpu")
        if not hasattr(self.policy, "obs_traj_len"):
            raise ValueError(
                f"--policy.type must be an EFM policy (efm_gc/ac/pc/ps/as), got {self.policy.type!r}."
            )
        if self.num_samples < 1:
            raise ValueError(f"num_samples must be >= 1, got {self.num_samples}.")

    @classmethod
    def __get_path_fields__(cls) -> list[str]:
        return ["policy"]


def log_dataset(cfg: LogDatasetConfig) -> list[dict]:
    """Sample ``cfg.num_samples`` rows (without replacement, seeded), log them, save ``cfg.output``."""
    import rerun as rr
    from lerobot.datasets.lerobot_dataset import LeRobotDataset

    from ..hindsight import HindsightGoalDataset, HindsightSpec
    from ..viz.dataset_log import log_hindsight_samples, samples_blueprint
    from ..viz.env_viz import get_env_viz

    data = cfg.dataset
    base = LeRobotDataset(
        data.repo_id, root=data.root, revision=data.revision, video_backend=data.video_backend
    )
    dataset = HindsightGoalDataset(base, HindsightSpec.from_config(cfg.policy))
    rng = np.random.default_rng(cfg.seed)
    n = min(cfg.num_samples, len(dataset))
    indices = sorted(rng.choice(len(dataset), size=n, replace=False).tolist())
    torch.manual_seed(cfg.seed)  # d ~ U{0..min(L_g, left)} is drawn with torch

    output = Path(cfg.output)
    output.parent.mkdir(parents=True, exist_ok=True)
    rec = rr.RecordingStream(cfg.application_id)
    rec.save(output)
    rec.send_recording_name(f"hindsight samples of {cfg.dataset.repo_id} ({cfg.policy.type})")
    try:
        logged = log_hindsight_samples(rec, dataset, indices, get_env_viz(cfg.env_type))
        cameras = sorted(
            k[len("observation.images.") :]
            for k in [*dataset.video_keys, *dataset.image_keys]
            if k.startswith("observation.images.")
        )
        rec.send_blueprint(samples_blueprint(len(logged), cameras))
    finally:
        rec.flush()
        rec.disconnect()
    return logged


@parser.wrap()
def log_dataset_main(cfg: LogDatasetConfig) -> list[dict]:
    logged = log_dataset(cfg)
    print(
        f"Wrote {cfg.output}: {len(logged)} hindsight sample(s), d = {[int(s['d']) for s in logged]}. "
        f"View it with: rerun {cfg.output}"
    )
    return logged


def main(argv: list[str] | None = None) -> list[dict] | None:
    """Console entry point; ``main([...])`` runs in-process with those CLI arguments and returns the summaries."""
    return run_cli(log_dataset_main, argv, "log_dataset")


if __name__ == "__main__":
    main()
