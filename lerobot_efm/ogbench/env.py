"""LeRobot env type ``ogbench``: OGBench's goal-reaching evaluation tasks (state-based pointmaze).

A thin gymnasium wrapper around ``ogbench.make_env_and_datasets(dataset, env_only=True)`` that speaks this
plugin's keys: ``agent_pos`` (OGBench observation -> ``observation.state``) and ``goal.state``
(``info["goal"]`` -> ``observation.goal.state``); ``info["is_success"]`` is OGBench's ``info["success"]``.
OGBench protocol: 5 fixed tasks (``reset(options={"task_id": k})``), termination at the goal, 1000 steps,
actions clipped to [-1, 1] (velocity commands: train with ``action_mode="velocity"``).

OGBench draws start/goal noise from the *global* ``np.random``: a seeded reset seeds it, so evaluation with
LeRobot's seeds is reproducible. With ``task="all"`` a seeded reset runs task ``seed % 5 + 1`` (lerobot-eval's
consecutive seeds cycle the five tasks, also across a batch of envs); unseeded resets take the next task.

Reward: ``"success"`` (default) is OGBench's own. ``"progress"`` is the share of the start's maze distance to the
goal closed by the step, counted in cells along OGBench's own BFS map (walls respected, teleporters ignored),
so lerobot-eval's ``sum_reward`` is 1 - cells_end / cells_start: a graded score for budgets too small to succeed.

``ogbench`` (MuJoCo, dm_control) is imported only when an env is built. Renders are a cheap top-down map
(walls, goal disc of the success radius, agent), since MuJoCo's software rendering costs ~0.2 s a frame;
``render_backend="mujoco"`` gives OGBench's camera view instead.

    lerobot-eval --policy.path=... --env.type=ogbench --env.dataset=pointmaze-large-navigate-v0 --env.task=all
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_STATE

from lerobot_efm.envs.goal_env import OBS_GOAL_STATE, GoalEnvConfig
from lerobot_efm.extras import require

GYM_ID = "lerobot_efm/OGBench-v0"
GOAL_STATE_KEY = "goal.state"  # env key; becomes observation.goal.state
FPS = 10  # point env's render_fps (5 substeps of 0.02 s per action)
TASK_NAMES = ("task1", "task2", "task3", "task4", "task5")
TASKS = (*TASK_NAMES, "all")
RENDER_BACKENDS = ("map", "mujoco")
REWARDS = ("success", "progress")
CELL_PX = 24  # map render: pixels per maze cell

# dataset name -> (observation dim, action dim, OGBench episode limit). Env-only: any of these evaluates.
DATASETS: dict[str, tuple[int, int, int]] = {
    f"pointmaze-{maze}-{kind}-v0": (2, 2, 1000)
    for maze in ("medium", "large", "giant", "teleport")
    for kind in ("navigate", "stitch")
}


def check_dataset(dataset: str) -> str:
    if dataset not in DATASETS:
        raise ValueError(
            f"Unknown OGBench dataset {dataset!r} for env type 'ogbench'; valid: {sorted(DATASETS)}"
        )
    return dataset


def check_task(task: str | None) -> str:
    if task not in TASKS:
        raise ValueError(f"Unknown OGBench task {task!r}; valid tasks: {list(TASKS)}")
    return task


class OGBenchEnv(gym.Env):
    """OGBench env with this plugin's observation keys; ``maze`` is the underlying OGBench ``MazeEnv``."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(
        self,
        dataset: str = "pointmaze-large-navigate-v0",
        task: str = "all",
        render_backend: str = "map",
        render_mode: str = "rgb_array",
        reward: str = "success",
    ):
        self.dataset, self.task = check_dataset(dataset), check_task(task)
        if reward not in REWARDS:
            raise ValueError(f"Unknown reward {reward!r}; valid: {list(REWARDS)}")
        self.reward_type = reward
        if render_backend not in RENDER_BACKENDS:
            raise ValueError(f"Unknown render_backend {render_backend!r}; valid: {list(RENDER_BACKENDS)}")
        self.render_backend, self.render_mode = render_backend, render_mode
        obs_dim, act_dim, _ = DATASETS[dataset]
        ogbench = require("ogbench", "ogbench", "the OGBench environment")  # lazy: MuJoCo + dm_control

        self.maze = ogbench.make_env_and_datasets(dataset, env_only=True, terminate_at_goal=True).unwrapped
        box = spaces.Box(-np.inf, np.inf, shape=(obs_dim,), dtype=np.float32)
        self.observation_space = spaces.Dict({"agent_pos": box, GOAL_STATE_KEY: box})
        self.action_space = spaces.Box(-1.0, 1.0, shape=(act_dim,), dtype=np.float32)
        self._next_task = 0  # unseeded resets with task="all" cycle from task1
        self.task_id = 1 if task == "all" else TASK_NAMES.index(task) + 1
        self.task_description = self._describe(self.task_id)
        self._goal = np.zeros(obs_dim, np.float32)
        self._map: np.ndarray | None = None
        self._cells_to_goal: np.ndarray | None = None  # BFS cell distances to the goal (progress reward)
        self._initial_cells = self._last_cells = 1

    def _describe(self, task_id: int) -> str:
        info = self.maze.task_infos[task_id - 1]
        return f"{self.dataset} {info['task_name']}: reach cell {tuple(info['goal_ij'])} from cell {tuple(info['init_ij'])}"

    def _pick_task(self, seed: int | None, options: dict) -> int:
        if options.get("task_id") is not None:
            k = int(options["task_id"])
            if not 1 <= k <= len(TASK_NAMES):
                raise ValueError(f"task_id must be in 1..{len(TASK_NAMES)}, got {options['task_id']!r}")
            return k
        if self.task != "all":
            return TASK_NAMES.index(self.task) + 1
        if seed is not None:
            return seed % len(TASK_NAMES) + 1
        k, self._next_task = self._next_task + 1, (self._next_task + 1) % len(TASK_NAMES)
        return k

    def _obs(self, ob) -> dict:
        return {"agent_pos": np.asarray(ob, np.float32), GOAL_STATE_KEY: self._goal.copy()}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        if seed is not None:  # OGBench's start/goal noise uses the global RNG
            np.random.seed(seed)
            self.maze.action_space.seed(seed)
        self.task_id = self._pick_task(seed, options)
        self.task_description = self._describe(self.task_id)
        ob, info = self.maze.reset(seed=seed, options={"task_id": self.task_id, "render_goal": False})
        self._goal = np.asarray(info["goal"], np.float32)
        if self.reward_type == "progress":
            self._cells_to_goal = self.maze.get_oracle_subgoal(self.maze.get_xy(), self.maze.cur_goal_xy)[1]
            self._initial_cells = self._last_cells = self._cells_from_goal()
        return self._obs(ob), {"is_success": False, "task_id": self.task_id}

    def _cells_from_goal(self) -> int:
        i, j = self.maze.xy_to_ij(self.maze.get_xy())
        return int(self._cells_to_goal[i, j])

    def _progress(self, success: bool) -> float:
        cells = 0 if success else self._cells_from_goal()
        before, self._last_cells = self._last_cells, cells
        return (before - cells) / max(self._initial_cells, 1)

    def step(self, action):
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != self.action_space.shape or not np.all(np.isfinite(a)):
            raise ValueError(
                f"OGBench action must be {self.action_space.shape[0]} finite numbers, got {np.asarray(action)!r}"
            )
        ob, reward, terminated, truncated, info = self.maze.step(np.clip(a, -1.0, 1.0))
        success = bool(info["success"])
        if self.reward_type == "progress":
            reward = self._progress(success)
        return (
            self._obs(ob),
            float(reward),
            bool(terminated),
            bool(truncated),
            {"is_success": success, "task_id": self.task_id},
        )

    def render(self) -> np.ndarray:
        if self.render_backend == "mujoco":
            return self.maze.render()
        return self._render_map()

    def _render_map(self) -> np.ndarray:
        """Top-down RGB uint8 map: walls, goal disc (success radius), agent."""
        m = self.maze
        if self._map is None:
            walls = np.kron(
                np.asarray(m.maze_map)[::-1] == 1, np.ones((CELL_PX, CELL_PX), bool)
            )  # row 0 = top
            img = np.full((*walls.shape, 3), 235, np.uint8)
            img[walls] = (70, 70, 70)
            self._map = img
        img = self._map.copy()
        h, w = img.shape[:2]
        unit = m._maze_unit
        xs = (np.arange(w) + 0.5) / CELL_PX * unit - 0.5 * unit - m._offset_x
        ys = ((h - np.arange(h) - 0.5) / CELL_PX * unit - 0.5 * unit - m._offset_y)[:, None]
        for center, radius, color in (
            (m.cur_goal_xy, m._goal_tol, (40, 170, 60)),
            (m.get_xy(), 0.35 * unit / 2, (210, 40, 40)),
        ):
            img[np.hypot(xs - center[0], ys - center[1]) <= radius] = color
        return img

    def close(self):
        self.maze.close()


@EnvConfig.register_subclass("ogbench")
@dataclass
class OGBenchEnvConfig(GoalEnvConfig):
    """``--env.type=ogbench --env.dataset=pointmaze-large-stitch-v0 --env.task=task3`` (or ``all``)."""

    GYM_ID: ClassVar[str] = GYM_ID
    MODULE: ClassVar[str] = "lerobot_efm.ogbench"

    dataset: str = "pointmaze-large-navigate-v0"
    task: str | None = "all"
    fps: int = FPS
    episode_length: int = 1000  # OGBench's limit for mazes
    render_backend: str = "map"
    render_mode: str = "rgb_array"
    reward: str = "success"  # or "progress": share of the maze distance to the goal closed (module docstring)
    features: dict[str, PolicyFeature] = field(default_factory=dict)
    features_map: dict[str, str] = field(
        default_factory=lambda: {ACTION: ACTION, "agent_pos": OBS_STATE, GOAL_STATE_KEY: OBS_GOAL_STATE}
    )

    def __post_init__(self):
        check_dataset(self.dataset)
        check_task(self.task)
        if self.render_backend not in RENDER_BACKENDS:
            raise ValueError(
                f"Unknown render_backend {self.render_backend!r}; valid: {list(RENDER_BACKENDS)}"
            )
        if self.reward not in REWARDS:
            raise ValueError(f"Unknown --env.reward={self.reward!r}; valid: {list(REWARDS)}")
        obs_dim, act_dim, _ = DATASETS[self.dataset]
        self.features = {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(act_dim,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(obs_dim,)),
            GOAL_STATE_KEY: PolicyFeature(type=FeatureType.STATE, shape=(obs_dim,)),
        }

    @property
    def gym_kwargs(self) -> dict:
        return {
            "dataset": self.dataset,
            "task": self.task,
            "render_backend": self.render_backend,
            "render_mode": self.render_mode,
            "reward": self.reward,
            "max_episode_steps": self.episode_length,
        }


if GYM_ID not in gym.registry:
    gym.register(id=GYM_ID, entry_point="lerobot_efm.ogbench.env:OGBenchEnv", max_episode_steps=1000)
