"""PlanarPush: push a disc through a maze with a small force-controlled effector (MuJoCo), after the paper's
pymunk ``PlanarPushEnv(variant_name="circle_maze_medium")``.

Physics (constants of the reference, ``reference-implementation.md`` §6; our MuJoCo mapping):

* zero gravity; both bodies move on slide joints x/y in the plane (no rotation: the reference ignores the
  disc angle in observations and success). They are spheres centred at z = 0, so contacts with each other and
  with the vertical wall boxes are exactly those of discs in the plane.
* disc r = 0.2, density 0.8 -> mass 0.8*pi*r^2; effector r = 0.075, density 1 -> mass pi*r^2.
* top-down friction of the disc (pymunk PivotJoint max_force 2.0 to the ground): an isotropic Coulomb force,
  applied each substep, that would stop the disc within the substep against the last constraint (contact)
  forces, clipped to norm 2 (:meth:`PlanarPushEnv._ground_friction`). MuJoCo's ``frictionloss`` acts on each
  slide joint separately: with it the disc slid along the axes (pushed at 30 deg it moved at 10 deg, at 60 deg at
  80 deg), as no disc on a table does. The GearJoint (rotation friction) has no counterpart.
* contact friction (effector-disc, disc-walls) 0.05: with 0.3 a hand lining up behind a sliding disc dragged it
  sideways, off the wall it was slid along.
* effector force F = clip_norm(50*(cmd - pos), 5) - 1.5*vel: the spring part is applied each substep as
  ``qfrc_applied``, the damping is the joints' ``damping = 1.5`` (integrated implicitly).
* one env step = 3 substeps of 1/200 s (as the reference; the env runs at 20 Hz of *control*).

Observation (gym Dict -> LeRobot key): ``agent_pos`` (4,) = [eff_x, eff_y, obj_x, obj_y] -> ``observation.state``;
``goal.state`` (4,) -> ``observation.goal.state``; with ``obs_type="pixels_state"`` also ``pixels`` = {"top"}
-> ``observation.images.top`` and ``goal.images.top`` -> ``observation.goal.images.top`` (top-down orthographic
view rendered by MuJoCo; goal markers are never drawn in observations, so a goal image is an observation).
Action: absolute commanded effector position in [-1, 1]^2 (clipped), NaN/inf raise ``ValueError``.

Tasks: ``pair0`` .. ``pair9`` = the fixed evaluation (initial, goal) pairs :data:`EVAL_PAIRS`; ``all`` cycles
through them across resets. Success (``info["is_success"]``, terminates) at any step when the disc
AND the effector are each within :data:`SUCCESS_TOL` = 0.04 of their goal positions (paper: 600 steps,
replanning every 6, success at any step).

Reward (``reward=``; never used for training, which relabels goals in hindsight): ``"success"`` (default) is
1 at success, else 0. ``"progress"`` is the share of the episode's initial goal distance D0 closed by the step,
(D_prev - D) / D0 with D = |disc - disc goal| + |effector - effector goal| (straight-line, not through the
maze), so lerobot-eval's ``sum_reward`` is 1 - D_end / D0: a graded score for small training budgets where
every success rate is 0.
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from lerobot.configs import PolicyFeature
from lerobot.envs.configs import EnvConfig

from ...extras import require
from ..goal_env import (
    GoalEnvConfig,
    add_camera_features,
    goal_image_key,
    state_goal_features,
    state_goal_features_map,
)
from .maze import ARENA, CORNER, EFFECTOR_RADIUS, OBJECT_RADIUS, wall_boxes, wall_distance

GYM_ID = "lerobot_efm/PlanarPush-v0"
ENV_TYPE = "planar_push"
FPS = 20
DEFAULT_EPISODE_STEPS = 600
SUBSTEPS = 3
TIMESTEP = 1.0 / 200.0
OBJECT_DENSITY, EFFECTOR_DENSITY = 0.8, 1.0
OBJECT_GROUND_FRICTION = 2.0  # max friction force (reference PivotJoint max_force)
KP, MAX_FORCE, KD = 50.0, 5.0, 1.5
SUCCESS_TOL = 0.04
STATE_NAMES = ("eff_x", "eff_y", "obj_x", "obj_y")
OBS_TYPES = ("state", "pixels_state")
REWARDS = ("success", "progress")
CAMERA = "top"
GOAL_STATE_KEY = "goal.state"
GOAL_IMAGE_KEY = f"goal.images.{CAMERA}"
OBS_GOAL_IMAGE = goal_image_key(CAMERA)
GOAL_MARKER_GROUP = 3  # geom group of the goal markers, hidden in observation images
ALL = "all"


def _pair(name, eff0, obj0, eff1, obj1):
    return name, np.array([*eff0, *obj0], dtype=np.float64), np.array([*eff1, *obj1], dtype=np.float64)


# (description, initial [eff, obj], goal [eff, obj]); corner discs rest against both walls (maze.CORNER).
# The goal effector sits behind the disc w.r.t. the last push, as in the last frame of a demonstration.
# Starts are near corners, never in them: a disc wedged in a corner leaves no room behind it to push it out.
C, N = CORNER, 0.5
B = C - OBJECT_RADIUS - EFFECTOR_RADIUS - 0.01  # the hand where a slide into a corner leaves it
EVAL_PAIRS = (
    _pair("bottom-right corner to top-right corner", (0.15, -N), (N, -N), (B, C), (C, C)),
    _pair("top-right corner to bottom-right corner", (0.15, N), (N, N), (B, -C), (C, -C)),
    _pair("bottom band to top-left corner", (0.8, -0.55), (0.5, -0.55), (-C, B), (-C, C)),
    _pair("top band to bottom-left corner", (0.8, 0.55), (0.5, 0.55), (-C, -B), (-C, -C)),
    _pair("bottom-left corner to top-right corner", (-0.15, -N), (-N, -N), (B, C), (C, C)),
    _pair("left passage to bottom-right corner", (-0.6, 0.35), (-0.6, 0.0), (B, -C), (C, -C)),
    _pair("top band to bottom band", (0.0, 0.75), (0.3, 0.5), (0.0, -0.55), (0.3, -0.55)),
    _pair("top-left corner to bottom-right corner", (-0.15, N), (-N, N), (B, -C), (C, -C)),
    _pair("bottom band centre to bottom-right corner", (-0.5, -0.55), (-0.2, -0.55), (B, -C), (C, -C)),
    _pair("top-right corner to the left passage", (N, 0.2), (N, N), (-0.6, 0.3), (-0.6, 0.0)),
)
TASK_NAMES = tuple(f"pair{k}" for k in range(len(EVAL_PAIRS)))


def check_task(task: str | None) -> str:
    if task not in TASK_NAMES and task != ALL:
        raise ValueError(f"Unknown planar_push task {task!r}; valid tasks: {[*TASK_NAMES, ALL]}")
    return task


def describe(task: str) -> str:
    return f"push the disc: {EVAL_PAIRS[TASK_NAMES.index(task)][0]}"


def check_state(state, name: str = "state") -> np.ndarray:
    """Validate a 4-D [eff_x, eff_y, obj_x, obj_y]: finite, both discs inside free space, not overlapping."""
    s = np.asarray(state, dtype=np.float64).reshape(-1)
    if s.shape != (4,) or not np.all(np.isfinite(s)):
        raise ValueError(
            f"planar_push {name} must be 4 finite numbers [eff_x, eff_y, obj_x, obj_y], got {state!r}"
        )
    if wall_distance(s[:2]) < EFFECTOR_RADIUS - 1e-3:
        raise ValueError(f"planar_push {name}: effector {s[:2].tolist()} overlaps a wall")
    if wall_distance(s[2:]) < OBJECT_RADIUS - 1e-3:
        raise ValueError(f"planar_push {name}: disc {s[2:].tolist()} overlaps a wall")
    if np.linalg.norm(s[:2] - s[2:]) < OBJECT_RADIUS + EFFECTOR_RADIUS - 1e-3:
        raise ValueError(f"planar_push {name}: effector {s[:2].tolist()} overlaps the disc {s[2:].tolist()}")
    return s


def build_mjcf(offscreen: int = 256) -> str:
    """MJCF of the scene (see the module docstring for the mapping of the reference's constants)."""
    m_obj = OBJECT_DENSITY * np.pi * OBJECT_RADIUS**2
    m_eff = EFFECTOR_DENSITY * np.pi * EFFECTOR_RADIUS**2
    walls = [
        (0.0, ARENA + 0.1, ARENA + 0.2, 0.1),
        (0.0, -ARENA - 0.1, ARENA + 0.2, 0.1),
        (ARENA + 0.1, 0.0, 0.1, ARENA + 0.2),
        (-ARENA - 0.1, 0.0, 0.1, ARENA + 0.2),
        *map(tuple, wall_boxes()),
    ]
    wall_xml = "\n".join(
        f'    <geom name="wall{k}" type="box" pos="{cx:.6f} {cy:.6f} 0" size="{hx:.6f} {hy:.6f} 0.25" '
        f'rgba="0.45 0.45 0.45 1"/>'
        for k, (cx, cy, hx, hy) in enumerate(walls)
    )
    marker = f'contype="0" conaffinity="0" group="{GOAL_MARKER_GROUP}"'
    return f"""<mujoco model="planar_push">
  <option timestep="{TIMESTEP}" gravity="0 0 0" integrator="implicitfast"/>
  <visual><global offwidth="{offscreen}" offheight="{offscreen}"/><quality shadowsize="0"/>
    <headlight ambient="0.9 0.9 0.9" diffuse="0.1 0.1 0.1" specular="0 0 0"/></visual>
  <default><geom friction="0.05 0.005 0.0001" solref="0.01 1"/></default>
  <worldbody>
    <camera name="{CAMERA}" pos="0 0 2" xyaxes="1 0 0 0 1 0" projection="orthographic" fovy="{2 * ARENA}"/>
    <geom name="floor" type="box" pos="0 0 -0.3" size="{ARENA} {ARENA} 0.01" rgba="0.93 0.93 0.9 1"
          contype="0" conaffinity="0"/>
{wall_xml}
    <body name="object" pos="0 0 0">
      <joint name="obj_x" type="slide" axis="1 0 0"/>
      <joint name="obj_y" type="slide" axis="0 1 0"/>
      <geom name="object" type="sphere" size="{OBJECT_RADIUS}" mass="{m_obj:.6f}" rgba="0.85 0.2 0.2 1"/>
    </body>
    <body name="effector" pos="0 0 0">
      <joint name="eff_x" type="slide" axis="1 0 0" damping="{KD}"/>
      <joint name="eff_y" type="slide" axis="0 1 0" damping="{KD}"/>
      <geom name="effector" type="sphere" size="{EFFECTOR_RADIUS}" mass="{m_eff:.6f}" rgba="0.2 0.35 0.9 1"/>
    </body>
    <body name="goal_object" mocap="true" pos="0 0 -0.25">
      <geom type="cylinder" size="{OBJECT_RADIUS} 0.01" rgba="0.85 0.2 0.2 0.3" {marker}/>
    </body>
    <body name="goal_effector" mocap="true" pos="0 0 -0.25">
      <geom type="cylinder" size="{EFFECTOR_RADIUS} 0.01" rgba="0.2 0.35 0.9 0.3" {marker}/>
    </body>
  </worldbody>
</mujoco>"""


class PlanarPushEnv(gym.Env):
    """Goal-conditioned planar pushing in a maze; see the module docstring.

    ``reset(options={"pair": k})`` picks evaluation pair k for one episode; ``options={"initial": s4,
    "goal": s4}`` sets any initial/goal state (either may be given). :meth:`set_state` / :meth:`observe`
    let scripted demonstrators place the scene and read observations without stepping.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": FPS}

    def __init__(
        self,
        task: str = "pair0",
        obs_type: str = "state",
        image_size: int = 96,
        render_mode: str = "rgb_array",
        render_size: int = 256,
        terminate_on_success: bool = True,
        reward: str = "success",
    ):
        self.suite = check_task(task)
        if reward not in REWARDS:
            raise ValueError(f"Unknown reward {reward!r}; valid: {list(REWARDS)}")
        self.reward_type = reward
        if obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown obs_type {obs_type!r}; valid: {list(OBS_TYPES)}")
        if render_mode != "rgb_array":
            raise ValueError(f"render_mode must be 'rgb_array', got {render_mode!r}")
        os.environ.setdefault("MUJOCO_GL", "egl")
        mujoco = require("mujoco", "planar", "the planar_push environment")

        self._mj = mujoco
        self.obs_type, self.image_size = obs_type, int(image_size)
        self.render_mode, self.render_size = render_mode, int(render_size)
        self.terminate_on_success = bool(terminate_on_success)
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(max(self.image_size, self.render_size, 64)))
        self.data = mujoco.MjData(self.model)
        jnt = {n: self.model.joint(n) for n in ("eff_x", "eff_y", "obj_x", "obj_y")}
        self._qpos = np.array([jnt[n].qposadr[0] for n in STATE_NAMES])  # [eff_x, eff_y, obj_x, obj_y]
        self._eff_dof = np.array([jnt["eff_x"].dofadr[0], jnt["eff_y"].dofadr[0]])
        self._obj_dof = np.array([jnt["obj_x"].dofadr[0], jnt["obj_y"].dofadr[0]])
        self._obj_mass = float(self.model.body("object").mass[0])
        self._mocap = (self.model.body("goal_effector").mocapid[0], self.model.body("goal_object").mocapid[0])
        self._renderers: dict[int, object] = {}

        box = spaces.Box(-ARENA, ARENA, shape=(4,), dtype=np.float32)
        obs = {"agent_pos": box, GOAL_STATE_KEY: box}
        if obs_type == "pixels_state":
            img = spaces.Box(0, 255, shape=(self.image_size, self.image_size, 3), dtype=np.uint8)
            obs["pixels"] = spaces.Dict({CAMERA: img})
            obs[GOAL_IMAGE_KEY] = img
        self.observation_space = spaces.Dict(obs)
        self.action_space = spaces.Box(-ARENA, ARENA, shape=(2,), dtype=np.float32)
        self._reset_count = 0
        self._initial_distance = self._last_distance = 1.0
        self._set_task(TASK_NAMES[0] if self.suite == ALL else self.suite)
        self.goal = EVAL_PAIRS[0][2].copy()
        self._goal_img: np.ndarray | None = None
        self.set_state(EVAL_PAIRS[0][1])

    # ----------------------------------------------------------------------------- state access
    def _set_task(self, name: str) -> None:
        self.task, self.task_description = name, describe(name)

    @property
    def state(self) -> np.ndarray:
        """Current [eff_x, eff_y, obj_x, obj_y] (float64 copy)."""
        return self.data.qpos[self._qpos].copy()

    def set_state(self, state) -> None:
        """Place effector and disc at rest (checked free and non-overlapping); the command holds the effector."""
        s = check_state(state)
        self.data.qpos[:] = 0.0
        self.data.qvel[:] = 0.0
        self.data.qpos[self._qpos] = s
        self.data.qfrc_applied[:] = 0.0
        self._mj.mj_forward(self.model, self.data)
        self.command = s[:2].copy()

    def _renderer(self, size: int):
        if size not in self._renderers:
            self._renderers[size] = self._mj.Renderer(self.model, height=size, width=size)
        return self._renderers[size]

    def _render(self, size: int, show_goal: bool) -> np.ndarray:
        opt = self._mj.MjvOption()
        opt.geomgroup[GOAL_MARKER_GROUP] = int(show_goal)
        if show_goal:
            for mid, xy in zip(self._mocap, (self.goal[:2], self.goal[2:]), strict=True):
                self.data.mocap_pos[mid] = [xy[0], xy[1], -0.25]
            self._mj.mj_kinematics(self.model, self.data)
        r = self._renderer(size)
        r.update_scene(self.data, camera=CAMERA, scene_option=opt)
        return r.render().copy()

    def render_state(self, state, size: int | None = None) -> np.ndarray:
        """Observation image of an arbitrary state (restores the current one); used for goal images."""
        saved = (self.data.qpos.copy(), self.data.qvel.copy(), self.command.copy())
        self.data.qpos[self._qpos] = check_state(state)
        self._mj.mj_forward(self.model, self.data)
        img = self._render(size or self.image_size, show_goal=False)
        self.data.qpos[:], self.data.qvel[:] = saved[0], saved[1]
        self.command = saved[2]
        self._mj.mj_forward(self.model, self.data)
        return img

    def observe(self) -> dict:
        """Raw observation of the current state (same format as ``reset``/``step``)."""
        obs = {"agent_pos": self.state.astype(np.float32), GOAL_STATE_KEY: self.goal.astype(np.float32)}
        if self.obs_type == "pixels_state":
            obs["pixels"] = {CAMERA: self._render(self.image_size, show_goal=False)}
            obs[GOAL_IMAGE_KEY] = self._goal_img.copy()
        return obs

    def errors(self) -> tuple[float, float]:
        """(effector distance, disc distance) to their goals."""
        s = self.state
        return float(np.linalg.norm(s[:2] - self.goal[:2])), float(np.linalg.norm(s[2:] - self.goal[2:]))

    def _info(self) -> dict:
        eff_err, obj_err = self.errors()
        ok = eff_err < SUCCESS_TOL and obj_err < SUCCESS_TOL
        return {
            "is_success": bool(ok),
            "effector_distance": eff_err,
            "object_distance": obj_err,
            "task": self.task,
        }

    # ----------------------------------------------------------------------------- gym API
    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        options = options or {}
        if options.get("pair") is not None:
            k = int(options["pair"])
            if not 0 <= k < len(EVAL_PAIRS):
                raise ValueError(
                    f"options['pair'] must be in 0..{len(EVAL_PAIRS) - 1}, got {options['pair']!r}"
                )
            name = TASK_NAMES[k]
        elif (
            self.suite == ALL
        ):  # a seeded reset picks pair seed % 10: lerobot-eval's batched envs then cover all pairs
            k = seed if seed is not None else self._reset_count
            name = TASK_NAMES[k % len(TASK_NAMES)]
        else:
            name = self.suite
        self._reset_count += 1
        self._set_task(name)
        _, initial, goal = EVAL_PAIRS[TASK_NAMES.index(name)]
        if options.get("initial") is not None:
            initial = options["initial"]
        if options.get("goal") is not None:
            goal = options["goal"]
        self.goal = check_state(goal, "goal").copy()
        self.set_state(check_state(initial, "initial"))
        self._initial_distance = self._last_distance = self._goal_distance()
        if self.obs_type == "pixels_state":
            self._goal_img = self.render_state(self.goal)
        return self.observe(), self._info()

    def step(self, action):
        a = np.asarray(action, dtype=np.float64).reshape(-1)
        if a.shape != (2,) or not np.all(np.isfinite(a)):
            raise ValueError(
                f"planar_push action must be 2 finite numbers (x, y), got {np.asarray(action)!r}"
            )
        self.command = np.clip(a, -ARENA, ARENA)
        d, mj = self.data, self._mj
        for _ in range(SUBSTEPS):
            force = KP * (self.command - d.qpos[self._qpos[:2]])
            norm = float(np.linalg.norm(force))
            if norm > MAX_FORCE:
                force *= MAX_FORCE / norm
            d.qfrc_applied[self._eff_dof] = force
            d.qfrc_applied[self._obj_dof] = self._ground_friction()
            mj.mj_step(self.model, d)
        info = self._info()
        success = info["is_success"]
        return self.observe(), self._reward(info), bool(success and self.terminate_on_success), False, info

    def _ground_friction(self) -> np.ndarray:
        """Isotropic Coulomb friction of the disc on the ground: the force that stops it within one substep against
        the constraint forces of the last substep (contacts with the effector and the walls), at most
        OBJECT_GROUND_FRICTION in norm (static below it, kinetic at it)."""
        d = self.data
        stop = -(self._obj_mass * d.qvel[self._obj_dof] / TIMESTEP + d.qfrc_constraint[self._obj_dof])
        norm = float(np.linalg.norm(stop))
        return stop if norm <= OBJECT_GROUND_FRICTION else stop * (OBJECT_GROUND_FRICTION / norm)

    def _goal_distance(self) -> float:
        return float(sum(self.errors()))

    def _reward(self, info: dict) -> float:
        if self.reward_type == "success":
            return float(info["is_success"])
        before, self._last_distance = self._last_distance, self._goal_distance()
        return (before - self._last_distance) / max(self._initial_distance, 1e-6)

    def render(self) -> np.ndarray:
        return self._render(self.render_size, show_goal=True)

    def close(self) -> None:
        for r in self._renderers.values():
            r.close()
        self._renderers.clear()
        super().close()


@EnvConfig.register_subclass(ENV_TYPE)
@dataclass
class PlanarPushEnvConfig(GoalEnvConfig):
    """LeRobot config: ``--env.type=planar_push --env.task=pair3`` (``all`` cycles the 10 pairs)."""

    GYM_ID: ClassVar[str] = GYM_ID
    MODULE: ClassVar[str] = "lerobot_efm.envs.planar_push.env"

    task: str | None = ALL
    fps: int = FPS
    episode_length: int = DEFAULT_EPISODE_STEPS
    obs_type: str = "state"
    image_size: int = 96
    render_mode: str = "rgb_array"
    reward: str = (
        "success"  # or "progress": share of the initial goal distance closed (see the module docstring)
    )
    features: dict[str, PolicyFeature] = field(default_factory=lambda: state_goal_features(4, 2))
    features_map: dict[str, str] = field(default_factory=lambda: state_goal_features_map(CAMERA))

    def __post_init__(self):
        check_task(self.task)
        if self.obs_type not in OBS_TYPES:
            raise ValueError(f"Unknown obs_type {self.obs_type!r}; valid: {list(OBS_TYPES)}")
        if self.reward not in REWARDS:
            raise ValueError(f"Unknown --env.reward={self.reward!r}; valid: {list(REWARDS)}")
        if self.obs_type == "pixels_state":
            add_camera_features(self.features, CAMERA, self.image_size)

    @property
    def gym_kwargs(self) -> dict:
        return {
            "task": self.task,
            "obs_type": self.obs_type,
            "image_size": self.image_size,
            "render_mode": self.render_mode,
            "reward": self.reward,
            "max_episode_steps": self.episode_length,
        }


if GYM_ID not in gym.registry:
    gym.register(
        id=GYM_ID,
        entry_point="lerobot_efm.envs.planar_push.env:PlanarPushEnv",
        max_episode_steps=DEFAULT_EPISODE_STEPS,
    )
