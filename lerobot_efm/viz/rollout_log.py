"""Log EFM policy rollouts to a rerun recording (an ``.rrd`` file, no viewer needed).

Everything of episode ``i`` lives under ``episode_{i}/`` on two timelines: ``step`` (control step, a
sequence) and ``time`` (``step / fps`` seconds, a duration). Entity paths (``ep`` = ``episode_{i}``):

=================================  ==========================================================================
``ep/camera/render``               ``env.render()`` frame (optional)
``ep/camera/<cam>``                ``observation.images.<cam>`` as seen by the policy (before normalisation)
``ep/goal/<cam>``                  ``observation.goal.images.<cam>`` (goal image)
``ep/world/<name>``                3-D point of the agent (``EnvViz.state_points``; point env: ``agent``; Talos:
                                   ``hand_commanded``, ``hand_measured``) or of an object (``EnvViz.object_points``;
                                   Talos: ``pot``, ``door_handle``, ``tray_handle``)
``ep/world/<name>_path``           the trajectory so far (line strip)
``ep/world/goal_<name>``           the goal point (from ``observation.goal.state`` / ``.goal.environment_state``)
``ep/world/action_chunk``          at each replanning: the predicted action chunk (``EnvViz.action_points``)
``ep/world/obs_plan``              planned observations ``obs_plan`` (FM-PC/PS/AS), when they are low-dimensional
``ep/world/candidates``            FM-PS/FM-AS: every candidate plan/chunk, the chosen one thick and red
``ep/action``                      executed action (unnormalised), one series per dimension
``ep/action_chunk/r<step>``        the chunk predicted at ``<step>``, over the steps it covers
``ep/distance/critic``             critic estimate of the steps to the goal, at each replanning
``ep/distance/true_remaining``     steps actually left, back-filled once the episode succeeded
``ep/distance/candidates``         FM-PS/FM-AS: the critic score of every candidate
``ep/obs/<key>``                   vector observations (``observation.state``, ``observation.environment_state``...),
                                   series named by ``EnvViz.dim_names``
``ep/objects/<name>``              object states (``EnvViz.object_series``; Talos: door, tray, pot_x/y/z), the
                                   goal's as ``ep/objects/goal_<name>``
``ep/goal_obs/<key>``              vector goal observations (``observation.goal.state``...)
``ep/reward``, ``ep/success``      per step
``ep/info/<key>``                  numeric ``info`` entries of the env (point env: ``distance``)
``ep/events``                      text log: replans, end of episode
``scene/...``                      static env geometry (point env: arena and wall; Talos: table, cabinet, workspace)
=================================  ==========================================================================

Env-specific geometry is a hook: :func:`register_env_viz` maps an env type (``--env.type``) to an
:class:`EnvViz` saying which observation / action dimensions are positions.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb
import torch

STATE_KEY = "observation.state"
GOAL_STATE_KEY = "observation.goal.state"
ENV_STATE_KEY = "observation.environment_state"
IMAGE_PREFIX = "observation.images."
GOAL_IMAGE_PREFIX = "observation.goal.images."
GOAL_PREFIX = "observation.goal."

CHOSEN_COLOR = (230, 40, 40)
CANDIDATE_COLOR = (150, 150, 150)
CHUNK_COLOR = (40, 90, 230)
PLAN_COLOR = (240, 150, 20)
GOAL_COLOR = (40, 170, 60)
AGENT_COLOR = (210, 40, 40)
# the state_points / object_points of an env, in order (first: the agent, as AGENT_COLOR)
POINT_COLORS = ((210, 40, 40), (150, 60, 200), (230, 140, 20), (20, 160, 170), (140, 90, 40), (200, 60, 140))
OBJECT_COLOR_OFFSET = 2  # objects take the palette after the (usually two) agent points


# --------------------------------------------------------------------------------------------------
# Env-specific geometry hooks
# --------------------------------------------------------------------------------------------------


def pad3(x: np.ndarray) -> np.ndarray:
    """(..., k) -> (..., 3): the first 3 dims, zero-padded (2-D positions get z = 0)."""
    x = np.asarray(x, dtype=np.float32)
    out = np.zeros((*x.shape[:-1], 3), dtype=np.float32)
    k = min(3, x.shape[-1])
    out[..., :k] = x[..., :k]
    return out


@dataclass
class EnvViz:
    """How to draw an env in 3-D (and name its vectors in the plots).

    state_points: (..., S) unnormalised ``observation.state`` -> {name: (..., 3)} positions to draw
        (also applied to ``observation.goal.state`` and to planned states).
    action_points: (..., A) unnormalised actions -> (..., 3), or None when actions are not positions.
    scene: optional callback ``scene(rec)`` logging static geometry under ``scene/``.
    object_points: other vector observation key (e.g. ``observation.environment_state``) -> callback
        (D,) -> {name: (3,)}: objects drawn at ``ep/world/<name>`` with their path (goal: ``goal_<name>``).
    object_series: observation key -> callback (D,) -> {name: float}: object states plotted under
        ``ep/objects/<name>``, the goal's under ``ep/objects/goal_<name>`` (names are entity path parts).
    dim_names: observation key -> one name per dimension, the legend of ``ep/obs/<key>`` series (and, prefixed
        with ``goal``, of its goal mirror).
    eye: ``(position, look_target)`` of the 3-D view's camera (z up), None for rerun's default.
    object_series_title: the name of the plot of ``object_series``.
    """

    state_points: Callable[[np.ndarray], dict[str, np.ndarray]]
    action_points: Callable[[np.ndarray], np.ndarray | None] | None = None
    scene: Callable[[rr.RecordingStream], None] | None = None
    object_points: dict[str, Callable[[np.ndarray], dict[str, np.ndarray]]] = field(default_factory=dict)
    object_series: dict[str, Callable[[np.ndarray], dict[str, float]]] = field(default_factory=dict)
    dim_names: dict[str, Sequence[str]] = field(default_factory=dict)
    eye: tuple[Sequence[float], Sequence[float]] | None = None
    object_series_title: str = "objects (thin: goal)"


def _default_state_points(state: np.ndarray) -> dict[str, np.ndarray]:
    return {"agent": pad3(state)}


DEFAULT_ENV_VIZ = EnvViz(state_points=_default_state_points, action_points=pad3)


def _point_reach_scene(rec: rr.RecordingStream) -> None:
    from lerobot_efm.envs.point_reach import WALL_HALF_WIDTH, WALL_TOP

    square = [[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [-1, -1, 0]]
    w = WALL_HALF_WIDTH
    wall = [[-w, -1, 0], [w, -1, 0], [w, WALL_TOP, 0], [-w, WALL_TOP, 0], [-w, -1, 0]]
    rec.log("scene/arena", rr.LineStrips3D([square], colors=[(120, 120, 120)], radii=0.004), static=True)
    rec.log("scene/wall", rr.LineStrips3D([wall], colors=[(60, 60, 60)], radii=0.008), static=True)


POINT_REACH_VIZ = EnvViz(
    state_points=lambda s: {"agent": pad3(np.asarray(s)[..., :2])},
    action_points=lambda a: pad3(np.asarray(a)[..., :2]),  # absolute position commands
    scene=_point_reach_scene,
    dim_names={STATE_KEY: ("x", "y")},
    eye=((0.0, -1.5, 2.3), (0.0, -0.1, 0.0)),  # from above, slightly tilted: the 2-D arena stays readable
)


def hand_points(
    commanded: slice = slice(0, 3), measured: slice | None = None, action: slice | None = None
) -> EnvViz:
    """An EnvViz for arms whose state holds the commanded and (optionally) measured hand positions and whose
    actions hold the hand position command at ``action`` (default: the ``commanded`` slice of the state).
    Talos: :data:`TALOS_KITCHEN_VIZ` (``observation.state[0:3]`` commanded, ``[10:13]`` measured)."""
    action = commanded if action is None else action

    def state_points(s: np.ndarray) -> dict[str, np.ndarray]:
        s = np.asarray(s)
        points = {"hand_commanded": pad3(s[..., commanded])}
        if measured is not None:
            points["hand_measured"] = pad3(s[..., measured])
        return points

    return EnvViz(state_points=state_points, action_points=lambda a: pad3(np.asarray(a)[..., action]))


# --- Talos kitchen ------------------------------------------------------------------------------------


def _talos_layout() -> dict[str, int]:
    """Where the hand positions and object states sit in the talos_kitchen vectors (from the env's names)."""
    from lerobot_efm.envs.talos_kitchen.env import ENV_STATE_NAMES, STATE_NAMES

    return {
        "cmd": STATE_NAMES.index("cmd_x"),
        "measured": STATE_NAMES.index("x"),
        "door": ENV_STATE_NAMES.index("door"),
        "tray": ENV_STATE_NAMES.index("tray"),
        "pot": ENV_STATE_NAMES.index("pot_x"),
    }


def _talos_objects(env_state: np.ndarray) -> dict[str, np.ndarray]:
    """Door handle, tray handle (where the door angle / tray slide put them) and pot base centre, in 3-D."""
    from lerobot_efm.envs.talos_kitchen import scene

    i, e = _talos_layout(), np.asarray(env_state, np.float64).reshape(-1)
    # the handle helpers read only the constants of the scene when the angle / slide is given
    return {
        "door_handle": scene.door_handle_pos(None, None, angle=float(e[i["door"]])).astype(np.float32),
        "tray_handle": scene.tray_handle_pos(None, None, slide=float(e[i["tray"]])).astype(np.float32),
        "pot": e[i["pot"] : i["pot"] + 3].astype(np.float32),
    }


def _talos_series(env_state: np.ndarray) -> dict[str, float]:
    i, e = _talos_layout(), np.asarray(env_state, np.float64).reshape(-1)
    pot = e[i["pot"] : i["pot"] + 3]
    return {"door": e[i["door"]], "tray": e[i["tray"]], "pot_x": pot[0], "pot_y": pot[1], "pot_z": pot[2]}


def _box_outline(lo, hi) -> list[list[float]]:
    """The 12 edges of an axis-aligned box as 2-point strips."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array(
        [[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    )
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
    return [[corners[i].tolist(), corners[j].tolist()] for i, j in edges]


def _talos_scene(rec: rr.RecordingStream) -> None:
    """Table top, cabinet front and door hinge, and the hand workspace box (static, from the scene constants)."""
    from lerobot_efm.envs.talos_kitchen import control, scene

    (tx, ty), (hx, hy), z = scene.TABLE_CENTER, scene.TABLE_HALF, scene.TABLE_TOP
    table = [
        [tx - hx, ty - hy, z],
        [tx + hx, ty - hy, z],
        [tx + hx, ty + hy, z],
        [tx - hx, ty + hy, z],
        [tx - hx, ty - hy, z],
    ]
    x0, y0, y1 = scene.CAB_X0, scene.CAB_Y0, scene.CAB_Y1
    cabinet = [[x0, y0, 0.0], [x0, y1, 0.0], [x0, y1, 1.25], [x0, y0, 1.25], [x0, y0, 0.0]]
    hinge = [
        [scene.DOOR_HINGE[0], scene.DOOR_HINGE[1], 0.92],
        [scene.DOOR_HINGE[0], scene.DOOR_HINGE[1], 1.25],
    ]
    rec.log("scene/table", rr.LineStrips3D([table], colors=[(150, 110, 60)], radii=0.006), static=True)
    rec.log(
        "scene/cabinet", rr.LineStrips3D([cabinet, hinge], colors=[(110, 110, 110)], radii=0.005), static=True
    )
    rec.log(
        "scene/workspace",
        rr.LineStrips3D(
            _box_outline(control.WORKSPACE_LOW, control.WORKSPACE_HIGH), colors=[(200, 200, 200)], radii=0.002
        ),
        static=True,
    )
    rec.log(
        "scene/robot_base",
        rr.Points3D(
            [[0.0, 0.0, scene.BASE_HEIGHT]], colors=[(90, 90, 90)], radii=0.05, labels=["Talos base"]
        ),
        static=True,
    )


def _talos_kitchen_viz() -> EnvViz:
    from lerobot_efm.envs.talos_kitchen.env import ENV_STATE_NAMES, STATE_NAMES

    i = _talos_layout()
    viz = hand_points(
        commanded=slice(i["cmd"], i["cmd"] + 3),
        measured=slice(i["measured"], i["measured"] + 3),
        action=slice(0, 3),
    )  # actions: position (3) + rot6d (6) + gripper (1)
    viz.scene = _talos_scene
    viz.object_points = {ENV_STATE_KEY: _talos_objects}
    viz.object_series = {ENV_STATE_KEY: _talos_series}
    viz.object_series_title = "door (rad), tray, pot (m); thin: goal"
    viz.dim_names = {STATE_KEY: STATE_NAMES, ENV_STATE_KEY: ENV_STATE_NAMES}
    viz.eye = (
        (-0.55, -1.25, 1.75),
        (0.45, 0.1, 0.95),
    )  # behind the robot's right shoulder, facing the kitchen
    return viz


TALOS_KITCHEN_VIZ = _talos_kitchen_viz()

_ENV_VIZ: dict[str, EnvViz] = {"efm_point_reach": POINT_REACH_VIZ, "talos_kitchen": TALOS_KITCHEN_VIZ}


def register_env_viz(env_type: str, viz: EnvViz) -> None:
    """Declare how to draw the env ``env_type`` (the ``--env.type`` name)."""
    _ENV_VIZ[env_type] = viz


# Geometry kept next to its env, imported on first use (module:attribute).
_LAZY_ENV_VIZ = {
    "planar_push": "lerobot_efm.envs.planar_push.viz:PLANAR_PUSH_VIZ",
    "ogbench": "lerobot_efm.ogbench.viz:OGBENCH_VIZ",
}


def get_env_viz(env_type: str | None) -> EnvViz:
    if env_type in _LAZY_ENV_VIZ and env_type not in _ENV_VIZ:
        module, attr = _LAZY_ENV_VIZ[env_type].split(":")
        _ENV_VIZ[env_type] = getattr(importlib.import_module(module), attr)
    return _ENV_VIZ.get(env_type or "", DEFAULT_ENV_VIZ)


# --------------------------------------------------------------------------------------------------
# Conversions
# --------------------------------------------------------------------------------------------------


def to_numpy(x) -> np.ndarray:
    if isinstance(x, torch.Tensor):
        return x.detach().float().cpu().numpy()
    return np.asarray(x)


def to_hwc_uint8(img) -> np.ndarray | None:
    """An image as (H, W, C) uint8, from (C, H, W) / (H, W, C), float in [0, 1] or [0, 255], or uint8."""
    x = to_numpy(img) if isinstance(img, torch.Tensor) else np.asarray(img)
    while x.ndim > 3 and x.shape[0] == 1:
        x = x[0]
    if x.ndim != 3:
        return None
    if x.shape[0] in (1, 3, 4) and x.shape[-1] not in (1, 3, 4):
        x = np.moveaxis(x, 0, -1)
    if x.dtype != np.uint8:
        scale = 255.0 if float(np.nanmax(x, initial=0.0)) <= 1.0 + 1e-6 else 1.0
        x = np.clip(x * scale, 0, 255).astype(np.uint8)
    return x


def _normalizer_step(preprocessor):
    from lerobot.processor import NormalizerProcessorStep

    for step in getattr(preprocessor, "steps", []):
        if isinstance(step, NormalizerProcessorStep):
            return step
    return None


_INVERSES: dict[int, tuple] = {}  # id(normaliser step) -> (step, its inverse): built once per pipeline


def _inverse_of(step):
    """LeRobot's public inverse of a normaliser step: an UnnormalizerProcessorStep with the same features, modes
    and statistics (its state dict)."""
    from lerobot.processor import UnnormalizerProcessorStep

    if id(step) not in _INVERSES:
        inverse = UnnormalizerProcessorStep(features=step.features, norm_map=step.norm_map, eps=step.eps)
        inverse.load_state_dict(step.state_dict())
        _INVERSES[id(step)] = (step, inverse)
    return _INVERSES[id(step)][1]


def unnormalize(preprocessor, key: str, x: torch.Tensor) -> torch.Tensor:
    """Inverse of the policy preprocessor's normalisation of ``key`` (identity when it has none)."""
    from lerobot.processor import TransitionKey
    from lerobot.processor.converters import create_transition

    step = _normalizer_step(preprocessor)
    if step is None:
        return x
    inverse = _inverse_of(step)
    if key == "action":
        return inverse(create_transition(action=x))[TransitionKey.ACTION]
    return inverse(create_transition(observation={key: x}))[TransitionKey.OBSERVATION][key]


def latent_to_states(policy, preprocessor, latent: torch.Tensor) -> dict[str, np.ndarray] | None:
    """Planned latents (..., D) -> unnormalised vector observations, when the latent *is* the
    observation (identity state encoder, no camera); None otherwise (latent image features)."""
    encoder = getattr(getattr(policy, "ema_model", None), "encoder", None)
    if encoder is None or encoder.image_keys or policy.config.state_encoder != "identity":
        return None
    dims = {k: policy.config.observation_features["observation." + k].shape[0] for k in encoder.vector_keys}
    if sum(dims.values()) != latent.shape[-1]:
        return None
    out, start = {}, 0
    for k, dim in dims.items():  # the encoder concatenates the sorted vector keys
        key = "observation." + k
        out[key] = to_numpy(unnormalize(preprocessor, key, latent[..., start : start + dim].float()))
        start += dim
    return out


def unnormalize_actions(postprocessor, chunk: torch.Tensor) -> np.ndarray:
    """Normalised actions (..., A) -> raw, through the policy postprocessor (unnormaliser + cpu)."""
    flat = chunk.reshape(-1, chunk.shape[-1])
    try:
        raw = postprocessor(flat) if postprocessor is not None else flat
    except Exception:  # noqa: BLE001  (a postprocessor that only takes (B, A) single actions)
        raw = torch.stack([postprocessor(a[None])[0] for a in flat])
    return to_numpy(raw).reshape(*chunk.shape)


# --------------------------------------------------------------------------------------------------
# Logger
# --------------------------------------------------------------------------------------------------


class RolloutLogger:
    """Logs rollouts of one policy in one env type to a ``rr.RecordingStream``.

    Usage per episode: ``begin_episode(i)``; per step ``log_observation(t, obs)`` (the observation after
    LeRobot's ``preprocess_observation`` and the env preprocessor, batch of 1), ``log_prediction(t, pred)``
    when the policy replanned, ``log_action(t, action)``, ``log_outcome(t, reward, success, info)``;
    finally ``end_episode(length, success)``. ``blueprint()`` gives the default layout.
    """

    def __init__(
        self,
        rec: rr.RecordingStream,
        env_type: str | None,
        fps: float,
        policy=None,
        preprocessor=None,
        postprocessor=None,
        env_viz: EnvViz | None = None,
    ):
        self.rec, self.fps = rec, float(fps)
        self.policy, self.preprocessor, self.postprocessor = policy, preprocessor, postprocessor
        self.viz = env_viz or get_env_viz(env_type)
        self.episodes: list[dict] = []
        self.cameras: set[str] = set()
        self.goal_cameras: set[str] = set()
        self._goal_images: dict[str, np.ndarray] = {}  # the goal image last logged per camera, this episode
        self._static_done: set[str] = set()
        if self.viz.scene is not None:
            self.viz.scene(rec)

    # --- helpers -----------------------------------------------------------------------------------
    @property
    def ep(self) -> str:
        return f"episode_{self.episodes[-1]['index']}"

    def set_step(self, step: int) -> None:
        self.rec.set_time("step", sequence=int(step))
        self.rec.set_time("time", duration=float(step) / self.fps)

    def _series_names(self, path: str, names: list[str], color=None) -> None:
        if path in self._static_done:
            return
        self._static_done.add(path)
        kwargs = {} if color is None else {"colors": [color] * len(names)}
        self.rec.log(path, rr.SeriesLines(names=names, **kwargs), static=True)

    def _scalars(self, path: str, values, names: list[str] | None = None, color=None) -> None:
        values = np.atleast_1d(np.asarray(values, dtype=np.float64)).reshape(-1)
        self._series_names(
            path,
            names
            or ([path.rsplit("/", 1)[-1]] if len(values) == 1 else [f"{i}" for i in range(len(values))]),
            color,
        )
        self.rec.log(path, rr.Scalars(values))

    # --- episode -----------------------------------------------------------------------------------
    def begin_episode(self, index: int, task: str | None = None, seed: int | None = None) -> None:
        self.episodes.append(
            {"index": int(index), "path": {}, "length": None, "success": None, "task": task, "seed": seed}
        )
        self.set_step(0)
        self._goal_images = {}
        self.rec.log(f"{self.ep}/events", rr.TextLog(f"episode {index} starts (task={task!r}, seed={seed})"))

    def log_render(self, step: int, frame) -> None:
        img = to_hwc_uint8(frame) if frame is not None else None
        if img is not None:
            self.set_step(step)
            self.cameras.add("render")
            self.rec.log(f"{self.ep}/camera/render", rr.Image(img))

    def _dim_names(self, key: str, size: int) -> list[str]:
        """Legend of the series of observation ``key`` (its goal mirror: the observation's names, 'goal ' first)."""
        base, prefix = key, ""
        if key.startswith(GOAL_PREFIX):
            base, prefix = "observation." + key[len(GOAL_PREFIX) :], "goal "
        names = self.viz.dim_names.get(base)
        if names is None or len(names) != size:
            return [f"{prefix}{i}" for i in range(size)]
        return [f"{prefix}{n}" for n in names]

    def _log_points(self, points: dict[str, np.ndarray], color_offset: int = 0) -> None:
        """Each named 3-D point at ``ep/world/<name>`` and its path so far at ``ep/world/<name>_path``."""
        paths = self.episodes[-1]["path"]
        for j, (name, p) in enumerate(points.items()):
            color = POINT_COLORS[(color_offset + j) % len(POINT_COLORS)]
            paths.setdefault(name, []).append(np.asarray(p, np.float32).reshape(3))
            self.rec.log(
                f"{self.ep}/world/{name}", rr.Points3D([paths[name][-1]], colors=[color], radii=0.03)
            )
            self.rec.log(
                f"{self.ep}/world/{name}_path",
                rr.LineStrips3D([np.stack(paths[name])], colors=[color], radii=0.006),
            )

    def _log_goal_points(self, points: dict[str, np.ndarray]) -> None:
        for name, p in points.items():
            self.rec.log(
                f"{self.ep}/world/goal_{name}",
                rr.Points3D([np.asarray(p).reshape(3)], colors=[GOAL_COLOR], radii=0.04),
            )

    def _log_object_series(self, values: dict[str, float], goal: bool) -> None:
        """Object states (door angle...) under ``ep/objects/<name>``; the goal's, thin, under ``goal_<name>``."""
        for j, (name, v) in enumerate(values.items()):
            path = f"{self.ep}/objects/{'goal_' if goal else ''}{name}"
            if path not in self._static_done:
                self._static_done.add(path)
                color = POINT_COLORS[(OBJECT_COLOR_OFFSET + j) % len(POINT_COLORS)]
                self.rec.log(
                    path,
                    rr.SeriesLines(
                        names=[f"goal {name}" if goal else name],
                        colors=[color],
                        widths=[1.0 if goal else 2.5],
                    ),
                    static=True,
                )
            self.rec.log(path, rr.Scalars([float(v)]))

    def log_observation(self, step: int, observation: dict) -> None:
        self.set_step(step)
        ep = self.ep
        vectors: dict[str, np.ndarray] = {}
        for key, value in observation.items():
            if not isinstance(value, (torch.Tensor, np.ndarray)):
                continue
            if key.startswith(GOAL_IMAGE_PREFIX):
                cam = key[len(GOAL_IMAGE_PREFIX) :]
                img = to_hwc_uint8(value)
                if img is not None and not np.array_equal(img, self._goal_images.get(cam)):
                    self.goal_cameras.add(cam)  # logged when it changes (a goal sequence), not every step
                    self._goal_images[cam] = img
                    self.rec.log(f"{ep}/goal/{cam}", rr.Image(img))
            elif key.startswith(IMAGE_PREFIX):
                cam = key[len(IMAGE_PREFIX) :]
                img = to_hwc_uint8(value)
                if img is not None:
                    self.cameras.add(cam)
                    self.rec.log(f"{ep}/camera/{cam}", rr.Image(img))
            elif key.startswith("observation.") and to_numpy(value).ndim <= 2:
                vec = vectors[key] = to_numpy(value).reshape(-1)
                if key.startswith(GOAL_PREFIX):
                    self._scalars(
                        f"{ep}/goal_obs/{key[len(GOAL_PREFIX) :]}", vec, self._dim_names(key, len(vec))
                    )
                else:
                    self._scalars(
                        f"{ep}/obs/{key[len('observation.') :]}", vec, self._dim_names(key, len(vec))
                    )
        if STATE_KEY in vectors:
            self._log_points(self.viz.state_points(vectors[STATE_KEY]))
        if GOAL_STATE_KEY in vectors:
            self._log_goal_points(self.viz.state_points(vectors[GOAL_STATE_KEY]))
        for key, points in self.viz.object_points.items():
            goal_key = GOAL_PREFIX + key[len("observation.") :]
            if key in vectors:
                self._log_points(points(vectors[key]), OBJECT_COLOR_OFFSET)
            if goal_key in vectors:
                self._log_goal_points(points(vectors[goal_key]))
        for key, series in self.viz.object_series.items():
            goal_key = GOAL_PREFIX + key[len("observation.") :]
            if key in vectors:
                self._log_object_series(series(vectors[key]), goal=False)
            if goal_key in vectors:
                self._log_object_series(series(vectors[goal_key]), goal=True)

    def log_action(self, step: int, action) -> None:
        self.set_step(step)
        a = to_numpy(action).reshape(-1)
        self._scalars(f"{self.ep}/action", a, [f"a{i}" for i in range(len(a))])

    def log_prediction(self, step: int, prediction: dict) -> None:
        """What the policy believed when it replanned at ``step`` (``policy.last_prediction``, batch row 0)."""
        self.set_step(step)
        ep, cfg = self.ep, getattr(self.policy, "config", None)
        stride = int(getattr(cfg, "action_traj_stride", 1) or 1)
        self.rec.log(f"{ep}/events", rr.TextLog(f"replan at step {step}"))
        if "action" in prediction:
            chunk = unnormalize_actions(self.postprocessor, prediction["action"][:1])[0]  # (L_a, A)
            pts = self.viz.action_points(chunk) if self.viz.action_points else None
            if pts is not None:
                self.rec.log(
                    f"{ep}/world/action_chunk", rr.LineStrips3D([pts], colors=[CHUNK_COLOR], radii=0.008)
                )
            names = [f"a{i}" for i in range(chunk.shape[-1])]
            path = f"{ep}/action_chunk/r{step:04d}"
            self._series_names(path, [f"{n} @{step}" for n in names])
            for j, a in enumerate(chunk):  # waypoint j covers control step step + j * S_a
                self.set_step(step + j * stride)
                self.rec.log(path, rr.Scalars(a.astype(np.float64)))
            self.set_step(step)
        if "distance" in prediction:
            d = float(to_numpy(prediction["distance"]).reshape(-1)[0])
            self._series_names(f"{ep}/distance/critic", ["critic estimate (steps)"], (40, 90, 230))
            self.rec.log(f"{ep}/distance/critic", rr.Scalars([d]))
        scores = prediction.get("candidate_distances")
        scores = None if scores is None else to_numpy(scores)[0]
        chosen = prediction.get("chosen_candidate")
        chosen = None if chosen is None else int(to_numpy(chosen).reshape(-1)[0])
        if scores is not None:
            self._scalars(f"{ep}/distance/candidates", scores, [f"c{i}" for i in range(len(scores))])
        if "obs_plan" in prediction:
            states = latent_to_states(self.policy, self.preprocessor, prediction["obs_plan"][:1])
            if states is not None and STATE_KEY in states:
                strips = list(self.viz.state_points(states[STATE_KEY][0]).values())
                self.rec.log(
                    f"{ep}/world/obs_plan",
                    rr.LineStrips3D(strips, colors=[PLAN_COLOR] * len(strips), radii=0.01),
                )
        candidates = None
        if "candidate_obs_plans" in prediction:
            states = latent_to_states(self.policy, self.preprocessor, prediction["candidate_obs_plans"][:1])
            if states is not None and STATE_KEY in states:
                candidates = list(self.viz.state_points(states[STATE_KEY][0]).values())[0]  # (N, L_o, 3)
        elif "candidate_actions" in prediction and self.viz.action_points:
            raw = unnormalize_actions(self.postprocessor, prediction["candidate_actions"][:1])[
                0
            ]  # (N, L_a, A)
            candidates = self.viz.action_points(raw)
        if candidates is not None:
            n = len(candidates)
            colors = [CHOSEN_COLOR if i == chosen else CANDIDATE_COLOR for i in range(n)]
            radii = [0.012 if i == chosen else 0.003 for i in range(n)]
            labels = [f"{i}: {scores[i]:.1f}" if scores is not None else str(i) for i in range(n)]
            self.rec.log(
                f"{ep}/world/candidates",
                rr.LineStrips3D(
                    list(candidates), colors=colors, radii=radii, labels=labels, show_labels=False
                ),
            )

    def log_outcome(self, step: int, reward: float, success: bool, info: dict | None = None) -> None:
        """Reward and success of the transition taken at ``step``."""
        self.set_step(step)
        ep = self.ep
        self._scalars(f"{ep}/reward", [float(reward)], ["reward"])
        self._scalars(f"{ep}/success", [float(bool(success))], ["success"])
        for key, value in (info or {}).items():
            if key.startswith("_") or key in ("is_success", "final_info", "final_obs"):
                continue
            v = np.asarray(value)
            if v.dtype.kind in "fiub" and v.size == 1:
                self._scalars(f"{ep}/info/{key}", [float(v.reshape(-1)[0])], [key])

    def end_episode(self, length: int, success: bool) -> None:
        """``length`` env steps were taken; on success, back-fill the true number of steps left."""
        ep = self.ep
        self.episodes[-1].update(length=int(length), success=bool(success))
        if success:
            self._series_names(f"{ep}/distance/true_remaining", ["true steps left"], (40, 170, 60))
            for t in range(length + 1):
                self.set_step(t)
                self.rec.log(f"{ep}/distance/true_remaining", rr.Scalars([float(length - t)]))
        self.set_step(length)
        self.rec.log(
            f"{ep}/events",
            rr.TextLog(
                f"episode {self.episodes[-1]['index']} ends after {length} steps, success={bool(success)}",
                level=rr.TextLogLevel.INFO,
            ),
        )

    # --- layout ------------------------------------------------------------------------------------
    def blueprint(self, episodes: list[int] | None = None) -> rrb.Blueprint:
        """One tab per episode (``episodes``: indices; default the logged ones): cameras and goal images | the 3-D
        world | plots, events below. The side panels start collapsed and the time cursor at the end of the
        recording (the whole trajectory shows)."""
        eye = (
            None
            if self.viz.eye is None
            else rrb.EyeControls3D(
                position=self.viz.eye[0], look_target=self.viz.eye[1], eye_up=(0.0, 0.0, 1.0)
            )
        )
        tabs = []
        for index in [e["index"] for e in self.episodes] if episodes is None else episodes:
            ep = f"episode_{index}"
            images = [rrb.Spatial2DView(origin=f"/{ep}/camera/{c}", name=c) for c in sorted(self.cameras)]
            images += [
                rrb.Spatial2DView(origin=f"/{ep}/goal/{c}", name=f"goal {c}")
                for c in sorted(self.goal_cameras)
            ]
            world = rrb.Spatial3DView(
                origin="/", contents=["/scene/**", f"/{ep}/world/**"], name="world", eye_controls=eye
            )
            plots = [
                rrb.TimeSeriesView(origin=f"/{ep}/distance", name="distance to goal (steps)"),
                rrb.TimeSeriesView(
                    origin=f"/{ep}",
                    contents=[f"/{ep}/action", f"/{ep}/action_chunk/**"],
                    name="actions & chunks",
                    plot_legend=rrb.PlotLegend(visible=False),
                ),  # one series per dim and chunk: too long
            ]
            if self.viz.object_series:
                plots.append(rrb.TimeSeriesView(origin=f"/{ep}/objects", name=self.viz.object_series_title))
            plots.append(
                rrb.TimeSeriesView(
                    origin=f"/{ep}",
                    contents=[
                        f"/{ep}/obs/**",
                        f"/{ep}/goal_obs/**",
                        f"/{ep}/reward",
                        f"/{ep}/success",
                        f"/{ep}/info/**",
                    ],
                    name="state, reward, success",
                    plot_legend=rrb.PlotLegend(visible=False),
                )
            )
            left = [rrb.Vertical(*images)] if images else []
            columns = [*left, world, rrb.Vertical(*plots)]
            shares = ([1] if left else []) + [2, 1.4]
            tabs.append(
                rrb.Vertical(
                    rrb.Horizontal(*columns, column_shares=shares),
                    rrb.TextLogView(origin=f"/{ep}/events", name="events"),
                    row_shares=[6, 1],
                    name=ep,
                )
            )
        root = rrb.Tabs(*tabs) if len(tabs) > 1 else (tabs[0] if tabs else rrb.Spatial3DView(origin="/"))
        return rrb.Blueprint(
            root,
            rrb.BlueprintPanel(state="collapsed"),
            rrb.SelectionPanel(state="collapsed"),
            rrb.TimePanel(timeline="step", state="collapsed", play_state="following"),
        )


# --------------------------------------------------------------------------------------------------
# Reading back
# --------------------------------------------------------------------------------------------------


def read_rrd(path: str | Path) -> dict[str, list[dict]]:
    """All rows of the first recording of an ``.rrd`` file, per entity path (without the leading ``/``),
    through rerun's reader (``rerun.experimental.RrdReader``). Each row maps column names (timelines such as
    ``step``; components such as ``Scalars:scalars``) to python values; static rows have no ``step``."""
    from rerun.experimental import RrdReader

    out: dict[str, list[dict]] = {}
    for chunk in RrdReader(str(path)).stream():
        data = chunk.to_record_batch().to_pydict()
        data.pop("rerun.controls.RowId", None)
        columns = list(data)
        rows = out.setdefault(chunk.entity_path.lstrip("/"), [])
        rows.extend({c: data[c][i] for c in columns} for i in range(chunk.num_rows))
    for rows in out.values():
        rows.sort(key=lambda r: (r.get("step") is not None, r.get("step") or 0, r.get("log_tick") or 0))
    return out
