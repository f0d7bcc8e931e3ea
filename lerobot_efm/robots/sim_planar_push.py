"""The planar push MuJoCo env as a LeRobot ``Robot``, and the scripted play operators as a ``Teleoperator``.

So that LeRobot's own deployment and recording CLIs run without hardware: ``lerobot-record`` records play on the
simulated robot with the scripted teleoperator, ``lerobot-rollout`` drives it with a trained ``efm_*`` policy
(a dry run of a real deployment). Feature names end in ``.pos`` as LeRobot's motor features do, because
``lerobot-rollout`` keeps only such scalar features for ``observation.state`` and ``action``:

* observation: ``eff_x.pos, eff_y.pos, obj_x.pos, obj_y.pos`` (-> ``observation.state``, the order of the
  plugin's planar recordings) and, with ``image_size > 0``, the top camera ``top`` (HWC uint8);
* action: ``x.pos, y.pos``, the absolute effector command in [-1, 1]^2.

    lerobot-record --robot.type=efm_sim_planar_push --robot.id=sim --teleop.type=efm_scripted_planar_push \\
        --teleop.robot_id=sim --dataset.repo_id=local/sim_play --dataset.root=data/sim_play \\
        --dataset.single_task=play --dataset.fps=20 --dataset.num_episodes=10 --dataset.episode_time_s=40

The teleoperator drives the simulated robot of the same process (found by ``robot_id``): a scripted operator
needs the state it acts on, which a real teleoperator reads from its human.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np
from lerobot.robots import Robot, RobotConfig
from lerobot.teleoperators import Teleoperator, TeleoperatorConfig

STATE_NAMES = ("eff_x.pos", "eff_y.pos", "obj_x.pos", "obj_y.pos")
ACTION_NAMES = ("x.pos", "y.pos")
CAMERA = "top"
PLAY_BEHAVIOURS = (
    "full",
    "partitioned",
    "hand",
)  # scripted operators of lerobot_efm.envs.planar_push.demonstrators

# connected simulated robots by id, so that a scripted teleoperator of the same process can drive one
_SIM_ROBOTS: dict[str | None, SimPlanarPush] = {}


@RobotConfig.register_subclass("efm_sim_planar_push")
@dataclass(kw_only=True)
class SimPlanarPushConfig(RobotConfig):
    image_size: int = 0  # > 0: add the top camera ("top", image_size x image_size RGB)
    start_pair: int = 0  # connect places disc and hand at this evaluation pair's start (0..9)
    seed: int = 0


class SimPlanarPush(Robot):
    config_class = SimPlanarPushConfig
    name = "efm_sim_planar_push"

    def __init__(self, config: SimPlanarPushConfig):
        super().__init__(config)
        self.config = config
        self.env = None
        self.cameras: dict = {}  # no LeRobot camera objects: the image is rendered by MuJoCo

    @cached_property
    def observation_features(self) -> dict:
        features: dict = dict.fromkeys(STATE_NAMES, float)
        if self.config.image_size > 0:
            features[CAMERA] = (self.config.image_size, self.config.image_size, 3)
        return features

    @cached_property
    def action_features(self) -> dict:
        return dict.fromkeys(ACTION_NAMES, float)

    @property
    def is_connected(self) -> bool:
        return self.env is not None

    @property
    def is_calibrated(self) -> bool:
        return True

    def connect(self, calibrate: bool = True) -> None:
        from lerobot_efm.envs.planar_push.env import PlanarPushEnv

        if self.env is not None:
            raise RuntimeError(f"{self} is already connected")
        obs_type = "pixels_state" if self.config.image_size > 0 else "state"
        self.env = PlanarPushEnv(
            task="all",
            obs_type=obs_type,
            image_size=max(self.config.image_size, 8),
            terminate_on_success=False,
        )
        self.env.reset(seed=self.config.seed, options={"pair": self.config.start_pair})
        _SIM_ROBOTS[self.id] = self

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    def get_observation(self) -> dict:
        obs = self.env.observe()
        out = {name: float(x) for name, x in zip(STATE_NAMES, obs["agent_pos"], strict=True)}
        if self.config.image_size > 0:
            out[CAMERA] = obs["pixels"][CAMERA]
        return out

    def send_action(self, action: dict) -> dict:
        if not all(name in action for name in ACTION_NAMES):  # e.g. rollout's return to the connect pose
            return {}
        self.env.step(np.array([float(action[name]) for name in ACTION_NAMES], dtype=np.float32))
        return {name: float(action[name]) for name in ACTION_NAMES}

    def disconnect(self) -> None:
        if self.env is not None:
            self.env.close()
            self.env = None
        _SIM_ROBOTS.pop(self.id, None)


@TeleoperatorConfig.register_subclass("efm_scripted_planar_push")
@dataclass(kw_only=True)
class ScriptedPlanarPushConfig(TeleoperatorConfig):
    # "full" or "partitioned" play, or "hand": the hand alone around the disc (a reach task for dry runs);
    # lerobot_efm.envs.planar_push.demonstrators
    behaviour: str = "full"
    robot_id: str | None = None  # --robot.id of the simulated robot it drives
    noise: float = 0.01  # command noise of the play operator
    seed: int = 0


class ScriptedPlanarPush(Teleoperator):
    config_class = ScriptedPlanarPushConfig
    name = "efm_scripted_planar_push"

    def __init__(self, config: ScriptedPlanarPushConfig):
        super().__init__(config)
        if config.behaviour not in PLAY_BEHAVIOURS:
            raise ValueError(f"--teleop.behaviour must be one of {PLAY_BEHAVIOURS}, got {config.behaviour!r}")
        self.config = config
        self.operator = None
        self._connected = False

    @cached_property
    def action_features(self) -> dict:
        return dict.fromkeys(ACTION_NAMES, float)

    @cached_property
    def feedback_features(self) -> dict:
        return {}

    @property
    def is_connected(self) -> bool:
        return self._connected

    @property
    def is_calibrated(self) -> bool:
        return True

    def connect(self, calibrate: bool = True) -> None:
        self._connected = True  # the robot may connect after us (lerobot-record does): bound at first use

    def calibrate(self) -> None:
        pass

    def configure(self) -> None:
        pass

    def _robot(self) -> SimPlanarPush:
        robot = _SIM_ROBOTS.get(self.config.robot_id)
        if robot is None:
            raise RuntimeError(
                f"no connected efm_sim_planar_push robot with id {self.config.robot_id!r} in this "
                f"process (connected: {sorted(map(str, _SIM_ROBOTS))}); pass --teleop.robot_id=<its "
                f"--robot.id>"
            )
        return robot

    def get_action(self) -> dict:
        from lerobot_efm.envs.planar_push.demonstrators import BEHAVIOURS

        robot = self._robot()
        if (
            self.operator is None
        ):  # plays on from the state the robot is in (no reset: no jump in the recording)
            cls = BEHAVIOURS[self.config.behaviour][0]
            self.operator = cls(robot.env, np.random.default_rng(self.config.seed), noise=self.config.noise)
        command = self.operator.act(robot.env.observe())
        return {name: float(x) for name, x in zip(ACTION_NAMES, command, strict=True)}

    def send_feedback(self, feedback: dict) -> None:
        pass

    def disconnect(self) -> None:
        self._connected = False
        self.operator = None
