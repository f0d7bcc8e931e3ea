"""Record scripted operators in the plugin's environments as LeRobot v3 datasets.

An *operator* plays the role of the human teleoperator of a real recording: it reads the simulator
(privileged state is fine: it stands in for a person looking at the scene) and returns the next
action. Operators are duck-typed::

    operator = Operator(env, rng)        # env: the unwrapped gymnasium env
    obs = operator.reset()               # after env.reset(): pick the episode's initial scene
    action = operator.act(obs)           # next action, recorded with obs, then sent to env.step
    operator.done                        # True: the episode is over before the frame budget

Datasets hold what a LeRobot recording holds: ``observation.*`` (cameras as video),
``action`` and a task string; no goals (hindsight relabelling makes them at train time).

Nothing already saved is lost when recording stops early: an exception in one episode drops that
episode's frames and recording goes on with the next; Ctrl-C, SIGTERM and even SIGKILL keep every saved
episode (:class:`lerobot_efm.dataset_writer.EpisodeWriter`) and ``--resume=true`` appends to them.
"""

from __future__ import annotations

import importlib
import logging
import time
from dataclasses import dataclass, field

import gymnasium as gym
import numpy as np

from .dataset_writer import EpisodeWriter, RecordingInterrupted, camera_feature, vector_feature

GOAL_KEY_PREFIX = "goal."  # goal observations of the env: not recorded (hindsight makes goals)

# (env type, operator name) -> "module:Class", imported when used (the modules import MuJoCo)
OPERATORS: dict[tuple[str, str], str] = {
    ("efm_point_reach", "play"): "lerobot_efm.synthetic:PointPlayOperator",
    ("talos_kitchen", "play"): "lerobot_efm.envs.talos_kitchen.play:TalosPlayOperator",
    ("planar_push", "expert"): "lerobot_efm.envs.planar_push.demonstrators:ExpertReachGoal",
    ("planar_push", "full"): "lerobot_efm.envs.planar_push.demonstrators:PlayFullSpace",
    ("planar_push", "partitioned"): "lerobot_efm.envs.planar_push.demonstrators:PlayPartitioned",
    ("planar_push", "hand"): "lerobot_efm.envs.planar_push.demonstrators:PlayHandOnly",
}


def operator_class(env_type: str, name: str):
    """The operator class registered for ``(env_type, name)``; a clear error lists the valid pairs."""
    target = OPERATORS.get((env_type, name))
    if target is None:
        valid = sorted(f"--env.type={e} --operator={o}" for e, o in OPERATORS)
        raise ValueError(f"No operator {name!r} for env type {env_type!r}; registered: {valid}")
    module, cls = target.split(":")
    return getattr(importlib.import_module(module), cls)


def make_raw_env(env_cfg) -> gym.Env:
    """The env of an ``EnvConfig`` without LeRobot's vector wrapper or time limit (the recorder sets
    its own frame budget)."""
    importlib.import_module(env_cfg.package_name)  # registers the gym id
    kwargs = {k: v for k, v in env_cfg.gym_kwargs.items() if k != "max_episode_steps"}
    return gym.make(env_cfg.gym_id, disable_env_checker=True, **kwargs).unwrapped


def flatten_observation(obs: dict, features_map: dict[str, str]) -> dict[str, np.ndarray]:
    """Raw env observation -> dataset keys (``pixels`` -> ``observation.images.<camera>``, others
    through the env config's ``features_map``); goal entries are left out."""
    out: dict[str, np.ndarray] = {}
    for key, value in obs.items():
        if key.startswith(GOAL_KEY_PREFIX):
            continue
        if key == "pixels":
            cams = value if isinstance(value, dict) else {"image": value}
            for cam, img in cams.items():
                out[f"observation.images.{cam}"] = np.asarray(img)
            continue
        name = features_map.get(key)
        if name is None:
            raise KeyError(
                f"Observation key {key!r} of the env has no entry in the env config's features_map "
                f"({sorted(features_map)}); cannot name it in the dataset"
            )
        out[name] = np.asarray(value, dtype=np.float32)
    return out


def dataset_features(
    frame: dict[str, np.ndarray],
    action_dim: int,
    names: dict[str, list[str]] | None = None,
    use_videos: bool = True,
) -> dict:
    """LeRobot feature spec from one flattened observation (images as video by default)."""
    names = names or {}
    feats: dict[str, dict] = {}
    for key, value in frame.items():
        if key.startswith("observation.images."):
            if value.ndim != 3 or value.shape[-1] != 3 or value.dtype != np.uint8:
                raise ValueError(f"Camera {key!r} must be (H, W, 3) uint8, got {value.shape} {value.dtype}")
            feats[key] = camera_feature(value.shape, use_videos)
        else:
            if value.ndim != 1:
                raise ValueError(f"Observation {key!r} must be a vector, got shape {value.shape}")
            feats[key] = vector_feature(_names(names, key, value.size, key.rsplit(".", 1)[-1]))
    feats["action"] = vector_feature(_names(names, "action", action_dim, "action"))
    return feats


def _names(names: dict[str, list[str]], key: str, size: int, stem: str) -> list[str]:
    given = names.get(key) or [f"{stem}_{i}" for i in range(size)]
    if len(given) != size:
        raise ValueError(f"The env names {len(given)} entries of {key!r} ({given}), its value has {size}")
    return list(given)


@dataclass
class RecordStats:
    saved: int = 0
    frames: int = 0
    failed: list[str] = field(default_factory=list)
    interrupted: bool = False
    seconds: float = 0.0


def record_episodes(
    writer: EpisodeWriter,
    env: gym.Env,
    operator,
    features_map: dict[str, str],
    *,
    episodes: int,
    episode_length: int,
    task: str,
    seed: int = 0,
    max_failures: int = 3,
    on_episode=None,
) -> RecordStats:
    """Record ``episodes`` episodes of at most ``episode_length`` frames through ``writer``.

    Each frame is (observation before the action, action). A failing episode is dropped (logged) and
    recording goes on; ``max_failures`` failures in a row stop it; SIGINT/SIGTERM stop it after the saved
    episodes (``stats.interrupted``). The caller's ``with writer:`` finalizes the dataset.
    """
    stats, failures_in_row, t0 = RecordStats(), 0, time.perf_counter()
    for ep in range(episodes):
        saved = False
        try:
            env.reset(seed=seed + ep)
            obs = operator.reset()
            n = 0
            while n < episode_length and not (n > 0 and operator.done):
                action = np.asarray(operator.act(obs), dtype=np.float32)
                if not np.all(np.isfinite(action)):
                    raise ValueError(f"operator returned a non-finite action {action} at frame {n}")
                writer.add_frame({**flatten_observation(obs, features_map), "action": action, "task": task})
                obs, *_ = env.step(action)
                n += 1
            writer.save_episode()  # sealed: on disk, a complete dataset even after a SIGKILL
            saved = True
            stats.saved, stats.frames = stats.saved + 1, stats.frames + n
            writer.check_interrupt()
        except RecordingInterrupted:
            stats.interrupted = True
            writer.drop_episode()
            logging.warning(
                "Recording interrupted during episode %d (%s); %d saved episodes are kept.",
                ep,
                "saved first" if saved else "its frames are dropped",
                stats.saved,
            )
            break
        except Exception as err:  # one bad episode must not lose the others
            logging.exception("Episode %d failed and is dropped", ep)
            stats.failed.append(f"episode {ep}: {type(err).__name__}: {err}")
            writer.drop_episode()
            failures_in_row += 1
            if failures_in_row >= max_failures:
                logging.error("%d episodes failed in a row; stopping.", failures_in_row)
                break
            continue
        failures_in_row = 0
        if on_episode is not None:
            on_episode(ep, n, stats)
    stats.seconds = time.perf_counter() - t0
    return stats
