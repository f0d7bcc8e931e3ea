"""Hindsight-goal relabelling over any LeRobot (v3) dataset, state or video (paper Sec. II-B).

For a start frame k the wrapper yields the tuple (o_k, tau^o, tau^a, d, g) with the goal g = o_{k+d}
taken from the same episode, d ~ U{0 .. min(L_g, frames left)}. Vector columns are read once into
memory; camera frames are decoded only for the frames used (o_k, g, and tau^o when the agent plans), or all
once into RAM with ``cache_frames`` (:mod:`lerobot_efm.frames`), and resized to the policy's image shape.
Keys produced (every ``observation.<key>`` of the policy is mirrored):

    observation.<key>            o_k
    observation.goal.<key>       g = o_{k+d}
    observation.traj.<key>       tau^o: (L_o, ...) frames k + min(j*S_o, d)        (FM-PC/PS/AS)
    observation.rl_goal.<key>    g' uniform over the whole dataset                 (use_rl)
    observation.goal_distance    d in frames
    action                       tau^a: (L_a, A) actions k + j*S_a, past the goal: held (absolute) or 0 (velocity)

Usable in a plain PyTorch loop: ``DataLoader(HindsightGoalDataset(LeRobotDataset(...), config), ...)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pyarrow as pa
import torch

from .configuration_efm import (
    GOAL_DISTANCE_KEY,
    GOAL_PREFIX,
    OBS_PREFIX,
    RL_GOAL_PREFIX,
    TRAJ_PREFIX,
    EFMConfig,
    is_mirror_key,
    mirror_key,
)
from .frames import DecodedFrames, fit_frames
from .processor_efm import mirror_stats


@dataclass(frozen=True)
class HindsightSpec:
    """The sampling parameters, taken from an :class:`EFMConfig` (same names)."""

    obs_traj_len: int
    obs_traj_stride: int
    action_traj_len: int
    action_traj_stride: int
    max_goal_distance: int
    action_mode: str = "absolute"
    use_rl: bool = False
    with_obs_trajectory: bool = False
    observation_keys: tuple[str, ...] | None = None  # None: every observation.* feature of the dataset
    image_shapes: tuple[tuple[str, tuple[int, ...]], ...] = ()  # (key, (C, H, W)) the policy takes
    cache_frames: bool = False
    auxiliary_keys: tuple[str, ...] = ()  # recorded vectors delivered for observation and goal, not encoded
    image_crop: tuple[float, float, float, float] | None = None  # camera region taken before the resize

    @classmethod
    def from_config(cls, config: EFMConfig) -> HindsightSpec:
        keys = tuple(config.observation_features) or None
        return cls(
            config.obs_traj_len,
            config.obs_traj_stride,
            config.action_traj_len,
            config.action_traj_stride,
            config.max_goal_distance,
            config.action_mode,
            config.use_rl and config.uses_critic,
            config.uses_obs_trajectory,
            keys,
            tuple((k, tuple(f.shape)) for k, f in config.image_features.items()),
            config.cache_frames,
            (config.auxiliary_state_key,) if config.auxiliary_state_key else (),
            config.image_crop,
        )

    @property
    def window(self) -> int:
        return max(self.obs_traj_len * self.obs_traj_stride, self.action_traj_len * self.action_traj_stride)


class HindsightGoalDataset(torch.utils.data.Dataset):
    """Wraps a ``LeRobotDataset``; indices are the wrapped dataset's (so LeRobot's samplers apply)."""

    def __init__(self, base, spec: HindsightSpec | EFMConfig):
        self._base = base
        self.spec = spec if isinstance(spec, HindsightSpec) else HindsightSpec.from_config(spec)
        meta = base.meta
        features = meta.features
        available = [k for k in features if k.startswith(OBS_PREFIX) and not is_mirror_key(k)]
        keys = list(self.spec.observation_keys or available)
        keys += [k for k in self.spec.auxiliary_keys if k not in keys]
        missing = [k for k in keys if k not in features]
        if missing:
            raise KeyError(
                f"Dataset {meta.repo_id!r} lacks the observation key(s) {missing} the policy needs; it has {available}."
            )
        if "action" not in features:
            raise KeyError(
                f"Dataset {meta.repo_id!r} has no 'action' feature; EFM policies learn action trajectories."
            )
        if not keys:
            raise KeyError(f"Dataset {meta.repo_id!r} has no observation.* feature to condition on.")
        self.video_keys = [k for k in keys if features[k]["dtype"] == "video"]
        self.image_keys = [k for k in keys if features[k]["dtype"] == "image"]
        self.vector_keys = [k for k in keys if features[k]["dtype"] not in ("video", "image")]

        table = base.hf_dataset.data
        self.episode_index = _column(table, "episode_index").astype(np.int64).reshape(-1)
        self.frame_index = (
            _column(table, "index").astype(np.int64).reshape(-1)
        )  # absolute, as LeRobot's items
        self.timestamps = _column(table, "timestamp").astype(np.float64).reshape(-1)
        self.task_index = _column(table, "task_index").astype(np.int64).reshape(-1)
        self.vectors = {
            k: torch.from_numpy(_column(table, k).astype(np.float32)) for k in [*self.vector_keys, "action"]
        }

        # Episode boundaries from runs of episode_index (rows of one episode are contiguous).
        n = len(self.episode_index)
        starts = np.flatnonzero(np.r_[True, self.episode_index[1:] != self.episode_index[:-1]])
        ends = np.r_[starts[1:], n]
        lengths = ends - starts
        short = [
            (int(self.episode_index[s]), int(length))
            for s, length in zip(starts, lengths, strict=True)
            if length <= self.spec.window
        ]
        if short:
            raise ValueError(
                f"Episode(s) (episode_index, frames) {short[:10]} of {meta.repo_id!r} are not longer than the trajectory window "
                f"max(L_o*S_o, L_a*S_a) = {self.spec.window} frames; drop them or lower obs_traj_len/obs_traj_stride/"
                "action_traj_len/action_traj_stride."
            )
        self.episode_start = np.repeat(starts, lengths)
        self.episode_end = np.repeat(ends, lengths)  # exclusive

        self.image_shapes = dict(self.spec.image_shapes)
        unsized = [k for k in [*self.image_keys, *self.video_keys] if k not in self.image_shapes]
        if self.spec.image_crop is not None and unsized:
            # The pre-processor passes frames at the policy's size as fitted already (training batches) and crops
            # the others (live cameras): a crop needs that size to be known here, and to differ from the camera's.
            raise ValueError(
                f"image_crop={self.spec.image_crop} needs the policy's image size of {unsized}: set it in the "
                "policy's input_features (e.g. a shape of [3, 64, 64]), smaller than the recording's frames"
            )
        self.frame_cache = {
            key: DecodedFrames(
                base,
                key,
                self.episode_index,
                self.timestamps,
                self.image_shapes.get(key),
                self.spec.image_crop,
            )
            for key in (self.video_keys if self.spec.cache_frames else [])
        }

    # --- LeRobotDataset compatibility: lerobot-train reads these from the dataset ----------------
    def __getattr__(self, name):
        if name.startswith("__") or name in ("_base", "spec", "_meta_view"):
            raise AttributeError(name)
        return getattr(self._base, name)

    @property
    def meta(self):
        """The wrapped metadata, whose ``stats`` also cover the goal keys (mirrored observation stats)."""
        if getattr(self, "_meta_view", None) is None:
            self._meta_view = _MirroredStatsMeta(self._base.meta)
        return self._meta_view

    def __len__(self) -> int:
        return len(self._base)

    # --- sampling --------------------------------------------------------------------------------
    def __getitem__(self, idx: int) -> dict:
        spec = self.spec
        k = int(idx)
        if not 0 <= k < len(self.episode_index):
            raise IndexError(f"index {idx} out of range for a dataset of {len(self.episode_index)} frames")
        end = int(self.episode_end[k])
        d = int(torch.randint(0, min(spec.max_goal_distance, end - 1 - k) + 1, ()).item())

        rows = {OBS_PREFIX: [k], GOAL_PREFIX: [k + d]}
        if spec.with_obs_trajectory:
            rows[TRAJ_PREFIX] = [k + min(j * spec.obs_traj_stride, d) for j in range(spec.obs_traj_len)]
        item = self._observations(rows)
        if spec.use_rl:
            item.update(
                self._observations(
                    {RL_GOAL_PREFIX: [int(torch.randint(0, len(self.episode_index), ()).item())]}
                )
            )

        offsets = torch.arange(spec.action_traj_len) * spec.action_traj_stride
        actions = self.vectors["action"][k + offsets.clamp(max=d)]
        if spec.action_mode == "velocity":
            actions = actions * (offsets < d).unsqueeze(-1)
        item["action"] = actions
        item[GOAL_DISTANCE_KEY] = torch.tensor(float(d))
        item["index"] = torch.tensor(int(self.frame_index[k]))
        item["episode_index"] = torch.tensor(int(self.episode_index[k]))
        item["task_index"] = torch.tensor(int(self.task_index[k]))
        item["task"] = str(self._base.meta.tasks.iloc[int(self.task_index[k])].name)
        return item

    def _observations(self, rows: dict[str, list[int]]) -> dict[str, torch.Tensor]:
        """Every observation key at the given rows, per mirror prefix; each camera decoded in one call."""
        out: dict[str, torch.Tensor] = {}
        for key in self.vector_keys:
            for prefix, r in rows.items():
                out[_name(key, prefix)] = _squeeze_single(self.vectors[key][r], prefix)
        flat = sorted({r for rs in rows.values() for r in rs})
        for key in [*self.image_keys, *self.video_keys]:
            if key in self.frame_cache:
                decoded = self.frame_cache[key].frames(flat)
            elif key in self.video_keys:
                decoded = fit_frames(
                    self._decode(key, flat), self.image_shapes.get(key), self.spec.image_crop
                )
            else:
                decoded = fit_frames(
                    torch.stack(self._base.hf_dataset[flat][key]),
                    self.image_shapes.get(key),
                    self.spec.image_crop,
                )
            frames = dict(zip(flat, decoded, strict=True))
            transform = (
                self._base.image_transforms
            )  # LeRobot's --dataset.image_transforms, on every frame used
            for prefix, r in rows.items():
                stack = torch.stack([frames[i] for i in r])
                out[_name(key, prefix)] = _squeeze_single(
                    stack if transform is None else transform(stack), prefix
                )
        return out

    def _decode(self, key: str, rows: list[int]) -> torch.Tensor:
        """Decode only the needed frames of one video (all rows belong to one episode)."""
        from lerobot.datasets.video_utils import decode_video_frames

        meta = self._base.meta
        ep = int(self.episode_index[rows[0]])
        shift = meta.episodes[ep][f"videos/{key}/from_timestamp"]
        path = self._base.root / meta.get_video_file_path(ep, key)
        stamps = [shift + float(self.timestamps[r]) for r in rows]
        frames = decode_video_frames(
            path, stamps, self._base.tolerance_s, getattr(self._base, "_video_backend", None)
        )
        return frames.reshape(len(rows), *frames.shape[-3:])


class _MirroredStatsMeta:
    """A view of ``LeRobotDatasetMetadata`` whose ``stats`` include the mirrored goal statistics, so that
    every path by which lerobot-train hands stats to the normaliser (fresh run, fine-tuning) covers goals."""

    def __init__(self, meta):
        self._meta = meta

    @property
    def stats(self):
        return mirror_stats(self._meta.stats)

    def __getattr__(self, name):
        if name.startswith("__") or name == "_meta":
            raise AttributeError(name)
        return getattr(self._meta, name)


def _name(key: str, prefix: str) -> str:
    return key if prefix == OBS_PREFIX else mirror_key(key, prefix)


def _squeeze_single(x: torch.Tensor, prefix: str) -> torch.Tensor:
    return x if prefix == TRAJ_PREFIX else x[0]


def _column(table: pa.Table, key: str) -> np.ndarray:
    """A (possibly list-valued) arrow column as a (rows, ...) numpy array, without Python loops."""
    if key not in table.column_names:
        raise KeyError(
            f"Column {key!r} missing from the dataset's parquet data (columns: {table.column_names})."
        )
    array = table.column(key).combine_chunks()
    if (
        pa.types.is_list(array.type)
        or pa.types.is_fixed_size_list(array.type)
        or pa.types.is_large_list(array.type)
    ):
        values = array.flatten().to_numpy(zero_copy_only=False)
        return values.reshape(len(array), -1)
    return array.to_numpy(zero_copy_only=False)
