"""``lerobot-efm-record``: record a scripted operator in one of the plugin's envs as a LeRobot dataset.

    lerobot-efm-record --env.type=talos_kitchen --episodes=20 --episode_length=2000 \\
        --root=data/talos_play --repo_id=local/talos_kitchen_play

Ctrl-C keeps every saved episode (the unfinished one is dropped) and finalizes the dataset;
``--resume=true`` appends to it later. See :mod:`lerobot_efm.recording`.
"""

import logging
import time
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lerobot.configs import parser
from lerobot.envs.configs import EnvConfig

from lerobot_efm.dataset_card import recording_card_kwargs
from lerobot_efm.recording import (
    dataset_features,
    finalizing,
    flatten_observation,
    make_raw_env,
    open_dataset,
    operator_class,
    record_episodes,
)
from lerobot_efm.scripts import run_cli


@dataclass
class RecordConfig:
    env: EnvConfig
    root: Path
    repo_id: str = "local/efm_play"
    operator: str = "play"  # name registered for the env type in lerobot_efm.recording.OPERATORS
    episodes: int = 10
    episode_length: int = 2000  # frames per episode at most (the operator may end an episode earlier)
    seed: int = 0
    resume: bool = False  # append to the dataset already at --root
    video: bool = True  # cameras as mp4 (LeRobot's default); false: PNG frames
    task: str | None = None  # task string stored with every frame; default: the operator's `task` or "play"
    push_to_hub: bool = False
    private: bool = False


@parser.wrap()
def record(cfg: RecordConfig):
    env = make_raw_env(cfg.env)
    rng = np.random.default_rng(cfg.seed)
    operator = operator_class(cfg.env.type, cfg.operator)(env, rng)
    env.reset(seed=cfg.seed)
    first = flatten_observation(operator.reset(), cfg.env.features_map)
    names = getattr(env, "feature_names", None)
    features = dataset_features(first, int(np.prod(env.action_space.shape)), names, cfg.video)
    dataset = open_dataset(
        Path(cfg.root), cfg.repo_id, cfg.env.fps, features, cfg.resume, cfg.env.type, cfg.video
    )
    start = dataset.meta.total_episodes
    task = cfg.task or getattr(operator, "task", "play")

    t0 = time.perf_counter()

    def progress(ep, n, stats):
        logging.info(
            "episode %d: %d frames saved (%d episodes, %d frames, %.1f frames/s)",
            start + ep,
            n,
            stats.saved,
            stats.frames,
            stats.frames / max(1e-9, time.perf_counter() - t0),
        )

    with finalizing(dataset), closing(env):
        stats = record_episodes(
            dataset,
            env,
            operator,
            cfg.env.features_map,
            episodes=cfg.episodes,
            episode_length=cfg.episode_length,
            task=task,
            seed=cfg.seed + start,
            on_episode=progress,
        )
    logging.info(
        "%s: %d episodes saved this run (%d frames, %.0f s)%s; dataset now %d episodes, %d frames",
        Path(cfg.root).resolve(),
        stats.saved,
        stats.frames,
        stats.seconds,
        " - interrupted" if stats.interrupted else "",
        dataset.meta.total_episodes,
        dataset.meta.total_frames,
    )
    for line in stats.failed:
        logging.warning("dropped %s", line)
    if cfg.push_to_hub:
        dataset.push_to_hub(private=cfg.private, **recording_card_kwargs(cfg.env.type, cfg.operator))
    if stats.interrupted:
        raise SystemExit(130)
    return stats


def main(argv: list[str] | None = None):
    """Console entry point; ``main([...])`` runs in-process and returns the :class:`RecordStats`."""
    return run_cli(record, argv, "lerobot-efm-record")


if __name__ == "__main__":
    main()
