"""TalosKitchen: goal-conditioned gymnasium env of the MuJoCo Talos kitchen (left-hand Cartesian control).

Importing this module registers the gym id :data:`GYM_ID` and the LeRobot ``EnvConfig`` type
``talos_kitchen`` but does **not** import MuJoCo (that happens when an env is constructed; set
``MUJOCO_GL`` before, ``egl`` is the default set here if unset).

Action (10-D, float32, world frame): absolute left-TCP pose command = position (3) + 6-D rotation
(``R[:, 0], R[:, 1]``) (6) + gripper (1; 0 open .. 1 closed), tracked by
:class:`~.control.CartesianController` for one control period (20 x 2 ms = 25 Hz). Positions outside
the controller workspace are clipped; NaN/inf entries raise ``ValueError`` naming them.

Observation (gym Dict; LeRobot key after ``preprocess_observation`` + :meth:`TalosKitchenEnvConfig.get_env_processors`):

======================================  ==========================================  ===========================
env key                                 LeRobot key                                 content
======================================  ==========================================  ===========================
``pixels`` = {"front": uint8 HWC}       ``observation.images.front``                (B, 3, H, W) float [0, 1]
``agent_pos`` (20,) float32             ``observation.state``                       :data:`STATE_NAMES`
``environment_state`` (9,) float32      ``observation.environment_state``           :data:`ENV_STATE_NAMES`
``goal.images.front`` uint8 HWC         ``observation.goal.images.front``           (B, 3, H, W) float [0, 1]
``goal.state`` (20,) float32            ``observation.goal.state``                  same layout as the state
``goal.environment_state`` (9,)         ``observation.goal.environment_state``      same layout
======================================  ==========================================  ===========================

State layout (20): commanded hand pose ``cmd_x, cmd_y, cmd_z, cmd_r00, cmd_r10, cmd_r20, cmd_r01,
cmd_r11, cmd_r21`` (the command actually tracked: clipped position, Gram-Schmidt rot6d) +
``cmd_gripper`` (clipped to [0, 1]), then the measured TCP pose ``x .. r21`` + ``gripper``
(measured closure in [0, 1]). After a reset the command equals the measured pose (hold).

Environment state (9): ``door`` (rad, 0 closed, negative open), ``tray`` (m, 0 in, negative out),
pot base centre ``pot_x, pot_y, pot_z`` and quaternion ``pot_qw, pot_qx, pot_qy, pot_qz``.

``obs_type="state"`` leaves out ``pixels`` and the goal image (nothing rendered for the policy: a frame costs
~25 ms on a CPU, whatever its size, against ~4 ms of physics per step).

Video frames (:meth:`render`): ``lerobot-eval`` renders one after every step of its first 10 episodes, which
was 3/4 of a state policy's evaluation time. ``video_frame_stride=k`` renders a new frame every k-th step since
the reset and repeats it in between (videos at 25/k frames/s of content, same length); a frame of the current
scene that the observation already rendered at the same size is reused instead of rendered twice.

Goal observations are rendered by putting the scene in the goal state (set qpos, settle), reading
image + state, then setting the initial state; they are cached per reset.
``info["is_success"]``: |door - goal| < 0.15 rad, |tray - goal| < 0.03 m and pot-position distance
< 0.05 m (:mod:`.tasks` tolerances; pot orientation is not checked). Success terminates the
episode (reward 1).

``task="all"`` cycles through :data:`.tasks.TASK_NAMES` across resets (reset count);
``reset(options={"task": name})`` picks a task for one episode. ``task`` / ``task_description``
always name the current task.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field, replace
from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs import FeatureType, PolicyFeature
from lerobot.envs.configs import EnvConfig
from lerobot.utils.constants import ACTION, OBS_ENV_STATE, OBS_IMAGES, OBS_STATE

from ...extras import require
from ..goal_env import OBS_GOAL_ENV_STATE, OBS_GOAL_STATE, GoalEnvConfig, goal_image_key
from .tasks import (
    ALL,
    DOOR_TOL,
    POT_TOL,
    TASK_NAMES,
    TASKS,
    TRAY_TOL,
    KitchenState,
    KitchenTask,
    check_task,
    describe,
)

GYM_ID = "lerobot_efm/TalosKitchen-v0"
DEFAULT_EPISODE_STEPS = 600  # 24 s at 25 Hz: gym.make's limit
STEPS_PER_OBJECT = 500  # 20 s at 25 Hz: lerobot-eval's default limit per object a task moves
CONTROL_FPS = 25
CAMERA = "front"
# "state" drops the camera and the goal image: a state policy's evaluation then renders nothing per step
OBS_TYPES = ("pixels_state", "state")
STATE_NAMES = tuple(
    f"cmd_{n}" for n in ("x", "y", "z", "r00", "r10", "r20", "r01", "r11", "r21", "gripper")
) + ("x", "y", "z", "r00", "r10", "r20", "r01", "r11", "r21", "gripper")
ENV_STATE_NAMES = ("door", "tray", "pot_x", "pot_y", "pot_z", "pot_qw", "pot_qx", "pot_qy", "pot_qz")
STATE_DIM, ENV_STATE_DIM, ACTION_DIM = len(STATE_NAMES), len(ENV_STATE_NAMES), 10
GOAL_STATE_KEY = "goal.state"
GOAL_ENV_STATE_KEY = "goal.environment_state"
GOAL_IMAGE_KEY = f"goal.images.{CAMERA}"
OBS_GOAL_IMAGE = goal_image_key(CAMERA)
SETTLE_STEPS = 5  # control steps (0.2 s) of physics after setting a state directly
TRAY_FLOOR = 0.009  # pot base height above the tray body origin (tray floor top 0.008 + 1 mm)
TABLE_CLEARANCE = 0.001
POT_JITTER_XY = 0.01  # m, uniform jitter of table placements per reset (randomize=True)
POT_JITTER_YAW = 0.1  # rad


class TalosKitchenEnv(gym.Env):
    """Goal-conditioned Talos kitchen; see the module docstring for spaces and success."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": CONTROL_FPS}

    def __init__(
        self,
        task: str = "open_door",
        image_size: int = 128,
        render_mode: str = "rgb_array",
        render_size: int | None = None,
        randomize: bool = True,
        terminate_on_success: bool = True,
        obs_type: str = "pixels_state",
        video_frame_stride: int = 1,
    ):
        self.suite = check_task(task)
        if obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown obs_type {obs_type!r}; valid: {list(OBS_TYPES)}")
        self.obs_type = obs_type
        if int(video_frame_stride) != video_frame_stride or video_frame_stride < 1:
            raise ValueError(f"video_frame_stride must be an integer >= 1, got {video_frame_stride!r}")
        self.video_frame_stride = int(video_frame_stride)
        self._reset_count = 0
        self._steps = 0  # steps since the reset
        self._scene_version = 0  # bumped by every change of the physics state: which frames are current
        self._obs_frame: tuple[int, np.ndarray] | None = None  # (scene version, camera frame) of the last obs
        # ((reset, step // stride), frame) of the last video frame
        self._video_frame: tuple[tuple[int, int], np.ndarray] | None = None
        self._set_current(TASK_NAMES[0] if task == ALL else task)
        if render_mode != "rgb_array":
            raise ValueError(f"render_mode must be 'rgb_array', got {render_mode!r}")
        os.environ.setdefault("MUJOCO_GL", "egl")
        from . import control, grasps, scene  # imports MuJoCo

        self._scene, self._control, self._grasps = scene, control, grasps
        self.image_size = int(image_size)
        self.render_mode = render_mode
        self.render_size = int(render_size or image_size)
        self.randomize, self.terminate_on_success = bool(randomize), bool(terminate_on_success)
        # the compiled model only depends on image_size through its offscreen buffer (>= 640 x 480):
        # sharing the 128 build avoids a recompilation per image size
        big = max(self.image_size, self.render_size)
        self.model, self.data, self.h = scene.build_kitchen(big if big > 480 else 128)
        self.controller = control.CartesianController(self.model, self.h)
        self._renderer = scene.KitchenRenderer(self.model, self.image_size)
        self._render_renderer = (
            self._renderer
            if self.render_size == self.image_size
            else scene.KitchenRenderer(self.model, self.render_size)
        )
        self._tray_body = self.model.body("tray").id
        mujoco = require("mujoco", "talos", "the Talos kitchen")

        self._mj = mujoco
        self._home_cmd = control.hand_pose10(self.data, self.h)  # data is at home after build_kitchen

        img = spaces.Box(0, 255, shape=(self.image_size, self.image_size, 3), dtype=np.uint8)
        state = spaces.Box(-np.inf, np.inf, shape=(STATE_DIM,), dtype=np.float32)
        env_state = spaces.Box(-np.inf, np.inf, shape=(ENV_STATE_DIM,), dtype=np.float32)
        spaces_ = {
            "agent_pos": state,
            "environment_state": env_state,
            GOAL_STATE_KEY: state,
            GOAL_ENV_STATE_KEY: env_state,
        }
        if self.obs_type == "pixels_state":
            spaces_.update({"pixels": spaces.Dict({CAMERA: img}), GOAL_IMAGE_KEY: img})
        self.observation_space = spaces.Dict(spaces_)
        low = np.concatenate([control.WORKSPACE_LOW, -np.ones(6), [0.0]]).astype(np.float32)
        high = np.concatenate([control.WORKSPACE_HIGH, np.ones(6), [1.0]]).astype(np.float32)
        self.action_space = spaces.Box(low, high, dtype=np.float32)

        self._cmd = self._home_cmd.copy()
        self._goal_img = np.zeros((self.image_size, self.image_size, 3), np.uint8)
        self._goal_state = np.zeros(STATE_DIM, np.float32)
        self._goal_env = np.zeros(ENV_STATE_DIM, np.float32)
        self._goal_snapshot: tuple | None = None
        self._initial_snapshot: tuple | None = None
        # dataset names of the recorded vectors (lerobot-efm-record)
        self.feature_names = {
            "observation.state": list(STATE_NAMES),
            "observation.environment_state": list(ENV_STATE_NAMES),
            "action": list(STATE_NAMES[10:]),
        }

    # ------------------------------------------------------------------------------ task / state
    def _set_current(self, name: str) -> None:
        self.task = name
        self.task_description = describe(name)

    @property
    def current_task(self) -> KitchenTask:
        return TASKS[self.task]

    def _jitter(self, state: KitchenState) -> KitchenState:
        if not self.randomize or state.pot_on != "table":
            return state
        dxy = self.np_random.uniform(-POT_JITTER_XY, POT_JITTER_XY, 2)
        yaw = state.pot_yaw + float(self.np_random.uniform(-POT_JITTER_YAW, POT_JITTER_YAW))
        return replace(state, pot_xy=(state.pot_xy[0] + dxy[0], state.pot_xy[1] + dxy[1]), pot_yaw=yaw)

    def set_state(self, state: KitchenState, settle_steps: int = SETTLE_STEPS) -> None:
        """Put the scene in ``state`` directly (qpos), then settle physics holding the hand still."""
        m, d, h, sc, ctl = self.model, self.data, self.h, self._scene, self._control
        sc.reset_kitchen(m, d, h)
        d.qpos[h.door_qpos] = state.door
        d.qpos[h.tray_qpos] = state.tray
        mujoco = self._mujoco()
        mujoco.mj_kinematics(m, d)
        if state.pot_on == "table":
            home = sc.POT_HOME
            pos = np.array(
                [home[0] + state.pot_xy[0], home[1] + state.pot_xy[1], sc.TABLE_TOP + TABLE_CLEARANCE]
            )
        else:  # tray frame (the tray body is axis-aligned with the world)
            pos = d.xpos[self._tray_body] + np.array([state.pot_xy[0], state.pot_xy[1], TRAY_FLOOR])
        a = h.pot_qpos
        d.qpos[a : a + 3] = pos
        d.qpos[a + 3 : a + 7] = [np.cos(state.pot_yaw / 2), 0.0, 0.0, np.sin(state.pot_yaw / 2)]
        self.controller.reset(d)
        if state.hand is not None:
            cmd = ctl.validate_command(state.hand)
            pos_c = np.clip(cmd[:3], ctl.WORKSPACE_LOW, ctl.WORKSPACE_HIGH)
            q = self.controller.solve_ik(pos_c, ctl.rot6d_to_matrix(cmd[3:9]), iters=200)
            d.qpos[self.controller.qadr] = q
            d.ctrl[self.controller.act] = q
            grip = float(np.clip(cmd[9], 0.0, 1.0)) * sc.GRIPPER_CLOSED
            d.qpos[h.left_gripper_qpos] = grip
            d.ctrl[h.actuator["gripper_left_joint"]] = grip
        mujoco.mj_forward(m, d)
        self.controller.reset(d)
        hold = ctl.hand_pose10(d, h)
        if state.hand is not None:
            hold[9] = float(np.clip(state.hand[9], 0.0, 1.0))
        for _ in range(settle_steps):
            self.controller.step(d, hold)
        mujoco.mj_forward(m, d)  # observations consistent with qpos
        self._cmd = self._tracked(hold)
        self._scene_version += 1

    def _mujoco(self):
        return self._mj

    def _snapshot(self) -> tuple:
        d = self.data
        return (
            d.time,
            d.qpos.copy(),
            d.qvel.copy(),
            d.act.copy(),
            d.ctrl.copy(),
            d.eq_active.copy(),
            self._cmd.copy(),
            self.controller.q_target.copy(),
        )

    def restore(self, snap: tuple) -> None:
        """Restore a snapshot taken by the env (e.g. :meth:`set_goal_scene`)."""
        d = self.data
        d.time = snap[0]
        d.qpos[:], d.qvel[:], d.act[:], d.ctrl[:], d.eq_active[:] = snap[1:6]
        self._cmd = snap[6].copy()
        self._mujoco().mj_forward(self.model, d)
        self.controller.reset(d)
        self.controller.q_target = snap[7].copy()
        self._scene_version += 1

    def set_goal_scene(self) -> None:
        """Put the scene exactly in this episode's (settled) goal state; for tests and demos."""
        if self._goal_snapshot is None:
            raise RuntimeError("call reset() first")
        self.restore(self._goal_snapshot)

    # ------------------------------------------------------------------------------ observations
    def _tracked(self, cmd: np.ndarray) -> np.ndarray:
        ctl = self._control
        out = np.asarray(cmd, dtype=float).copy()
        out[:3] = np.clip(out[:3], ctl.WORKSPACE_LOW, ctl.WORKSPACE_HIGH)
        out[3:9] = ctl.matrix_to_rot6d(ctl.rot6d_to_matrix(out[3:9]))
        out[9] = np.clip(out[9], 0.0, 1.0)
        return out

    def _state_vec(self) -> np.ndarray:
        return np.concatenate([self._cmd, self._control.hand_pose10(self.data, self.h)]).astype(np.float32)

    def _env_vec(self) -> np.ndarray:
        sc = self._scene
        pos, quat = sc.pot_pose(self.data, self.h)
        return np.concatenate(
            [[sc.door_angle(self.data, self.h), sc.tray_slide(self.data, self.h)], pos, quat]
        ).astype(np.float32)

    def _obs(self) -> dict:
        obs = {
            "agent_pos": self._state_vec(),
            "environment_state": self._env_vec(),
            GOAL_STATE_KEY: self._goal_state.copy(),
            GOAL_ENV_STATE_KEY: self._goal_env.copy(),
        }
        if self.obs_type == "pixels_state":  # rendering is ~90 % of a step's cost: only when observed
            frame = self._renderer.render(self.data)
            self._obs_frame = (self._scene_version, frame)
            obs["pixels"] = {CAMERA: frame.copy()}
            obs[GOAL_IMAGE_KEY] = self._goal_img.copy()
        return obs

    def success_errors(self) -> dict:
        env = self._env_vec().astype(float)
        goal = self._goal_env.astype(float)
        return {
            "door_error": abs(env[0] - goal[0]),
            "tray_error": abs(env[1] - goal[1]),
            "pot_error": float(np.linalg.norm(env[2:5] - goal[2:5])),
        }

    def _info(self) -> dict:
        err = self.success_errors()
        ok = err["door_error"] < DOOR_TOL and err["tray_error"] < TRAY_TOL and err["pot_error"] < POT_TOL
        return {
            "is_success": bool(ok),
            "task": self.task,
            **err,
            **self._grasps.info(self.data, self.h, self._cmd[9]),
        }

    # ------------------------------------------------------------------------------ gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        if options.get("task") is not None:
            name = check_task(options["task"])
            if name == ALL:
                raise ValueError(f"options['task'] must be a single task: {list(TASK_NAMES)}")
        elif self.suite == ALL:
            name = TASK_NAMES[self._reset_count % len(TASK_NAMES)]
        else:
            name = self.suite
        self._reset_count += 1
        self._steps = 0
        self._set_current(name)
        task = TASKS[name]
        initial, goal = self._jitter(task.initial), self._jitter(task.goal)
        self.set_state(goal)
        if self.obs_type == "pixels_state":
            self._goal_img = self._renderer.render(self.data)
        self._goal_state = self._state_vec()
        self._goal_env = self._env_vec()
        self._goal_snapshot = self._snapshot()
        self.set_state(initial)
        self._initial_snapshot = self._snapshot()
        return self._obs(), self._info()

    def step(self, action):
        if self._goal_snapshot is None:
            raise RuntimeError("call reset() before step()")
        self.advance(action)
        info = self._info()
        success = info["is_success"]
        return self._obs(), float(success), bool(success and self.terminate_on_success), False, info

    def observe(self) -> dict:
        """The current observation (same format as :meth:`reset` / :meth:`step`), e.g. after :meth:`set_state`."""
        return self._obs()

    def advance(self, action) -> None:
        """Apply one action with exactly :meth:`step`'s physics but no rendering / observation / success.

        For fast scripted rollouts and statistics (rendering dominates :meth:`step`'s cost).
        """
        cmd = self._control.validate_command(action)  # ValueError naming NaN/inf entries
        self.controller.step(self.data, cmd)
        self._mujoco().mj_forward(self.model, self.data)  # mj_step leaves kinematics one substep stale
        self._cmd = self._tracked(cmd)
        self._steps += 1
        self._scene_version += 1

    def render(self) -> np.ndarray:
        """The video frame (``render_size``): a new one every ``video_frame_stride``-th step since the reset,
        the observation's frame when it shows the current scene at this size (see the module docstring)."""
        key = (self._reset_count, self._steps // self.video_frame_stride)
        if self.video_frame_stride > 1 and self._video_frame is not None and self._video_frame[0] == key:
            return self._video_frame[1].copy()
        obs = self._obs_frame
        if self._render_renderer is self._renderer and obs is not None and obs[0] == self._scene_version:
            frame = obs[1]  # never handed out: the observation and render() get copies
        else:
            frame = self._render_renderer.render(self.data)
        self._video_frame = (key, frame)
        return frame.copy()

    def close(self) -> None:
        for r in {
            id(x): x
            for x in (getattr(self, "_renderer", None), getattr(self, "_render_renderer", None))
            if x is not None
        }.values():
            r.close()
        super().close()


# ---------------------------------------------------------------------------------- LeRobot config


@EnvConfig.register_subclass("talos_kitchen")
@dataclass
class TalosKitchenEnvConfig(GoalEnvConfig):
    """LeRobot config: ``--env.type=talos_kitchen --env.task=open_door`` (``all`` = whole suite).

    ``episode_length`` None: :data:`STEPS_PER_OBJECT` per object the task moves (500 steps for open_door, 1500
    for store_pot; ``all``: the longest task's), so that a long task is not cut off at a short task's limit.
    """

    GYM_ID: ClassVar[str] = GYM_ID
    MODULE: ClassVar[str] = "lerobot_efm.envs.talos_kitchen.env"

    task: str | None = "open_door"
    fps: int = CONTROL_FPS
    episode_length: int | None = None
    image_size: int = 128
    randomize: bool = True
    render_mode: str = "rgb_array"
    obs_type: str = "pixels_state"  # "state": no camera, no goal image (faster evaluation of state policies)
    # video frames: a new one every k-th step, repeated in between (lerobot-eval renders its first 10 episodes)
    video_frame_stride: int = 1
    features: dict[str, PolicyFeature] = field(
        default_factory=lambda: {
            ACTION: PolicyFeature(type=FeatureType.ACTION, shape=(ACTION_DIM,)),
            "agent_pos": PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,)),
            "environment_state": PolicyFeature(type=FeatureType.ENV, shape=(ENV_STATE_DIM,)),
            GOAL_STATE_KEY: PolicyFeature(type=FeatureType.STATE, shape=(STATE_DIM,)),
            GOAL_ENV_STATE_KEY: PolicyFeature(type=FeatureType.ENV, shape=(ENV_STATE_DIM,)),
        }
    )
    features_map: dict[str, str] = field(
        default_factory=lambda: {
            ACTION: ACTION,
            "agent_pos": OBS_STATE,
            "environment_state": OBS_ENV_STATE,
            GOAL_STATE_KEY: OBS_GOAL_STATE,
            GOAL_ENV_STATE_KEY: OBS_GOAL_ENV_STATE,
            f"{OBS_IMAGES}.{CAMERA}": f"{OBS_IMAGES}.{CAMERA}",  # identity: eval recording needs this form
            GOAL_IMAGE_KEY: OBS_GOAL_IMAGE,
        }
    )

    def __post_init__(self):
        check_task(self.task)
        if self.episode_length is None:
            self.episode_length = episode_steps(self.task)
        if self.episode_length < 1:
            raise ValueError(f"--env.episode_length must be >= 1, got {self.episode_length}")
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown --env.obs_type={self.obs_type!r}; valid: {list(OBS_TYPES)}")
        if self.video_frame_stride < 1:
            raise ValueError(f"--env.video_frame_stride must be >= 1, got {self.video_frame_stride}")
        if self.obs_type == "pixels_state":
            img = PolicyFeature(type=FeatureType.VISUAL, shape=(self.image_size, self.image_size, 3))
            self.features[f"{OBS_IMAGES}.{CAMERA}"] = img
            self.features[GOAL_IMAGE_KEY] = img

    @property
    def gym_kwargs(self) -> dict:
        return {
            "task": self.task,
            "image_size": self.image_size,
            "randomize": self.randomize,
            "render_mode": self.render_mode,
            "obs_type": self.obs_type,
            "video_frame_stride": self.video_frame_stride,
            "max_episode_steps": self.episode_length,
        }


def episode_steps(task: str) -> int:
    """The default episode limit of ``task`` (``all``: the longest of the suite)."""
    names = TASK_NAMES if check_task(task) == ALL else (task,)
    return STEPS_PER_OBJECT * max(TASKS[n].num_objects for n in names)


if GYM_ID not in gym.registry:
    gym.register(
        id=GYM_ID,
        entry_point="lerobot_efm.envs.talos_kitchen.env:TalosKitchenEnv",
        max_episode_steps=DEFAULT_EPISODE_STEPS,
    )
