"""OGBench raw ``.npz`` -> LeRobot v3 dataset, so ``lerobot-train`` (and the hindsight wrapper) can use it.

``observation.state`` = OGBench observation, ``action`` = OGBench action (pointmaze: a velocity command in
[-1, 1]^2, so train EFM policies with ``action_mode="velocity"``). Episodes end at ``terminals`` rows (OGBench
marks each episode's last row); every row becomes a frame. No goals, rewards or qpos/qvel are stored:
goals come from hindsight relabelling, and for pointmaze the observation *is* qpos.

FPS = 10: the point env's own ``render_fps`` (5 MuJoCo substeps of 0.02 s per action). It only sets timestamps.

CLI: ``python -m lerobot_efm.ogbench.convert --npz=X.npz --dataset.root=DIR [--dataset.repo_id=local/X] [--fps=10]``
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from tqdm import tqdm

from lerobot_efm.dataset_writer import (
    GENERATOR_SEAL_INTERVAL_S,
    DatasetTarget,
    EpisodeWriter,
    state_action_features,
)

FPS = 10
REQUIRED_KEYS = ("observations", "actions", "terminals")


def load_raw(path: str | Path) -> dict[str, np.ndarray]:
    """Read and validate an OGBench raw npz; errors name the file and the offending key."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"OGBench npz {path} does not exist")
    with np.load(path) as npz:
        missing = [k for k in REQUIRED_KEYS if k not in npz.files]
        if missing:
            raise KeyError(
                f"{path}: missing key(s) {missing}; OGBench raw datasets need {list(REQUIRED_KEYS)}, found {npz.files}"
            )
        data = {k: npz[k] for k in REQUIRED_KEYS}
    check_raw(data, str(path))
    return data


def check_raw(data: dict[str, np.ndarray], source: str = "dataset") -> None:
    obs, act, term = data["observations"], data["actions"], data["terminals"]
    if obs.ndim != 2 or len(obs) == 0:
        raise ValueError(f"{source}: 'observations' must be [N, obs_dim] with N > 0, got shape {obs.shape}")
    n = len(obs)
    if act.ndim != 2 or len(act) != n:
        raise ValueError(f"{source}: 'actions' must be [N={n}, action_dim], got shape {act.shape}")
    if term.shape != (n,):
        raise ValueError(f"{source}: 'terminals' must be [N={n}], got shape {term.shape}")
    if not term[-1]:
        raise ValueError(f"{source}: 'terminals' must be 1 on the last row (end of the last episode)")
    for key in ("observations", "actions"):
        if not np.all(np.isfinite(data[key])):
            raise ValueError(f"{source}: {key!r} holds non-finite values")


def episode_bounds(terminals: np.ndarray) -> list[tuple[int, int]]:
    """[start, end) row ranges of the episodes, each ending on a terminal row."""
    ends = np.flatnonzero(np.asarray(terminals).astype(bool)) + 1
    starts = np.r_[0, ends[:-1]]
    return [(int(s), int(e)) for s, e in zip(starts, ends, strict=True)]


def ogbench_features(obs_dim: int, action_dim: int) -> dict:
    planar = obs_dim == 2 and action_dim == 2
    return state_action_features(
        ["x", "y"] if planar else [f"state_{i}" for i in range(obs_dim)],
        ["vx", "vy"] if planar else [f"action_{i}" for i in range(action_dim)],
    )


def convert_arrays(
    data: dict[str, np.ndarray],
    root: str | Path,
    repo_id: str,
    fps: int = FPS,
    task: str = "play",
    source: str = "dataset",
) -> LeRobotDataset:
    """Write raw OGBench arrays as a new LeRobot dataset at ``root`` (must not exist); returns it reopened."""
    check_raw(data, source)
    obs = np.ascontiguousarray(data["observations"], dtype=np.float32)
    act = np.ascontiguousarray(data["actions"], dtype=np.float32)
    features = ogbench_features(obs.shape[1], act.shape[1])
    writer = EpisodeWriter.open(
        root, repo_id, fps, features, use_videos=False, seal_interval_s=GENERATOR_SEAL_INTERVAL_S
    )
    with writer:  # keeps the already saved episodes readable even if conversion fails mid-way
        bounds = episode_bounds(data["terminals"])
        for start, end in tqdm(bounds, desc=f"converting to {repo_id}", unit="ep", leave=False):
            writer.write_episode(
                {"observation.state": obs[t], "action": act[t], "task": task} for t in range(start, end)
            )
    return LeRobotDataset(repo_id, root=root)


def convert_npz(
    npz_path: str | Path,
    root: str | Path,
    repo_id: str | None = None,
    fps: int = FPS,
    task: str | None = None,
) -> LeRobotDataset:
    """``<name>.npz`` -> LeRobot dataset ``local/<name>`` at ``root``; the task label defaults to the file stem."""
    name = Path(npz_path).stem
    return convert_arrays(
        load_raw(npz_path), root, repo_id or f"local/{name}", fps, task or name, str(npz_path)
    )


@dataclass
class ConvertConfig:
    """``python -m lerobot_efm.ogbench.convert --npz=X.npz --dataset.root=DIR [--dataset.repo_id=local/X]``."""

    npz: str = ""  # OGBench raw dataset (observations, actions, terminals)
    dataset: DatasetTarget = field(default_factory=DatasetTarget)  # default repo id: local/<npz stem>
    fps: int = FPS
    task: str | None = None  # task label of every frame (default: the npz stem)

    def __post_init__(self):
        if not self.npz:
            raise ValueError("--npz is required (an OGBench raw .npz file)")


def convert(cfg: ConvertConfig):
    repo_id, root = cfg.dataset.resolved(f"local/{Path(cfg.npz).stem}")
    t0 = time.perf_counter()
    ds = convert_npz(cfg.npz, root, repo_id, cfg.fps, cfg.task)
    print(f"{root}: {ds.num_episodes} episodes, {ds.num_frames} frames in {time.perf_counter() - t0:.1f} s")
    return ds


def main(argv: list[str] | None = None):
    """Convert; ``main([...])`` runs in-process and returns the LeRobot dataset."""
    from lerobot_efm.scripts import run_config_cli

    return run_config_cli(ConvertConfig, convert, argv, "lerobot_efm.ogbench.convert")


if __name__ == "__main__":
    main()
