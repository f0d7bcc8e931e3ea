"""An auxiliary training loss: predict a privileged vector (e.g. a simulator's object state) from the latent.

Why: an image policy must read from pixels what a state policy is handed (where the door, tray and pot are),
but its encoder only learns from the flow-matching losses of the actor and critic, which a few hours of play
can fit by keying on the robot's own pose. Regressing a recorded object state from the latent of the same
frame (observation and goal alike) tells the encoder what to look for. The target is used during training only:
the policy still acts from camera and proprioception, and a recording without that key (a real robot's) trains
as before with the option off. ``--policy.auxiliary_state_key=observation.environment_state`` turns it on.
Measured on the Talos kitchen (64x64 image FM-AC, 48 episodes of play): 34 % over the 13 tasks against 14 %
without, the head reading door and tray on unseen frames within 2.6 deg / 0.2 cm (``benchmarks/results/``).
"""

from __future__ import annotations

import torch
import torch.nn.functional as F
from torch import Tensor, nn

from .processor_efm import CONSTANT_RANGE  # a constant dimension gets range 2 (centred), like the normaliser

HIDDEN_DIM = 256


class AuxiliaryStateHead(nn.Module):
    """latent -> the auxiliary vector scaled to [-1, 1] by the recording's min/max (buffers, saved)."""

    def __init__(
        self, latent_dim: int, state_dim: int, low: Tensor | None = None, high: Tensor | None = None
    ):
        super().__init__()
        self.net = nn.Sequential(
            nn.Linear(latent_dim, HIDDEN_DIM), nn.SiLU(), nn.Linear(HIDDEN_DIM, state_dim)
        )
        low = torch.zeros(state_dim) if low is None else torch.as_tensor(low, dtype=torch.float32).reshape(-1)
        high = (
            torch.ones(state_dim) if high is None else torch.as_tensor(high, dtype=torch.float32).reshape(-1)
        )
        span = high - low
        flat = span < CONSTANT_RANGE
        self.register_buffer("centre", (low + high) / 2)
        self.register_buffer("half_range", torch.where(flat, torch.ones_like(span), span / 2))

    def scale(self, state: Tensor) -> Tensor:
        return (state - self.centre) / self.half_range

    def loss(self, latents: Tensor, state: Tensor) -> Tensor:
        """Mean squared error of the prediction, in [-1, 1] units per dimension."""
        return F.mse_loss(self.net(latents), self.scale(state.float()))

    @torch.no_grad()
    def predict(self, latents: Tensor) -> Tensor:
        """The auxiliary vector in the recording's units (for inspection; acting never uses it)."""
        return self.net(latents) * self.half_range + self.centre


def auxiliary_bounds(key: str, dataset_stats: dict | None) -> tuple[Tensor, Tensor]:
    """min / max of ``key`` in the training recording's statistics, with an error naming the key if absent."""
    entry = (dataset_stats or {}).get(key)
    if entry is None or "min" not in entry or "max" not in entry:
        have = sorted(k for k in (dataset_stats or {}) if k.startswith("observation."))
        raise KeyError(
            f"auxiliary_state_key={key!r}: the dataset statistics have no min/max for it (they have {have}); "
            "name an observation.* vector of the training recording."
        )
    return (torch.as_tensor(entry[k], dtype=torch.float32).reshape(-1) for k in ("min", "max"))
