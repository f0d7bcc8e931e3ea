"""``lerobot-efm-goal``: save a goal observation (a frame of a LeRobot dataset, or a live robot's) to a goal file.

    lerobot-efm-goal --dataset.root=data/my_play --dataset.episode=3 --dataset.frame=-1 --output=goal.safetensors
    lerobot-efm-goal --robot.type=so101_follower --robot.port=... --teleop.type=so101_leader --output=goal.safetensors

From a robot: it connects (and the teleoperator, if given, which then moves the robot), lets you bring the robot
to the goal (by teleoperation or by hand) until you press Enter (or for ``--capture_after_s``), and saves that
observation, named as ``lerobot-record`` names it (``observation.state`` from the robot's ``.pos``/``.vel``
scalars in order, ``observation.images.<camera>``).

The file holds the ``observation.*`` tensors (state, camera images as float CHW in [0, 1]); deploy with
``lerobot-rollout --policy.path=CKPT --policy.goal_path=goal.safetensors`` (see :mod:`lerobot_efm.goal_source`).
``--display=true`` also logs the goal to rerun (``--rrd=goal.rrd`` saves it to a file instead of a viewer).
"""

import logging
import time
from dataclasses import dataclass, field
from pathlib import Path

import torch
from lerobot.configs import parser
from lerobot.robots import RobotConfig
from lerobot.teleoperators import TeleoperatorConfig

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
    robot: RobotConfig | None = None  # capture the goal from this robot instead of a dataset
    teleop: TeleoperatorConfig | None = None  # moves the robot to the goal while capturing
    fps: int = 30  # teleoperation rate while waiting
    capture_after_s: float | None = None  # capture after this many seconds instead of waiting for Enter
    output: Path = Path("goal.safetensors")
    display: bool = False  # log the goal's state and images to rerun
    rrd: Path | None = None  # with --display: save the rerun recording here instead of spawning a viewer


def describe(goal: dict) -> str:
    lines = []
    for key, value in sorted(goal.items()):
        if value.dim() <= 1:
            lines.append(f"  {key}: {[round(float(x), 4) for x in value.reshape(-1)]}")
        else:
            lines.append(
                f"  {key}: {tuple(value.shape)} {value.dtype}, range [{float(value.min()):.3f}, "
                f"{float(value.max()):.3f}]"
            )
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


def capture_from_robot(cfg: GoalConfig) -> dict:
    """Connect, let the user bring the robot to the goal, return its observation as policy input tensors."""
    import select
    import sys

    from lerobot.robots.utils import make_robot_from_config
    from lerobot.teleoperators.utils import make_teleoperator_from_config
    from lerobot.utils.feature_utils import build_dataset_frame, hw_to_dataset_features

    robot = make_robot_from_config(cfg.robot)
    teleop = make_teleoperator_from_config(cfg.teleop) if cfg.teleop is not None else None
    if teleop is not None:
        teleop.connect()
    robot.connect()
    try:
        if cfg.capture_after_s is None:
            print("Bring the robot to the goal, then press Enter.", flush=True)
        start = time.perf_counter()
        while True:
            if teleop is not None:
                robot.send_action(teleop.get_action())
            if cfg.capture_after_s is not None:
                if time.perf_counter() - start >= cfg.capture_after_s:
                    break
            elif select.select([sys.stdin], [], [], 0)[0]:
                sys.stdin.readline()
                break
            time.sleep(1.0 / cfg.fps)
        raw = robot.get_observation()
        features = hw_to_dataset_features(robot.observation_features, "observation")
        frame = build_dataset_frame(features, raw, "observation")
    finally:
        robot.disconnect()
        if teleop is not None:
            teleop.disconnect()
    goal = {}
    for key, value in frame.items():
        t = torch.as_tensor(value)
        goal[key] = t.permute(2, 0, 1).float() / 255.0 if t.dim() == 3 else t.float()
    return goal


@parser.wrap()
def export_goal(cfg: GoalConfig) -> Path:
    if cfg.robot is not None:
        goal = capture_from_robot(cfg)
        source = f"robot {cfg.robot.type}"
    elif cfg.dataset.root is not None:
        goal = read_dataset_frame(
            cfg.dataset.root, cfg.dataset.episode, cfg.dataset.frame, cfg.dataset.repo_id
        )
        source = f"episode {cfg.dataset.episode}, frame {cfg.dataset.frame} of {cfg.dataset.root}"
    else:
        raise ValueError("give --dataset.root (a LeRobot dataset frame) or --robot.type (a live robot)")
    path = write_goal_file(goal, cfg.output)
    logging.info("goal: %s -> %s\n%s", source, path, describe(goal))
    if cfg.display:
        display(goal, cfg.rrd)
    return path


def main(argv: list[str] | None = None):
    """Console entry point; ``main([...])`` runs in-process and returns the goal file's path."""
    return run_cli(export_goal, argv, "lerobot-efm-goal")


if __name__ == "__main__":
    main()
