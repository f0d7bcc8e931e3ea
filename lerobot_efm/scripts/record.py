"""``lerobot-efm-record``: record a scripted operator in one of the plugin's envs as a LeRobot dataset.

    lerobot-efm-record --env.type=talos_kitchen --dataset.repo_id=local/talos_kitchen_play \\
        --dataset.root=data/talos_play --dataset.num_episodes=20 --dataset.episode_time_s=80

The ``--dataset.*`` flags are LeRobot's own (``DatasetRecordConfig``, as in ``lerobot-record``); the frame rate
is the env's control rate (``--dataset.fps`` and ``--dataset.reset_time_s`` do not apply to a simulator) and the
repo id is kept as given (no date stamp: scripts and configs name it). Ctrl-C keeps every saved episode (the
unfinished one is dropped), a SIGKILL too (:mod:`lerobot_efm.dataset_writer`); ``--resume=true`` appends.
"""

import logging
import time
from contextlib import closing
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from lerobot.configs import parser
from lerobot.configs.dataset import DatasetRecordConfig
from lerobot.envs.configs import EnvConfig

from lerobot_efm.dataset_card import recording_card_kwargs
from lerobot_efm.dataset_writer import EpisodeWriter
from lerobot_efm.operators import OperatorConfig, default_operator, register_operators
from lerobot_efm.recording import dataset_features, flatten_observation, make_raw_env, record_episodes
from lerobot_efm.scripts import run_cli

registered = register_operators()  # before the CLI is parsed: --operator.type choices


@dataclass
class RecordConfig:
    env: EnvConfig
    dataset: DatasetRecordConfig
    # --operator.type=<name> --operator.<option>=...; default: the env's play operator
    operator: OperatorConfig | None = None
    seed: int = 0
    resume: bool = False  # append to the dataset already at --dataset.root

    def __post_init__(self):
        if not self.dataset.repo_id or self.dataset.root is None:
            raise ValueError(
                "--dataset.repo_id and --dataset.root are required (e.g. local/my_play, data/my_play)"
            )
        if self.dataset.num_episodes < 1 or self.dataset.episode_time_s <= 0:
            raise ValueError(
                f"--dataset.num_episodes={self.dataset.num_episodes} and --dataset.episode_time_s="
                f"{self.dataset.episode_time_s} must be positive"
            )


@parser.wrap()
def record(cfg: RecordConfig):
    env = make_raw_env(cfg.env)
    rng = np.random.default_rng(cfg.seed)
    chosen = cfg.operator or default_operator(cfg.env.type)
    if chosen.env_type != cfg.env.type:
        valid = sorted(c for c in registered if OperatorConfig.get_choice_class(c).env_type == cfg.env.type)
        raise ValueError(
            f"--operator.type={chosen.type} records {chosen.env_type}, not --env.type={cfg.env.type}; "
            f"its operators: {valid}"
        )
    operator = chosen.build(env, rng)
    env.reset(seed=cfg.seed)
    first = flatten_observation(operator.reset(), cfg.env.features_map)
    names = getattr(env, "feature_names", None)
    data = cfg.dataset
    features = dataset_features(first, int(np.prod(env.action_space.shape)), names, data.video)
    writer = EpisodeWriter.open(
        data.root,
        data.repo_id,
        cfg.env.fps,
        features,
        resume=cfg.resume,
        robot_type=cfg.env.type,
        use_videos=data.video,
    )
    dataset = writer.dataset
    start = dataset.meta.total_episodes
    task = data.single_task or getattr(operator, "task", "play")

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

    with writer, closing(env):
        stats = record_episodes(
            writer,
            env,
            operator,
            cfg.env.features_map,
            episodes=data.num_episodes,
            episode_length=max(1, round(data.episode_time_s * cfg.env.fps)),
            task=task,
            seed=cfg.seed + start,
            on_episode=progress,
        )
    logging.info(
        "%s: %d episodes saved this run (%d frames, %.0f s)%s; dataset now %d episodes, %d frames",
        Path(data.root).resolve(),
        stats.saved,
        stats.frames,
        stats.seconds,
        " - interrupted" if stats.interrupted else "",
        dataset.meta.total_episodes,
        dataset.meta.total_frames,
    )
    for line in stats.failed:
        logging.warning("dropped %s", line)
    if data.push_to_hub:
        card = recording_card_kwargs(cfg.env.type, chosen.name)
        card["tags"] = sorted(set(card["tags"]) | set(data.tags or []))
        dataset.push_to_hub(private=data.private, **card)
    if stats.interrupted:
        raise SystemExit(130)
    return stats


def main(argv: list[str] | None = None):
    """Console entry point; ``main([...])`` runs in-process and returns the :class:`RecordStats`."""
    return run_cli(record, argv, "lerobot-efm-record")


if __name__ == "__main__":
    main()
