"""Generated *play* data for PointReach, saved as a LeRobot v3 dataset.

A scripted operator wanders between random waypoints with noise, pauses and detours (going
around the wall through the gap above it), so the recording is goal-free and passes by many
states. It stores no goals: hindsight relabelling creates them from future states at train time.

CLI: ``python -m lerobot_efm.synthetic --dataset.root=DIR [--num_episodes=N] [--episode_length=L] [--images=true]``
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_efm.dataset_writer import (
    GENERATOR_SEAL_INTERVAL_S,
    DatasetTarget,
    EpisodeWriter,
    state_action_features,
)
from lerobot_efm.envs.point_reach import (
    WALL_TOP,
    in_wall,
    move_point,
    render_scene,
    sample_free,
    segment_hits_wall,
)

FPS = 20
TASK = "play"


def play_features(with_images: bool = False, image_size: int = 64) -> dict:
    """Dataset features of the play recordings (no goal keys, no rewards)."""
    return state_action_features(["x", "y"], ["x", "y"], {"top": image_size} if with_images else None)


def _route(p: np.ndarray, target: np.ndarray, rng: np.random.Generator, wall: bool) -> list[np.ndarray]:
    """Waypoints from p to target; through the gap above the wall when the straight line is blocked."""
    if not segment_hits_wall(p, target, wall=wall):
        return [target]
    route = []
    for side in (np.sign(p[0]) or 1.0, np.sign(target[0]) or 1.0):
        via = np.array([side * rng.uniform(0.08, 0.35), rng.uniform(WALL_TOP + 0.1, 0.85)])
        if not route or np.sign(route[-1][0]) != side:
            route.append(via)
    return route + [target]


def _new_leg(p: np.ndarray, rng: np.random.Generator, wall: bool) -> list[np.ndarray]:
    """Next play leg: a random free target, sometimes reached via a random detour point.

    Targets mostly stay on the current side of the wall: always crossing would over-visit the gap.
    """
    target = sample_free(rng, wall)
    if wall and rng.random() < 0.6 and target[0] * p[0] < 0:
        target[0] = -target[0]  # mirror onto p's side (free space is symmetric in x)
    if rng.random() < 0.3:  # detour: a point off the straight line
        mid = 0.5 * (p + target) + rng.normal(0.0, 0.35, 2)
        if np.all(np.abs(mid) < 0.95) and not in_wall(mid, 0.05, wall):
            return _route(p, mid, rng, wall) + _route(mid, target, rng, wall)
    return _route(p, target, rng, wall)


class PointPlayOperator:
    """Scripted play in PointReach, as an operator of ``lerobot-efm-record`` (see
    :mod:`lerobot_efm.recording`): legs to random free targets with smooth heading noise, pauses
    and detours. Deterministic given ``rng``."""

    task = TASK

    def __init__(self, env=None, rng: np.random.Generator | None = None, wall: bool | None = None):
        self.env, self.rng = env, rng if rng is not None else np.random.default_rng()
        self.wall = bool(getattr(env, "wall", True) if wall is None else wall)
        self.done = False  # play never ends by itself

    def start(self) -> np.ndarray:
        """Forget the current leg and pick a random free start position."""
        self.queue: list[np.ndarray] = []
        self.pause, self.budget, self.speed, self.drift = 0, 0, 0.04, np.zeros(2)
        return sample_free(self.rng, self.wall)

    def reset(self) -> dict:
        self.env.set_position(self.start())
        return self.env.observe()

    def act(self, obs: dict) -> np.ndarray:
        p, rng = np.asarray(obs["agent_pos"], dtype=np.float64), self.rng
        if self.pause > 0:  # idle: tiny jitter around the current position
            self.pause -= 1
            return np.clip(p + rng.normal(0.0, 0.003, 2), -1.0, 1.0)
        if not self.queue:
            self.queue, self.speed = _new_leg(p, rng, self.wall), rng.uniform(0.015, 0.05)
            self.budget = 150
        delta = self.queue[0] - p
        dist = float(np.linalg.norm(delta))
        self.budget -= 1
        if dist < 0.04 or self.budget <= 0:  # waypoint reached (or hopeless): next one, maybe pause
            self.queue.pop(0)
            self.budget = 150
            if rng.random() < 0.2:
                self.pause = int(rng.integers(3, 20))
        self.drift = 0.85 * self.drift + rng.normal(0.0, 0.25, 2)  # smooth heading noise -> curved paths
        heading = delta / max(dist, 1e-6) + self.drift
        heading /= max(float(np.linalg.norm(heading)), 1e-6)
        cmd = p + heading * min(self.speed, max(dist, 0.01)) + rng.normal(0.0, 0.004, 2)
        return np.clip(cmd, -1.0, 1.0)


def play_episode(rng: np.random.Generator, length: int, wall: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Simulate one play episode without an env object (the point dynamics are a pure function);
    returns states (length, 2) and commanded positions (length, 2)."""
    operator = PointPlayOperator(rng=rng, wall=wall)
    p = operator.start()
    states, actions = np.empty((length, 2)), np.empty((length, 2))
    for t in range(length):
        cmd = operator.act({"agent_pos": p})
        states[t], actions[t] = p, cmd
        p = move_point(p, cmd, wall)
    return states, actions


def make_point_play_dataset(
    root: str | Path,
    repo_id: str = "local/efm_point_play",
    num_episodes: int = 20,
    episode_length: int = 200,
    seed: int = 0,
    with_images: bool = False,
    image_size: int = 64,
    wall: bool = True,
) -> LeRobotDataset:
    """Record ``num_episodes`` play episodes into a new dataset at ``root`` (which must not exist).

    Images (``observation.images.top``) use the same renderer as ``PointReachEnv`` observations, so
    env goal images match dataset frames. Returns the dataset reopened read-only.
    """
    rng = np.random.default_rng(seed)
    features = play_features(with_images, image_size)
    writer = EpisodeWriter.open(
        root, repo_id, FPS, features, use_videos=with_images, seal_interval_s=GENERATOR_SEAL_INTERVAL_S
    )
    with writer:  # keeps the already saved episodes readable even if recording fails mid-way
        for _ in range(num_episodes):
            states, actions = play_episode(rng, episode_length, wall)
            writer.write_episode(
                {
                    "observation.state": s,
                    "action": a,
                    "task": TASK,
                    **({"observation.images.top": render_scene(s, image_size, wall)} if with_images else {}),
                }
                for s, a in zip(states.astype(np.float32), actions.astype(np.float32), strict=True)
            )
    return LeRobotDataset(repo_id, root=root)


@dataclass
class PointPlayConfig:
    """``python -m lerobot_efm.synthetic --dataset.root=DIR [--num_episodes=N] [--images=true]``."""

    dataset: DatasetTarget = field(default_factory=DatasetTarget)
    num_episodes: int = 20
    episode_length: int = 200
    seed: int = 0
    images: bool = False  # also record observation.images.top (video)
    image_size: int = 64
    wall: bool = True

    def __post_init__(self):
        if self.num_episodes < 1 or self.episode_length < 1:
            raise ValueError(
                f"--num_episodes={self.num_episodes} and --episode_length={self.episode_length} must be positive"
            )


def generate(cfg: PointPlayConfig) -> LeRobotDataset:
    repo_id, root = cfg.dataset.resolved("local/efm_point_play")
    ds = make_point_play_dataset(
        root, repo_id, cfg.num_episodes, cfg.episode_length, cfg.seed, cfg.images, cfg.image_size, cfg.wall
    )
    print(f"{root}: {ds.num_episodes} episodes, {ds.num_frames} frames")
    return ds


def main(argv: list[str] | None = None):
    """Generate PointReach play; ``main([...])`` runs in-process and returns the dataset."""
    from lerobot_efm.scripts import run_config_cli

    return run_config_cli(PointPlayConfig, generate, argv, "lerobot_efm.synthetic")


if __name__ == "__main__":
    main()
