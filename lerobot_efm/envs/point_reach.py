"""PointReach: a tiny 2-D goal-reaching env, the embedded default for demos and end-to-end tests.

A point moves in [-1, 1]^2 towards absolute position commands (as in the paper's planar push),
at most ``MAX_STEP`` per step. An optional wall (x = 0, y < ``WALL_TOP``) makes shortest paths
non-trivial. Plain numpy so it is fast, deterministic and needs no simulator.

LeRobot key mapping (via ``lerobot.envs.utils.preprocess_observation``):
``agent_pos`` -> ``observation.state``; ``goal.state`` -> ``observation.goal.state``;
``pixels`` = {"top": img} -> ``observation.images.top``; ``goal.images.top`` arrives as a raw float
HWC array under ``observation.goal.images.top`` and the env processor step of
:class:`PointReachEnvConfig` turns it into CHW in [0, 1] like the other camera.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs import PolicyFeature
from lerobot.envs.configs import EnvConfig

from .goal_env import (  # noqa: F401  (GoalImagesChannelFirstStep re-exported)
    GoalEnvConfig,
    GoalImagesChannelFirstStep,
    add_camera_features,
    goal_image_key,
    state_goal_features,
    state_goal_features_map,
)

GYM_ID = "lerobot_efm/PointReach-v0"
MAX_STEP = 0.05  # max displacement per step
SUCCESS_RADIUS = 0.05
WALL_HALF_WIDTH = 0.02  # the wall occupies |x| < WALL_HALF_WIDTH, y < WALL_TOP
WALL_TOP = 0.4
AGENT_RADIUS = 0.07  # drawing only: the point is a disc in images
OBS_TYPES = ("state", "pixels_state")
GOAL_STATE_KEY = "goal.state"  # env key; becomes observation.goal.state
GOAL_IMAGE_KEY = "goal.images.top"  # env key; becomes observation.goal.images.top
OBS_GOAL_IMAGE = goal_image_key("top")

# Named tasks: (nominal start, nominal goal, description). Each reset jitters both by up to
# TASK_JITTER so that repeated evaluation episodes are not identical copies.
TASKS: dict[str, tuple[tuple[float, float] | None, tuple[float, float] | None, str]] = {
    "random": (None, None, "reach the goal position"),
    "around_wall": ((-0.5, -0.6), (0.5, -0.6), "go around the wall to the goal on the other side"),
    "short": ((-0.65, 0.7), (-0.05, 0.7), "reach the nearby goal"),
    "diagonal": ((-0.8, 0.8), (0.8, -0.8), "cross the whole arena to the opposite corner"),
}
TASK_JITTER = 0.05
MIN_START_GOAL_DIST = 0.5


def check_task(task: str | None) -> str:
    if task not in TASKS:
        raise ValueError(f"Unknown PointReach task {task!r}; valid tasks: {sorted(TASKS)}")
    return task


def in_wall(p: np.ndarray, margin: float = 0.0, wall: bool = True) -> bool:
    """Whether ``p`` lies strictly inside the wall dilated by ``margin``."""
    return bool(wall and abs(p[0]) < WALL_HALF_WIDTH + margin and p[1] < WALL_TOP + margin)


def move_point(p: np.ndarray, command: np.ndarray, wall: bool = True) -> np.ndarray:
    """One step of dynamics: move toward ``command`` by at most MAX_STEP, blocked by the wall.

    Motion is resolved per axis (x then y) against the wall box, so the point slides along it and
    can never tunnel through, whatever the step length.
    """
    p = np.asarray(p, dtype=np.float64)
    delta = np.clip(np.asarray(command, dtype=np.float64), -1.0, 1.0) - p
    norm = float(np.linalg.norm(delta))
    if norm > MAX_STEP:
        delta *= MAX_STEP / norm
    x, y = float(np.clip(p[0] + delta[0], -1.0, 1.0)), float(p[1])
    if wall and y < WALL_TOP:  # horizontal move at height y: stop at the wall face
        if p[0] <= -WALL_HALF_WIDTH and x > -WALL_HALF_WIDTH:
            x = -WALL_HALF_WIDTH
        elif p[0] >= WALL_HALF_WIDTH and x < WALL_HALF_WIDTH:
            x = WALL_HALF_WIDTH
    y = float(np.clip(p[1] + delta[1], -1.0, 1.0))
    if wall and abs(x) < WALL_HALF_WIDTH and y < WALL_TOP:  # vertical move above the wall: land on top
        y = WALL_TOP
    return np.array([x, y])


def segment_hits_wall(a: np.ndarray, b: np.ndarray, margin: float = 0.03, wall: bool = True) -> bool:
    """Whether the straight segment a->b passes through the (dilated) wall; used by planners."""
    if not wall:
        return False
    ts = np.linspace(0.0, 1.0, 64)[:, None]
    pts = (1 - ts) * np.asarray(a)[None] + ts * np.asarray(b)[None]
    return bool(np.any((np.abs(pts[:, 0]) < WALL_HALF_WIDTH + margin) & (pts[:, 1] < WALL_TOP + margin)))


def sample_free(rng: np.random.Generator, wall: bool = True, margin: float = 0.05) -> np.ndarray:
    """Uniform position in free space, away from the wall by ``margin``."""
    while True:
        p = rng.uniform(-0.95, 0.95, size=2)
        if not in_wall(p, margin, wall):
            return p


@lru_cache(maxsize=8)
def _background(size: int, wall: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Static background image and the world coordinates of pixel centres (cached per size)."""
    coords = (np.arange(size) + 0.5) / size * 2.0 - 1.0
    xs, ys = np.meshgrid(coords, -coords)  # row 0 is the top (y = +1)
    img = np.full((size, size, 3), 235, dtype=np.uint8)
    if wall:
        half = max(WALL_HALF_WIDTH, 1.0 / size)  # pixel centres nearest x=0 are at +-1/size
        img[(np.abs(xs) <= half) & (ys < WALL_TOP)] = (60, 60, 60)
    img.flags.writeable = False
    return img, xs, ys


def _draw_disc(img: np.ndarray, xs, ys, center, radius: float, color, size: int) -> None:
    dist_px = np.hypot(xs - center[0], ys - center[1]) * size / 2.0
    alpha = np.clip(radius * size / 2.0 + 0.5 - dist_px, 0.0, 1.0)[..., None]  # anti-aliased edge
    img[:] = (img * (1 - alpha) + np.asarray(color, np.float32) * alpha).astype(np.uint8)


def render_scene(pos, size: int = 64, wall: bool = True, goal=None) -> np.ndarray:
    """Top-down RGB uint8 (size, size, 3) image: background, wall, point; ``goal`` adds a marker.

    Observations never show the goal marker, so goal images equal observation images of the goal.
    """
    bg, xs, ys = _background(int(size), bool(wall))
    img = bg.copy()
    if goal is not None:
        _draw_disc(img, xs, ys, goal, AGENT_RADIUS * 0.6, (40, 170, 60), size)
    _draw_disc(img, xs, ys, pos, AGENT_RADIUS, (210, 40, 40), size)
    return img


class PointReachEnv(gym.Env):
    """Goal-conditioned point reaching; success (and termination) when |p - goal| < SUCCESS_RADIUS.

    ``reset(options={"start": xy, "goal": xy})`` pins the start and/or goal (e.g. for scripted tests).
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 20}

    def __init__(
        self,
        task: str = "random",
        obs_type: str = "state",
        image_size: int = 64,
        wall: bool = True,
        render_mode: str = "rgb_array",
        render_size: int = 256,
    ):
        self.task = check_task(task)
        self.task_description = TASKS[task][2]
        if obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown obs_type {obs_type!r}; valid: {list(OBS_TYPES)}")
        self.obs_type, self.image_size, self.wall = obs_type, int(image_size), bool(wall)
        self.render_mode, self.render_size = render_mode, int(render_size)
        box = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        obs = {"agent_pos": box, GOAL_STATE_KEY: box}
        if obs_type == "pixels_state":
            img = spaces.Box(0, 255, shape=(self.image_size, self.image_size, 3), dtype=np.uint8)
            obs["pixels"] = spaces.Dict({"top": img})
            obs[GOAL_IMAGE_KEY] = img
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.pos = np.zeros(2)
        self.goal = np.zeros(2)
        self._goal_img: np.ndarray | None = None

    def _sample_task(self, options: dict) -> tuple[np.ndarray, np.ndarray]:
        start, goal, _ = TASKS[self.task]
        if start is None:
            start = sample_free(self.np_random, self.wall)
            while True:
                goal = sample_free(self.np_random, self.wall)
                if np.linalg.norm(goal - start) >= MIN_START_GOAL_DIST:
                    break
        else:
            start = np.asarray(start) + self.np_random.uniform(-TASK_JITTER, TASK_JITTER, 2)
            goal = np.asarray(goal) + self.np_random.uniform(-TASK_JITTER, TASK_JITTER, 2)
        if options.get("start") is not None:
            start = np.asarray(options["start"], dtype=np.float64)
        if options.get("goal") is not None:
            goal = np.asarray(options["goal"], dtype=np.float64)
        for name, p in (("start", start), ("goal", goal)):
            if p.shape != (2,) or np.any(np.abs(p) > 1) or in_wall(p, 0.0, self.wall):
                raise ValueError(f"PointReach {name} {p.tolist()} is not a free position in [-1,1]^2")
        return start, goal

    def observe(self) -> dict:
        """The current observation (e.g. after :meth:`set_position`)."""
        return self._obs()

    def set_position(self, pos) -> None:
        """Put the point at a free position (scripted operators choose where an episode starts)."""
        pos = np.asarray(pos, dtype=np.float64)
        if pos.shape != (2,) or np.any(np.abs(pos) > 1) or in_wall(pos, 0.0, self.wall):
            raise ValueError(f"PointReach position {pos.tolist()} is not a free position in [-1,1]^2")
        self.pos = pos

    def _obs(self) -> dict:
        obs = {"agent_pos": self.pos.astype(np.float32), GOAL_STATE_KEY: self.goal.astype(np.float32)}
        if self.obs_type == "pixels_state":
            obs["pixels"] = {"top": render_scene(self.pos, self.image_size, self.wall)}
            obs[GOAL_IMAGE_KEY] = self._goal_img.copy()  # callers may keep/modify it
        return obs

    def _info(self) -> dict:
        dist = float(np.linalg.norm(self.pos - self.goal))
        return {"is_success": dist < SUCCESS_RADIUS, "distance": dist}

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        self.pos, self.goal = self._sample_task(options or {})
        if self.obs_type == "pixels_state":
            self._goal_img = render_scene(self.goal, self.image_size, self.wall)
        return self._obs(), self._info()

    def step(self, action):
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ValueError(f"PointReach action must be 2 finite numbers (x, y), got {np.asarray(action)!r}")
        self.pos = move_point(self.pos, a, self.wall)
        info = self._info()
        return self._obs(), float(info["is_success"]), info["is_success"], False, info

    def render(self) -> np.ndarray:
        return render_scene(self.pos, self.render_size, self.wall, goal=self.goal)


@EnvConfig.register_subclass("efm_point_reach")
@dataclass
class PointReachEnvConfig(GoalEnvConfig):
    """LeRobot config: ``--env.type=efm_point_reach --env.task=around_wall --env.obs_type=pixels_state``."""

    GYM_ID: ClassVar[str] = GYM_ID
    MODULE: ClassVar[str] = "lerobot_efm.envs"

    task: str | None = "random"
    fps: int = 20
    episode_length: int = 200
    obs_type: str = "state"
    image_size: int = 64
    wall: bool = True
    render_mode: str = "rgb_array"
    features: dict[str, PolicyFeature] = field(default_factory=lambda: state_goal_features(2, 2))
    features_map: dict[str, str] = field(default_factory=lambda: state_goal_features_map("top"))

    def __post_init__(self):
        check_task(self.task)
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown obs_type {self.obs_type!r}; valid: {list(OBS_TYPES)}")
        if self.obs_type == "pixels_state":
            add_camera_features(self.features, "top", self.image_size)

    @property
    def gym_kwargs(self) -> dict:
        return {
            "task": self.task,
            "obs_type": self.obs_type,
            "image_size": self.image_size,
            "wall": self.wall,
            "render_mode": self.render_mode,
            "max_episode_steps": self.episode_length,
        }


if GYM_ID not in gym.registry:
    gym.register(id=GYM_ID, entry_point="lerobot_efm.envs.point_reach:PointReachEnv", max_episode_steps=200)
