"""Camera frames at the policy's resolution: one resize rule for training and deployment, and a RAM cache of
decoded frames for trainings where decoding, not the network, would bound the step rate.

Why a cache: a hindsight sample needs two or three frames of one camera that sit far apart in the video
(o_k, g = o_{k+d}, g'), so every sample pays for a seek and a decode from the preceding keyframe (~2.4 ms a
frame on one core for the 128x128 Talos recording, against 0.35 ms a frame decoded in sequence). With small
images on a CPU that is most of a training step. ``--policy.cache_frames=true`` decodes each camera once,
in order, resizes it to the policy's input size and keeps it as uint8: C x H x W bytes a frame (48,000 frames
at 64 x 64: 590 MB; at 128 x 128: 2.4 GB).

A policy may also take a fixed region of the camera (``--policy.image_crop``: top, left, height, width as
fractions of the frame), cropped before the resize: with a wide camera the objects of the task are then drawn
with more of the policy's pixels. The fractions make one crop fit every resolution a camera is read at.
"""

from __future__ import annotations

import logging

import numpy as np
import torch

log = logging.getLogger(__name__)

DECODE_CHUNK = 256  # frames per decoder call while filling the cache (bounds the float32 staging memory)


Crop = tuple[float, float, float, float]  # top, left, height, width: fractions of the frame


def crop_frames(frames: torch.Tensor, crop: Crop | None) -> torch.Tensor:
    """The ``crop`` region of (..., H, W) frames (None: the whole frame); pixel bounds rounded to the nearest."""
    if crop is None:
        return frames
    h, w = frames.shape[-2:]
    top, left, height, width = crop
    rows = slice(round(top * h), round((top + height) * h))
    cols = slice(round(left * w), round((left + width) * w))
    return frames[..., rows, cols]


def resize_frame(img: torch.Tensor, shape: tuple[int, ...], crop: Crop | None = None) -> torch.Tensor:
    """(C, H, W) image -> its ``crop`` region -> ``shape`` (C, H, W) with OpenCV: area interpolation when
    shrinking (a box average for integer factors), bilinear when growing. Float in, float out; uint8 in, uint8
    out."""
    import cv2

    img = crop_frames(img, crop)
    c, h, w = shape
    hwc = img.permute(1, 2, 0).numpy()
    shrink = h * w < hwc.shape[0] * hwc.shape[1]
    out = cv2.resize(
        hwc if hwc.dtype == np.uint8 else hwc.astype(np.float32),
        (w, h),
        interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR,
    )
    return torch.from_numpy(out.reshape(h, w, c)).permute(2, 0, 1).contiguous()


def fit_frames(frames: torch.Tensor, shape: tuple[int, ...] | None, crop: Crop | None = None) -> torch.Tensor:
    """(N, C, H, W) frames cropped to ``crop`` and resized to ``shape`` when their size differs (None: left as
    they are)."""
    frames = crop_frames(frames, crop)
    if shape is None or tuple(frames.shape[-2:]) == tuple(shape[-2:]):
        return frames if crop is None else frames.contiguous()
    return torch.stack([resize_frame(f, shape) for f in frames])


class DecodedFrames:
    """Every frame of one camera of a LeRobot dataset, decoded once in order, resized to ``shape`` and kept as
    uint8 (rows of the dataset's table order), after the ``crop``. ``frames(rows)`` returns float (N, C, H, W)
    in [0, 1], as LeRobot's decoder does."""

    def __init__(
        self,
        base,
        key: str,
        episode_index: np.ndarray,
        timestamps: np.ndarray,
        shape: tuple[int, ...] | None,
        crop: Crop | None = None,
    ):
        from lerobot.datasets.video_utils import decode_video_frames

        meta = base.meta
        n = len(episode_index)
        self.array: np.ndarray | None = None  # (N, C, H, W) uint8, allocated at the first decoded chunk
        starts = np.flatnonzero(np.r_[True, episode_index[1:] != episode_index[:-1]])
        ends = np.r_[starts[1:], n]
        backend = getattr(base, "_video_backend", None)
        for start, end in zip(starts, ends, strict=True):
            ep = int(episode_index[start])
            shift = meta.episodes[ep][f"videos/{key}/from_timestamp"]
            path = base.root / meta.get_video_file_path(ep, key)
            for lo in range(int(start), int(end), DECODE_CHUNK):
                hi = min(lo + DECODE_CHUNK, int(end))
                stamps = [shift + float(t) for t in timestamps[lo:hi]]
                decoded = decode_video_frames(path, stamps, base.tolerance_s, backend, return_uint8=True)
                decoded = fit_frames(decoded.reshape(hi - lo, *decoded.shape[-3:]), shape, crop)
                if self.array is None:
                    self.array = np.empty((n, *decoded.shape[1:]), np.uint8)
                    log.info(
                        "cache_frames: decoding the %d frames of %s once, kept in RAM as %s uint8 (%.0f MB)",
                        n,
                        key,
                        tuple(decoded.shape[1:]),
                        self.array.nbytes / 1e6,
                    )
                self.array[lo:hi] = decoded.numpy()

    def frames(self, rows: list[int]) -> torch.Tensor:
        return torch.from_numpy(self.array[rows]).float().div_(255.0)
