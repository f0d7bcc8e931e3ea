"""Networks of the EFM agents: a FiLM-conditioned 1-D UNet (trajectory actor), an ensemble MLP flow
(critics, planner, world model), the IMPALA-small image encoder and the observation encoder.

Both flow networks split their conditioning in two steps, ``condition(c)`` then ``velocity(x, t, cache)``:
the conditioning does not change across Euler steps, so it is projected once per integration and only
the (cheap) state and time terms are recomputed at each step.
"""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F
from torch import Tensor, nn

# --------------------------------------------------------------------------------------------------
# Time embedding
# --------------------------------------------------------------------------------------------------


class SinusoidalTimeEmbedding(nn.Module):
    """Sinusoids with periods spread geometrically in [min_period, max_period], then a small MLP.

    ``t`` may be a 0-d tensor (same time for the whole batch, as during Euler integration) or (B,).
    """

    def __init__(
        self, dim: int = 32, hidden_dim: int = 128, min_period: float = 0.002, max_period: float = 10.0
    ):
        super().__init__()
        if dim % 2:
            raise ValueError(f"time embedding dim must be even, got {dim}")
        periods = torch.exp(torch.linspace(math.log(min_period), math.log(max_period), dim // 2))
        self.register_buffer("frequencies", 2 * math.pi / periods, persistent=False)
        self.mlp = nn.Sequential(nn.Linear(dim, hidden_dim), nn.SiLU(), nn.Linear(hidden_dim, dim), nn.SiLU())

    def forward(self, t: Tensor) -> Tensor:
        phase = t.unsqueeze(-1) * self.frequencies
        return self.mlp(torch.cat([phase.sin(), phase.cos()], dim=-1))


# --------------------------------------------------------------------------------------------------
# 1-D conditional UNet (trajectory flows)
# --------------------------------------------------------------------------------------------------


class TemporalConv1d(nn.Conv1d):
    """``nn.Conv1d`` (same weights and state dict) that runs as one GEMM over the stacked shifted windows
    where PyTorch's CPU convolution is slow on the UNet's few time steps: every CPU training call (forward
    plus backward 1.5x faster over the Talos UNet's layers, a state FM-AC update 1.2x:
    ``benchmarks/bench_temporal_conv.py``) and small inference calls. CUDA training and large inference
    batches keep the regular convolution."""

    SMALL = 64  # inference: batch x length up to which the GEMM path is used
    GEMM_FOR_CPU_TRAINING = True  # class switch, so a benchmark can time both paths

    def uses_gemm(self, x: Tensor) -> bool:
        if self.groups != 1 or self.dilation[0] != 1 or self.padding_mode != "zeros":
            return False
        if torch.is_grad_enabled():
            return self.GEMM_FOR_CPU_TRAINING and x.device.type == "cpu"
        return x.shape[0] * x.shape[-1] <= self.SMALL

    def forward(self, x: Tensor) -> Tensor:
        if not self.uses_gemm(x):
            return super().forward(x)
        (k,), (stride,), (pad,) = self.kernel_size, self.stride, self.padding
        length = (x.shape[-1] + 2 * pad - k) // stride + 1
        xp = F.pad(x, (pad, pad)).transpose(1, 2)  # (B, L + 2p, C)
        # (B, L', C, k) flattened channel-major, matching a *view* of the (out, C, k) weight: no weight copy.
        windows = torch.stack([xp[:, j : j + stride * (length - 1) + 1 : stride] for j in range(k)], dim=-1)
        return F.linear(windows.flatten(2), self.weight.view(self.out_channels, -1), self.bias).transpose(
            1, 2
        )


class FiLMResidualBlock1d(nn.Module):
    """Conv-GN-SiLU, FiLM(time, condition), Conv-GN-SiLU, plus a 1x1 skip.

    The FiLM projection is split into a condition part (cached per integration) and a time part.
    """

    def __init__(
        self, in_ch: int, out_ch: int, cond_dim: int, time_dim: int, kernel_size: int, n_groups: int
    ):
        super().__init__()
        pad = kernel_size // 2
        self.conv1 = nn.Sequential(
            TemporalConv1d(in_ch, out_ch, kernel_size, padding=pad), nn.GroupNorm(n_groups, out_ch), nn.SiLU()
        )
        self.conv2 = nn.Sequential(
            TemporalConv1d(out_ch, out_ch, kernel_size, padding=pad),
            nn.GroupNorm(n_groups, out_ch),
            nn.SiLU(),
        )
        self.film_cond = nn.Linear(cond_dim, 2 * out_ch)
        self.film_time = nn.Linear(time_dim, 2 * out_ch, bias=False)
        self.skip = TemporalConv1d(in_ch, out_ch, 1) if in_ch != out_ch else nn.Identity()

    def forward(self, x: Tensor, film_cond: Tensor, time_emb: Tensor) -> Tensor:
        film = (film_cond + self.film_time(time_emb)).unsqueeze(-1)
        scale, bias = film.chunk(2, dim=1)
        h = self.conv1(x) * (1 + scale) + bias
        return self.conv2(h) + self.skip(x)


class ConditionalUnet1d(nn.Module):
    """Velocity field over a trajectory (B, L, C) conditioned on a vector (B, cond_dim).

    Levels with two residual blocks each and stride-2 down-sampling, two middle blocks, a mirrored up
    path (nearest up-sampling) with skip connections: the trajectory length must be divisible by
    2**len(down_dims).
    """

    def __init__(
        self,
        channels: int,
        cond_dim: int,
        down_dims: tuple[int, ...] = (64, 128, 256),
        time_dim: int = 32,
        kernel_size: int = 3,
        n_groups: int = 8,
    ):
        super().__init__()
        self.time_embedding = SinusoidalTimeEmbedding(time_dim)

        def block(i: int, o: int) -> FiLMResidualBlock1d:
            return FiLMResidualBlock1d(i, o, cond_dim, time_dim, kernel_size, n_groups)

        self.down = nn.ModuleList()
        in_ch = channels
        for ch in down_dims:
            self.down.append(
                nn.ModuleList(
                    [block(in_ch, ch), block(ch, ch), TemporalConv1d(ch, ch, 3, stride=2, padding=1)]
                )
            )
            in_ch = ch
        self.middle = nn.ModuleList([block(in_ch, in_ch), block(in_ch, in_ch)])
        self.up = nn.ModuleList()
        for ch in reversed(down_dims):
            self.up.append(nn.ModuleList([block(in_ch + ch, ch), block(ch, ch)]))
            in_ch = ch
        self.final = TemporalConv1d(in_ch, channels, 1)
        self.blocks = [m for m in self.modules() if isinstance(m, FiLMResidualBlock1d)]
        self.length_multiple = 2 ** len(down_dims)

    def condition(self, cond: Tensor) -> list[Tensor]:
        """Project the conditioning for every block once; reused at every Euler step."""
        return [blk.film_cond(cond) for blk in self.blocks]

    def velocity(self, x: Tensor, t: Tensor, cache: list[Tensor]) -> Tensor:
        if x.shape[1] % self.length_multiple:
            raise ValueError(
                f"UNet trajectory length {x.shape[1]} is not divisible by {self.length_multiple}."
            )
        time_emb = self.time_embedding(t)
        films = iter(cache)
        h = x.transpose(1, 2)
        skips = []
        for blk1, blk2, downsample in self.down:
            h = blk2(blk1(h, next(films), time_emb), next(films), time_emb)
            skips.append(h)
            h = downsample(h)
        for blk in self.middle:
            h = blk(h, next(films), time_emb)
        for blk1, blk2 in self.up:
            # Parameter-free nearest up-sampling (each step repeated twice, in time order: the reference's
            # reshape interleaved the wrong way), then the skip connection of the same resolution.
            h = torch.cat([h.repeat_interleave(2, dim=-1), skips.pop()], dim=1)
            h = blk2(blk1(h, next(films), time_emb), next(films), time_emb)
        return self.final(h).transpose(1, 2)

    def forward(self, x: Tensor, t: Tensor, cond: Tensor) -> Tensor:
        return self.velocity(x, t, self.condition(cond))


# --------------------------------------------------------------------------------------------------
# Ensemble MLP flow (critics, planner, world model)
# --------------------------------------------------------------------------------------------------


class EnsembleMLPFlow(nn.Module):
    """``num_members`` independent MLP velocity fields evaluated as one batched call.

    Input of member e is [x (flattened), t (raw scalar, no embedding), c]; hidden layers are
    Linear-SiLU-LayerNorm. The first layer's weight is split by input part so that ``c @ W_c + b`` is
    computed once per integration. Shapes: x (E, B, x_dim), c (B, cond_dim) shared by all members.
    """

    def __init__(self, num_members: int, x_dim: int, cond_dim: int, hidden_dims: tuple[int, ...]):
        super().__init__()
        if not hidden_dims:
            raise ValueError("EnsembleMLPFlow needs at least one hidden layer.")
        self.num_members, self.x_dim = num_members, x_dim
        dims = [x_dim + 1 + cond_dim, *hidden_dims, x_dim]
        self.weights = nn.ParameterList()
        self.biases = nn.ParameterList()
        for fan_in, fan_out in zip(dims[:-1], dims[1:], strict=True):
            bound = 1.0 / math.sqrt(fan_in)
            self.weights.append(
                nn.Parameter(torch.empty(num_members, fan_in, fan_out).uniform_(-bound, bound))
            )
            self.biases.append(nn.Parameter(torch.empty(num_members, 1, fan_out).uniform_(-bound, bound)))
        self.norm_weights = nn.ParameterList(
            [nn.Parameter(torch.ones(num_members, 1, h)) for h in hidden_dims]
        )
        self.norm_biases = nn.ParameterList(
            [nn.Parameter(torch.zeros(num_members, 1, h)) for h in hidden_dims]
        )

    def condition(self, cond: Tensor) -> Tensor:
        """(B, cond_dim) -> (E, B, H1): the conditioning part of the first layer."""
        w_c = self.weights[0][:, self.x_dim + 1 :]
        return torch.matmul(cond.unsqueeze(0), w_c) + self.biases[0]

    def velocity(self, x: Tensor, t: Tensor, cache: Tensor) -> Tensor:
        """x (E, B, x_dim); t 0-d or broadcastable to (E, B, 1); returns (E, B, x_dim)."""
        w0 = self.weights[0]
        t = t.reshape(t.shape + (1,) * (3 - t.dim())) if t.dim() else t
        h = torch.baddbmm(cache, x, w0[:, : self.x_dim]) + t * w0[:, self.x_dim : self.x_dim + 1]
        for i in range(1, len(self.weights)):
            h = F.layer_norm(F.silu(h), h.shape[-1:]) * self.norm_weights[i - 1] + self.norm_biases[i - 1]
            h = torch.baddbmm(self.biases[i], h, self.weights[i])
        return h

    def forward(self, x: Tensor, t: Tensor, cond: Tensor) -> Tensor:
        return self.velocity(x, t, self.condition(cond))


# --------------------------------------------------------------------------------------------------
# Encoders
# --------------------------------------------------------------------------------------------------


class ImpalaResidualBlock(nn.Module):
    """ReLU-Conv-ReLU-Conv plus identity, with two *distinct* convolutions (the reference reuses one)."""

    def __init__(self, channels: int):
        super().__init__()
        self.conv1 = nn.Conv2d(channels, channels, 3, padding=1)
        self.conv2 = nn.Conv2d(channels, channels, 3, padding=1)

    def forward(self, x: Tensor) -> Tensor:
        return x + self.conv2(F.relu(self.conv1(F.relu(x))))


class ImpalaEncoder(nn.Module):
    """IMPALA-small: 3 stacks (conv, max-pool /2, residual block, dropout), then an MLP head.

    Takes float images in [0, 1] (LeRobot's convention), shape (..., 3, H, W).
    """

    def __init__(
        self,
        image_shape: tuple[int, int, int],
        out_dim: int = 64,
        channels: tuple[int, ...] = (16, 32, 32),
        hidden_dim: int = 512,
        dropout: float = 0.2,
    ):
        super().__init__()
        layers: list[nn.Module] = []
        in_ch = image_shape[0]
        for ch in channels:
            layers += [
                nn.Conv2d(in_ch, ch, 3, padding=1),
                nn.MaxPool2d(3, stride=2, padding=1),
                ImpalaResidualBlock(ch),
                nn.Dropout(dropout),
            ]
            in_ch = ch
        self.stacks = nn.Sequential(*layers)
        with torch.no_grad():
            flat = self.stacks(torch.zeros(1, *image_shape)).numel()
        self.head = nn.Sequential(
            nn.Flatten(),
            nn.SiLU(),
            nn.LayerNorm(flat),
            nn.Linear(flat, hidden_dim),
            nn.SiLU(),
            nn.LayerNorm(hidden_dim),
            nn.Linear(hidden_dim, out_dim),
        )

    def forward(self, images: Tensor) -> Tensor:
        lead = images.shape[:-3]
        # channels-last: the CPU kernels of max-pool and convolution run 1.6-2.4x faster on it (64x64 frames,
        # forward + backward); same values, so checkpoints do not depend on it.
        x = (images.reshape(-1, *images.shape[-3:]) - 0.5).contiguous(memory_format=torch.channels_last)
        return self.head(self.stacks(x)).reshape(*lead, -1)


class FourierFeatures(nn.Module):
    """x -> [x, sin(2^k pi x), cos(2^k pi x)] for k < num_frequencies, per coordinate (no parameters).

    Why: an MLP fed raw low-dimensional positions learns smooth functions first (spectral bias), so a critic
    reads a maze as open space long before it learns that a goal behind a wall is far; periodic features at the
    scale of the walls let it carve them in far fewer updates. Inputs are normalised to about [-1, 1]."""

    def __init__(self, num_frequencies: int):
        super().__init__()
        self.register_buffer("scales", math.pi * 2.0 ** torch.arange(num_frequencies), persistent=False)

    def forward(self, x: Tensor) -> Tensor:
        angles = (x.unsqueeze(-1) * self.scales).flatten(-2)
        return torch.cat([x, angles.sin(), angles.cos()], dim=-1)


class ObservationEncoder(nn.Module):
    """Maps every observation key (cameras, ``observation.state``, ``observation.environment_state``,
    any other vector) to one latent vector: IMPALA per camera, identity or an MLP per vector key.

    ``forward(obs, prefix)`` reads ``prefix + key`` so the same weights encode observations
    (``observation.``), goals (``observation.goal.``) and trajectory frames (``observation.traj.``).
    """

    def __init__(
        self,
        image_shapes: dict[str, tuple[int, int, int]],
        vector_dims: dict[str, int],
        image_latent_dim: int,
        image_channels: tuple[int, ...],
        image_hidden_dim: int,
        image_dropout: float,
        state_encoder: str,
        state_latent_dim: int,
        state_fourier_frequencies: int = 6,
    ):
        super().__init__()
        # Keys are the feature names without the "observation." prefix, e.g. "images.front", "state".
        self.image_keys, self.vector_keys = sorted(image_shapes), sorted(vector_dims)
        self.images = nn.ModuleDict(
            {
                _module_name(k): ImpalaEncoder(
                    image_shapes[k], image_latent_dim, image_channels, image_hidden_dim, image_dropout
                )
                for k in self.image_keys
            }
        )
        if state_encoder == "identity":
            self.vectors = nn.ModuleDict({_module_name(k): nn.Identity() for k in self.vector_keys})
            vector_out = sum(vector_dims.values())
        elif state_encoder == "mlp":
            self.vectors = nn.ModuleDict(
                {
                    _module_name(k): nn.Sequential(
                        nn.Linear(vector_dims[k], state_latent_dim), nn.SiLU(), nn.LayerNorm(state_latent_dim)
                    )
                    for k in self.vector_keys
                }
            )
            vector_out = state_latent_dim * len(self.vector_keys)
        elif state_encoder == "fourier":
            self.vectors = nn.ModuleDict(
                {_module_name(k): FourierFeatures(state_fourier_frequencies) for k in self.vector_keys}
            )
            vector_out = sum(vector_dims.values()) * (1 + 2 * state_fourier_frequencies)
        else:
            raise ValueError(f"state_encoder must be 'identity', 'mlp' or 'fourier', got {state_encoder!r}.")
        self.latent_dim = image_latent_dim * len(self.image_keys) + vector_out

    def forward(self, batch: dict[str, Tensor], prefix: str = "observation.") -> Tensor:
        parts = [self.images[_module_name(k)](batch[prefix + k]) for k in self.image_keys]
        parts += [self.vectors[_module_name(k)](batch[prefix + k]) for k in self.vector_keys]
        return torch.cat(parts, dim=-1)


def _module_name(key: str) -> str:
    return key.replace(".", "__")
