"""``lerobot-efm-goal``: export a goal observation from a frame of a LeRobot dataset into a goal file.

    lerobot-efm-goal --dataset.root=data/my_play --dataset.episode=3 --dataset.frame=-1 --output=goal.safetensors

The file holds the frame's ``observation.*`` tensors (state, decoded camera images); deploy with
``lerobot-rollout --policy.path=CKPT --policy.goal_path=goal.safetensors`` (see :mod:`lerobot_efm.goal_source`).
``--display=true`` also logs the goal to rerun (``--rrd=goal.rrd`` saves it to a file instead of a viewer).
"""

import logging
from dataclasses import dataclass, field
from pathlib import Path

from lerobot.configs import parser

from lerobot_efm.goal_source import read_dataset_frame, write_goal_file
from lerobot_efm.scripts import run_cli


@dataclass
class GoalFrameConfig:
    root: Path | None = None  # the LeRobot dataset's directory
    repo_id: str | None = None  # default: local/<root's name>
    episode: int = 0
    frame: int = -1  # negative: counted from the episode's end (-1 = its last frame)


@dataclass
class GoalConfig:
    dataset: GoalFrameConfig = field(default_factory=GoalFrameConfig)
    output: Path = Path("goal.safetensors")
    display: bool = False  # log the goal's state and images to rerun
    rrd: Path | None = None  # with --display: save the rerun recording here instead of spawning a viewer


def describe(goal: dict) -> str:
    lines = []
    for key, value in sorted(goal.items()):
        if value.dim() <= 1:
            lines.append(f"  {key}: {[round(float(x), 4) for x in value.reshape(-1)]}")
        else:
            lines.append(f"  {key}: {tuple(value.shape)} {value.dtype}, range [{float(value.min()):.3f}, "
                         f"{float(value.max()):.3f}]")
    return "\n".join(lines)


def display(goal: dict, rrd: Path | None) -> None:
    import numpy as np
    import rerun as rr

    rec = rr.RecordingStream("lerobot_efm_goal")
    if rrd is None:
        rec.spawn()
    else:
        rec.save(str(rrd))
    try:
        for key, value in goal.items():
            if value.dim() == 3:  # CHW float image in [0, 1]
                rgb = (value.permute(1, 2, 0).numpy() * 255).clip(0, 255).astype(np.uint8)
                rec.log(f"goal/{key}", rr.Image(rgb))
            else:
                for i, x in enumerate(value.reshape(-1).tolist()):
                    rec.log(f"goal/{key}/{i}", rr.Scalars(float(x)))
    finally:
        rec.flush()
        rec.disconnect()


@parser.wrap()
def export_goal(cfg: GoalConfig) -> Path:
    if cfg.dataset.root is None:
        raise ValueError("--dataset.root is required: the LeRobot dataset to take the goal frame from")
    goal = read_dataset_frame(cfg.dataset.root, cfg.dataset.episode, cfg.dataset.frame, cfg.dataset.repo_id)
    path = write_goal_file(goal, cfg.output)
    logging.info("goal: episode %d, frame %d of %s -> %s\n%s", cfg.dataset.episode, cfg.dataset.frame,
                 cfg.dataset.root, path, describe(goal))
    if cfg.display:
        display(goal, cfg.rrd)
    return path


def main(argv: list[str] | None = None):
    """Console entry point; ``main([...])`` runs in-process and returns the goal file's path."""
    return run_cli(export_goal, argv, "lerobot-efm-goal")


if __name__ == "__main__":
    main()
