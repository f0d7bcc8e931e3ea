"""Random-shift augmentation of camera images during training (DrQ, Kostrikov et al. 2020).

Why: a goal-conditioned image policy trained on half an hour of play from one fixed camera can key its
actions on exact pixel positions of the few trajectories it saw; shifting every training image by a few
pixels (edges replicated) makes it match *what* is in the image rather than where each pixel sits, the way
LeRobot's diffusion policy crops its images at random. Observation and goal images get independent shifts;
inference sees the image unshifted. Measured on the Talos kitchen (4 px at 64x64): no gain there
(``benchmarks/results/talos_kitchen.md``), so it is off by default.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor


def random_shift(images: Tensor, pad: int, generator: torch.Generator | None = None) -> Tensor:
    """Shift each image of ``images`` (..., C, H, W) by its own integer offset in [-pad, pad] along both axes,
    filling the uncovered border with the edge pixels. ``pad=0`` returns the input unchanged."""
    if pad <= 0:
        return images
    lead, (c, h, w) = images.shape[:-3], images.shape[-3:]
    flat = images.reshape(-1, c, h, w)
    n, device = flat.shape[0], images.device
    padded = F.pad(flat.float(), (pad, pad, pad, pad), mode="replicate").to(images.dtype)
    # One gather over the flattened padded pixels (1.3 ms for 32 64x64 images on one core, 3x faster than
    # advanced indexing of an (n, H, W) grid).
    offsets = torch.randint(0, 2 * pad + 1, (n, 2), generator=generator, device=device)
    rows = offsets[:, :1] + torch.arange(h, device=device)  # (n, H)
    cols = offsets[:, 1:] + torch.arange(w, device=device)  # (n, W)
    index = (rows[:, :, None] * (w + 2 * pad) + cols[:, None, :]).reshape(n, 1, h * w).expand(n, c, h * w)
    return padded.flatten(2).gather(2, index).reshape(*lead, c, h, w)
