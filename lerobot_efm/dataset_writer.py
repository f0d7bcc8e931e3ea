"""The one LeRobot v3 dataset writer behind every recording path of the plugin: ``lerobot-efm-record`` (scripted
operators in the envs), the planar push demonstrators, the synthetic point play and the OGBench converter.

It keeps every saved episode, whatever stops the process:

* an exception inside an episode: the caller drops that episode (:meth:`EpisodeWriter.drop_episode`) or lets it
  propagate; on exit the unsaved frames are dropped and LeRobot's ``VideoEncodingManager`` finalizes the dataset
  (parquet footers, pending videos, temporary images);
* SIGINT / SIGTERM: noted by :class:`InterruptGuard` and raised as :class:`RecordingInterrupted` at the next frame
  (never inside ``save_episode``, which would leave a half-written episode): at most the unfinished episode is lost;
* SIGKILL (OOM killer, power cut), which cannot be caught: the files are sealed at episode boundaries
  (:func:`lerobot_efm.crash_safe.seal_episode_files`), after every episode (``seal_interval_s=0``, recorders: a
  human's or a simulator's episode is expensive) or at the first boundary ``seal_interval_s`` seconds after the
  last seal (generators and converters, which can re-run from their source: sealing opens new files, and a
  thousand one-episode files would slow every later read). Worst case: the episodes saved in the last
  ``seal_interval_s`` seconds plus the one being written; ``--resume`` repairs the debris of a save cut short.
"""

from __future__ import annotations

import signal
import time
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.datasets.video_utils import VideoEncodingManager
from lerobot.utils.utils import SuppressProgressBars

from .crash_safe import drop_sealed_copy, keep_sealed_copy, repair_dataset, seal_episode_files

GENERATOR_SEAL_INTERVAL_S = 30.0  # generators / converters: at most 30 s of their output lost to a SIGKILL
_now = time.monotonic  # the sealing clock (a test steps it)


@dataclass
class DatasetTarget:
    """``--dataset.repo_id`` / ``--dataset.root`` of the generators and converters (LeRobot's flag names)."""

    repo_id: str | None = None  # default: the generator's (local/<name>)
    root: str | None = None  # a new directory

    def resolved(self, default_repo_id: str) -> tuple[str, Path]:
        if not self.root:
            raise ValueError("--dataset.root is required (a new directory, e.g. data/my_play)")
        return self.repo_id or default_repo_id, Path(self.root)


class RecordingInterrupted(Exception):
    """SIGINT or SIGTERM arrived while writing; raised between frames so that no episode is half-written."""


class InterruptGuard:
    """Notes SIGINT/SIGTERM while active; :meth:`raise_pending` raises :class:`RecordingInterrupted` afterwards.

    The handler never raises itself: an exception thrown into whatever code runs when the signal lands can be
    swallowed there (a logging handler catches it and recording went on: a test hung on it) or leave a
    half-written episode (``save_episode`` consumes the episode buffer as it writes parquet, videos and metadata).
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
        self.previous = {}

    def raise_pending(self):
        if self.pending is not None:
            raise RecordingInterrupted(f"signal {self.pending}")


def vector_feature(names: Sequence[str]) -> dict:
    return {"dtype": "float32", "shape": (len(names),), "names": list(names)}


def camera_feature(shape: Sequence[int], use_videos: bool = True) -> dict:
    return {
        "dtype": "video" if use_videos else "image",
        "shape": tuple(shape),
        "names": ["height", "width", "channels"],
    }


def state_action_features(
    state_names: Sequence[str],
    action_names: Sequence[str],
    cameras: dict[str, int] | None = None,
    use_videos: bool = True,
) -> dict:
    """``observation.state`` + ``action`` (+ square RGB ``observation.images.<name>`` of the given sizes)."""
    features = {"observation.state": vector_feature(state_names), "action": vector_feature(action_names)}
    for name, size in (cameras or {}).items():
        features[f"observation.images.{name}"] = camera_feature((size, size, 3), use_videos)
    return features


def open_dataset(
    root: str | Path,
    repo_id: str,
    fps: int,
    features: dict,
    resume: bool = False,
    robot_type: str | None = None,
    use_videos: bool = True,
) -> LeRobotDataset:
    """A new dataset at ``root`` or, with ``resume``, the existing one there, repaired after a hard kill (its
    features and fps must match)."""
    root = Path(root)
    if resume:
        if not (root / "meta" / "info.json").exists():
            raise FileNotFoundError(f"--resume=true but {root} holds no LeRobot dataset (no meta/info.json)")
        repair_dataset(root)  # debris of a writer killed while saving an episode
        ds = LeRobotDataset.resume(repo_id, root=root)
        have = {k: tuple(v["shape"]) for k, v in ds.meta.features.items() if k in features}
        want = {k: tuple(v["shape"]) for k, v in features.items()}
        if have != want:
            raise ValueError(
                f"Dataset at {root} has features {have}, the source produces {want}: cannot resume"
            )
        if ds.meta.fps != fps:
            raise ValueError(
                f"Dataset at {root} was recorded at {ds.meta.fps} fps, the source runs at {fps} fps"
            )
        keep_sealed_copy(root)
        return ds
    if root.exists():  # LeRobot would fail later with a bare mkdir error
        raise FileExistsError(
            f"Dataset root {root} already exists; pick a new root (lerobot-efm-record appends with --resume=true)"
        )
    dataset = LeRobotDataset.create(
        repo_id,
        fps=fps,
        features=features,
        root=root,
        robot_type=robot_type,
        use_videos=use_videos,
        metadata_buffer_size=1,
    )
    keep_sealed_copy(root)  # a kill during the first save then still finds the features
    return dataset


def drop_unsaved_frames(dataset: LeRobotDataset) -> None:
    """Forget the frames of an episode that was not saved (also one whose ``save_episode`` failed midway,
    which leaves LeRobot's episode buffer half-consumed, without its ``size``)."""
    buffer = dataset.writer.episode_buffer if dataset.writer is not None else None
    if buffer is not None and buffer.get("size", 1) > 0:
        dataset.clear_episode_buffer()


class EpisodeWriter:
    """Frames in, saved episodes out, none of them lost (see the module docstring)::

    with EpisodeWriter.open(root, repo_id, fps, features) as writer:
        for episode in source:
            writer.write_episode(frames)   # or add_frame(...) per frame, then save_episode()
    """

    def __init__(self, dataset: LeRobotDataset, seal_interval_s: float = 0.0):
        if seal_interval_s < 0:
            raise ValueError(f"seal_interval_s={seal_interval_s} must be >= 0")
        self.dataset, self.seal_interval_s = dataset, seal_interval_s
        self.guard = InterruptGuard()
        self._last_seal = _now()

    @classmethod
    def open(cls, root, repo_id: str, fps: int, features: dict, *, seal_interval_s: float = 0.0, **kwargs):
        """:func:`open_dataset` (``resume``, ``robot_type``, ``use_videos``) wrapped in a writer."""
        return cls(open_dataset(root, repo_id, fps, features, **kwargs), seal_interval_s)

    def __enter__(self) -> EpisodeWriter:
        self.guard.__enter__()
        return self

    def __exit__(self, exc_type, exc, tb):
        try:
            drop_unsaved_frames(self.dataset)
            VideoEncodingManager(self.dataset).__exit__(exc_type, exc, tb)  # finalize + temporary images
            drop_sealed_copy(self.dataset.root)
        finally:
            self.guard.__exit__()
        return False

    def check_interrupt(self) -> None:
        """Raise :class:`RecordingInterrupted` if SIGINT/SIGTERM arrived (between frames, never mid-save)."""
        self.guard.raise_pending()

    def add_frame(self, frame: dict) -> None:
        self.check_interrupt()
        self.dataset.add_frame(frame)

    def save_episode(self) -> None:
        """Save the buffered episode and, when due, seal the files so that a SIGKILL keeps it."""
        with SuppressProgressBars():  # LeRobot shows a "Map" bar per saved episode otherwise
            self.dataset.save_episode()
            if _now() - self._last_seal >= self.seal_interval_s:
                seal_episode_files(self.dataset)
                self._last_seal = _now()

    def drop_episode(self) -> None:
        drop_unsaved_frames(self.dataset)

    def write_episode(self, frames: Iterable[dict]) -> int:
        """Add every frame and save them as one episode; returns its length."""
        n = 0
        for frame in frames:
            self.add_frame(frame)
            n += 1
        self.save_episode()
        return n
