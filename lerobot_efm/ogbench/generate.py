"""JAX-free generator of OGBench pointmaze datasets (the official download server is unreachable offline).

Recipe (OGBench's, re-implemented; see ``datasets_cards/ogbench_pointmaze.md``): OGBench's own MuJoCo maze with
``terminate_at_goal=False``; the "expert" is the unit direction from the point to the BFS oracle subgoal
(``env.unwrapped.get_oracle_subgoal``) plus Gaussian noise (sigma 0.5), clipped to [-1, 1].

- navigate: start in a uniform free cell, goal in a uniform non-corridor ("vertex") cell; a new vertex goal is
  drawn each time the goal is reached. 1000 episodes x 1001 steps.
- stitch: start in a uniform free cell, goal a uniform cell exactly 4 BFS steps away, kept for the whole
  episode (the point hovers there). 5000 episodes x 201 steps.

All randomness comes from the global ``np.random`` (OGBench's env draws start/goal noise from it), which we
seed, plus the env's own ``np_random`` and action space, seeded too: a (name, size, seed) triple gives
bit-identical arrays. Val files hold the next ``num_episodes // 10`` episodes of the same stream.

CLI (generate + convert to LeRobot): ``python -m lerobot_efm.ogbench.generate
--ogbench_dataset=pointmaze-large-navigate-v0 --dataset.root=DIR [--num_episodes=N] [--npz_dir=D]``.
"""

from __future__ import annotations

import time
from collections import deque
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from lerobot_efm.dataset_writer import DatasetTarget
from lerobot_efm.extras import require

NOISE = 0.5  # OGBench's --noise for pointmaze
STITCH_CELLS = 4  # BFS distance of stitch goals
RAW_KEYS = ("observations", "actions", "terminals", "qpos", "qvel")


@dataclass(frozen=True)
class Recipe:
    env_id: str  # OGBench gym id (the dataset name without its dataset type)
    kind: str  # "navigate" or "stitch"
    num_episodes: int  # official number of training episodes
    episode_steps: int  # rows per episode (last row: terminal)


RECIPES: dict[str, Recipe] = {
    "pointmaze-large-navigate-v0": Recipe("pointmaze-large-v0", "navigate", 1000, 1001),
    "pointmaze-large-stitch-v0": Recipe("pointmaze-large-v0", "stitch", 5000, 201),
}


def recipe_of(dataset_name: str) -> Recipe:
    if dataset_name not in RECIPES:
        raise ValueError(f"No local generator for OGBench dataset {dataset_name!r}; valid: {sorted(RECIPES)}")
    return RECIPES[dataset_name]


def free_cells(maze_map: np.ndarray) -> tuple[list[tuple[int, int]], list[tuple[int, int]]]:
    """(all free cells, free cells that are not straight corridor pieces), row-major like OGBench."""
    m = np.asarray(maze_map)
    free = m == 0
    pad = np.pad(free, 1)  # outside the map counts as wall
    up, down, left, right = pad[:-2, 1:-1], pad[2:, 1:-1], pad[1:-1, :-2], pad[1:-1, 2:]
    corridor = free & ((up & down & ~left & ~right) | (left & right & ~up & ~down))
    cells = [tuple(map(int, ij)) for ij in np.argwhere(free)]
    vertices = [tuple(map(int, ij)) for ij in np.argwhere(free & ~corridor)]
    return cells, vertices


def cells_at_distance(maze_map: np.ndarray, source: tuple[int, int], steps: int) -> list[tuple[int, int]]:
    """Free cells exactly ``steps`` 4-connected moves from ``source``, in BFS discovery order."""
    m = np.asarray(maze_map)
    dist = np.full(m.shape, -1, dtype=np.int64)
    dist[source] = 0
    queue, found = deque([source]), []
    while queue:
        i, j = queue.popleft()
        for ni, nj in ((i - 1, j), (i, j - 1), (i + 1, j), (i, j + 1)):
            if 0 <= ni < m.shape[0] and 0 <= nj < m.shape[1] and m[ni, nj] == 0 and dist[ni, nj] < 0:
                dist[ni, nj] = dist[i, j] + 1
                queue.append((ni, nj))
                if dist[ni, nj] == steps:
                    found.append((ni, nj))
    return found


def make_ogbench_env(dataset_name: str, **env_kwargs):
    """OGBench's env for a dataset name, without touching the (offline) dataset server."""
    ogbench = require("ogbench", "ogbench", "OGBench dataset generation")  # lazy: imports cost ~0.3 s

    return ogbench.make_env_and_datasets(dataset_name, env_only=True, **env_kwargs)


def oracle_direction(maze, noise: float = 0.0, exact_goal: bool = False) -> np.ndarray:
    """Unit vector towards the BFS oracle subgoal (+ N(0, noise) from the global RNG), clipped to [-1, 1].

    The subgoal of the goal's own cell is its centre, which a noisy goal can be farther than the success
    radius from: ``exact_goal`` heads for the goal itself there (an evaluation oracle; the data recipe
    keeps OGBench's rule, whose action noise reaches such goals eventually).
    """
    xy = maze.get_xy()
    subgoal, _ = maze.get_oracle_subgoal(xy, maze.cur_goal_xy)
    if exact_goal and maze.xy_to_ij(xy) == maze.xy_to_ij(maze.cur_goal_xy):
        subgoal = np.asarray(maze.cur_goal_xy, dtype=np.float64)
    direction = subgoal - xy
    direction = direction / (np.linalg.norm(direction) + 1e-6)
    if noise > 0:
        direction = direction + np.random.normal(0.0, noise, direction.shape)
    return np.clip(direction, -1.0, 1.0)


def evaluate_oracle(
    dataset: str = "pointmaze-large-navigate-v0", episodes_per_task: int = 2, seed: int = 0
) -> dict[str, float]:
    """The noise-free BFS oracle on OGBench's five tasks (OGBench protocol, ``reward="progress"``): a reference
    row for agent tables. Returns success % and the mean share (%) of the maze distance closed."""
    from .env import TASK_NAMES, OGBenchEnv

    env, successes, closed = OGBenchEnv(dataset, task="all", reward="progress"), [], []
    for k in range(len(TASK_NAMES) * episodes_per_task):
        env.reset(seed=seed + k)
        total, info = 0.0, {"is_success": False}
        for _ in range(1000):
            _, reward, terminated, truncated, info = env.step(oracle_direction(env.maze, exact_goal=True))
            total += reward
            if terminated or truncated:
                break
        successes.append(info["is_success"])
        closed.append(total)
    env.close()
    return {"pc_success": 100.0 * float(np.mean(successes)), "pc_closed": 100.0 * float(np.mean(closed))}


def generate_pointmaze(
    dataset_name: str,
    num_episodes: int | None = None,
    episode_steps: int | None = None,
    noise: float = NOISE,
    seed: int = 0,
) -> dict[str, np.ndarray]:
    """``num_episodes`` episodes of ``episode_steps`` rows in OGBench's raw npz format.

    Defaults are the official sizes. Keys: observations/actions/qpos/qvel float32 [N, 2], terminals bool [N]
    (True on each episode's last row). Seeds the global ``np.random`` (as OGBench's env uses it).
    """
    recipe = recipe_of(dataset_name)
    num_episodes = recipe.num_episodes if num_episodes is None else int(num_episodes)
    episode_steps = recipe.episode_steps if episode_steps is None else int(episode_steps)
    if num_episodes < 1 or episode_steps < 2:
        raise ValueError(
            f"num_episodes must be >= 1 and episode_steps >= 2, got {num_episodes}, {episode_steps}"
        )
    np.random.seed(seed)
    maze = make_ogbench_env(dataset_name, terminate_at_goal=False).unwrapped
    maze.action_space.seed(seed)
    cells, vertices = free_cells(maze.maze_map)

    n = num_episodes * episode_steps
    obs_dim = maze.observation_space.shape[0]
    out = {k: np.empty((n, obs_dim), np.float32) for k in ("observations", "qpos", "qvel")}
    out["actions"] = np.empty((n, 2), np.float32)
    out["terminals"] = np.zeros(n, bool)
    out["terminals"][episode_steps - 1 :: episode_steps] = True

    row = 0
    for ep in tqdm(range(num_episodes), desc=f"{dataset_name} episodes", unit="ep", leave=False):
        init_ij = cells[np.random.randint(len(cells))]
        if recipe.kind == "navigate":
            goal_ij = vertices[np.random.randint(len(vertices))]
        else:
            near = cells_at_distance(maze.maze_map, init_ij, STITCH_CELLS)
            goal_ij = near[np.random.randint(len(near))] if near else init_ij
        ob, _ = maze.reset(
            seed=seed if ep == 0 else None, options={"task_info": {"init_ij": init_ij, "goal_ij": goal_ij}}
        )
        for _ in range(episode_steps):
            action = oracle_direction(maze, noise)
            next_ob, _, _, _, info = maze.step(action)
            if (
                recipe.kind == "navigate" and info["success"]
            ):  # reached: draw the next goal (noisy, like reset)
                new_goal = vertices[np.random.randint(len(vertices))]
                maze.set_goal(goal_xy=maze.add_noise(maze.ij_to_xy(new_goal)))
            out["observations"][row] = ob
            out["actions"][row] = action
            out["qpos"][row] = info["prev_qpos"]
            out["qvel"][row] = info["prev_qvel"]
            ob = next_ob
            row += 1
    maze.close()
    return out


def split_episodes(data: dict[str, np.ndarray], num_first: int) -> tuple[dict, dict]:
    """Split raw arrays after the ``num_first``-th episode (terminal row)."""
    ends = np.flatnonzero(data["terminals"]) + 1
    if not 0 <= num_first <= len(ends):
        raise ValueError(f"cannot split {len(ends)} episodes after episode {num_first}")
    cut = int(ends[num_first - 1]) if num_first else 0
    return {k: v[:cut] for k, v in data.items()}, {k: v[cut:] for k, v in data.items()}


def save_pointmaze_npz(
    dataset_name: str,
    out_dir: str | Path,
    num_episodes: int | None = None,
    episode_steps: int | None = None,
    noise: float = NOISE,
    seed: int = 0,
) -> tuple[Path, Path]:
    """Write ``<out_dir>/<name>.npz`` (num_episodes) and ``<name>-val.npz`` (num_episodes // 10) like OGBench.

    ``ogbench.make_env_and_datasets(name, dataset_path=<out_dir>/<name>.npz)`` loads them (needs >= 10 episodes,
    else the val file is empty and OGBench's loader fails).
    """
    num_episodes = recipe_of(dataset_name).num_episodes if num_episodes is None else int(num_episodes)
    data = generate_pointmaze(dataset_name, num_episodes + num_episodes // 10, episode_steps, noise, seed)
    train, val = split_episodes(data, num_episodes)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = out_dir / f"{dataset_name}.npz", out_dir / f"{dataset_name}-val.npz"
    for path, arrays in zip(paths, (train, val), strict=True):
        np.savez_compressed(path, **arrays)
    return paths


@dataclass
class GenerateConfig:
    """``python -m lerobot_efm.ogbench.generate --ogbench_dataset=pointmaze-large-navigate-v0
    --dataset.root=DIR [--num_episodes=N] [--episode_steps=T]``: generate, then convert to LeRobot v3."""

    ogbench_dataset: str = ""  # one of RECIPES
    dataset: DatasetTarget = field(default_factory=DatasetTarget)  # default repo id: local/<ogbench_dataset>
    num_episodes: int | None = None  # training episodes (default: the official size)
    episode_steps: int | None = None  # rows per episode (default: official)
    noise: float = NOISE
    seed: int = 0
    npz_dir: str | None = None  # where the raw npz files go (default: <root>-npz)
    fps: int | None = None  # dataset fps (default: lerobot_efm.ogbench.convert.FPS)

    def __post_init__(self):
        if self.ogbench_dataset not in RECIPES:
            raise ValueError(f"--ogbench_dataset={self.ogbench_dataset!r}: expected one of {sorted(RECIPES)}")


def generate(cfg: GenerateConfig):
    from .convert import FPS, convert_npz

    repo_id, root = cfg.dataset.resolved(f"local/{cfg.ogbench_dataset}")
    npz_dir = Path(cfg.npz_dir) if cfg.npz_dir else Path(f"{root}-npz")
    t0 = time.perf_counter()
    train_path, val_path = save_pointmaze_npz(
        cfg.ogbench_dataset, npz_dir, cfg.num_episodes, cfg.episode_steps, cfg.noise, cfg.seed
    )
    t1 = time.perf_counter()
    ds = convert_npz(train_path, root, repo_id=repo_id, fps=cfg.fps or FPS, task=cfg.ogbench_dataset)
    t2 = time.perf_counter()
    print(f"{train_path}, {val_path}: generated in {t1 - t0:.1f} s")
    print(f"{root}: {ds.num_episodes} episodes, {ds.num_frames} frames, converted in {t2 - t1:.1f} s")
    return ds


def main(argv: list[str] | None = None):
    """Generate and convert; ``main([...])`` runs in-process and returns the LeRobot dataset."""
    from lerobot_efm.scripts import run_config_cli

    return run_config_cli(GenerateConfig, generate, argv, "lerobot_efm.ogbench.generate")


if __name__ == "__main__":
    main()
