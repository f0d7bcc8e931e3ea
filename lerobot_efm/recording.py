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
episode's frames and recording goes on with the next; Ctrl-C or SIGTERM drop the unfinished episode
and finalize the dataset (closing its parquet files), so the saved episodes stay readable and
``--resume=true`` appends to them. Only a hard kill (SIGKILL, power loss) can corrupt the files
being written.
"""

from __future__ import annotations

import importlib
import logging
import signal
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

import gymnasium as gym
import numpy as np
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.utils.utils import SuppressProgressBars

from .crash_safe import repair_dataset, seal_episode_files

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
            feats[key] = {
                "dtype": "video" if use_videos else "image",
                "shape": tuple(value.shape),
                "names": ["height", "width", "channels"],
            }
        else:
            feats[key] = {
                "dtype": "float32",
                "shape": tuple(value.shape),
                "names": names.get(key) or [f"{key.rsplit('.', 1)[-1]}_{i}" for i in range(value.size)],
            }
    feats["action"] = {
        "dtype": "float32",
        "shape": (action_dim,),
        "names": names.get("action") or [f"action_{i}" for i in range(action_dim)],
    }
    return feats


@dataclass
class RecordStats:
    saved: int = 0
    frames: int = 0
    failed: list[str] = field(default_factory=list)
    interrupted: bool = False
    seconds: float = 0.0


class _Interrupt(Exception):
    """SIGINT or SIGTERM, turned into an exception so that ``finally`` blocks run."""


class _InterruptGuard:
    """Notes SIGINT/SIGTERM; the recording loop raises :class:`_Interrupt` at its next frame or after the save.

    The handler never raises itself: an exception thrown into whatever code runs when the signal lands can be
    swallowed there (a logging handler catches it and recording went on: a test hung on it) or leave a
    half-written episode (``save_episode`` consumes the episode buffer as it writes parquet, videos and metadata).
    Checked once per frame, an interrupt costs at most the unfinished episode.
    """

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self):
        self.pending, self.previous = None, {}

    def _handle(self, signum, frame):  # noqa: ARG002
        self.pending = signum

    def __enter__(self):
        self.previous = {sig: signal.signal(sig, self._handle) for sig in self.SIGNALS}
        return self

    def __exit__(self, *exc):
        for sig, handler in self.previous.items():
            signal.signal(sig, handler)

    def raise_pending(self):
        if self.pending is not None:
            raise _Interrupt(f"signal {self.pending}")


def record_episodes(
    dataset: LeRobotDataset,
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
    """Record ``episodes`` episodes of at most ``episode_length`` frames into ``dataset``.

    Each frame is (observation before the action, action). A failing episode is dropped (logged) and
    recording goes on; ``max_failures`` failures in a row stop it. The caller finalizes the dataset.
    """
    stats, failures_in_row, t0 = RecordStats(), 0, time.perf_counter()
    with _InterruptGuard() as guard:
        for ep in range(episodes):
            saved = False
            try:
                env.reset(seed=seed + ep)
                obs = operator.reset()
                n = 0
                while n < episode_length and not (n > 0 and operator.done):
                    guard.raise_pending()
                    action = np.asarray(operator.act(obs), dtype=np.float32)
                    if not np.all(np.isfinite(action)):
                        raise ValueError(f"operator returned a non-finite action {action} at frame {n}")
                    dataset.add_frame(
                        {**flatten_observation(obs, features_map), "action": action, "task": task}
                    )
                    obs, *_ = env.step(action)
                    n += 1
                with SuppressProgressBars():
                    dataset.save_episode()
                    seal_episode_files(dataset)  # on disk, a complete dataset even after a SIGKILL
                saved = True
                stats.saved, stats.frames = stats.saved + 1, stats.frames + n
                guard.raise_pending()
            except _Interrupt:
                stats.interrupted = True
                drop_unsaved_frames(dataset)
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
                drop_unsaved_frames(dataset)
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


def drop_unsaved_frames(dataset: LeRobotDataset) -> None:
    """Forget the frames of an episode that was not saved (also one whose ``save_episode`` failed midway,
    which leaves LeRobot's episode buffer half-consumed, without its ``size``)."""
    buffer = dataset.writer.episode_buffer if dataset.writer is not None else None
    if buffer is not None and buffer.get("size", 1) > 0:
        dataset.clear_episode_buffer()


@contextmanager
def finalizing(dataset: LeRobotDataset):
    """Whatever happens inside, drop the unsaved episode and finalize, so saved episodes stay readable."""
    try:
        yield dataset
    finally:
        drop_unsaved_frames(dataset)
        dataset.finalize()


def open_dataset(
    root: Path, repo_id: str, fps: int, features: dict, resume: bool, robot_type: str | None, use_videos: bool
) -> LeRobotDataset:
    """A new dataset at ``root`` or, with ``resume``, the existing one there (features must match)."""
    if resume:
        if not (root / "meta" / "info.json").exists():
            raise FileNotFoundError(f"--resume=true but {root} holds no LeRobot dataset (no meta/info.json)")
        repair_dataset(root)  # debris of a recorder killed while saving an episode
        ds = LeRobotDataset.resume(repo_id, root=root)
        have = {k: tuple(v["shape"]) for k, v in ds.meta.features.items() if k in features}
        want = {k: tuple(v["shape"]) for k, v in features.items()}
        if have != want:
            raise ValueError(f"Dataset at {root} has features {have}, the env produces {want}: cannot resume")
        if ds.meta.fps != fps:
            raise ValueError(
                f"Dataset at {root} was recorded at {ds.meta.fps} fps, the env runs at {fps} fps"
            )
        return ds
    if root.exists():
        raise FileExistsError(
            f"Dataset root {root} already exists; pass --resume=true to append or pick a new root"
        )
    return LeRobotDataset.create(
        repo_id,
        fps=fps,
        features=features,
        root=root,
        robot_type=robot_type,
        use_videos=use_videos,
        metadata_buffer_size=1,
    )
