"""Model-space tensors back to what the env saw: LeRobot's public ``UnnormalizerProcessorStep`` built from the
policy preprocessor's normaliser, planned latents back to observations, images to (H, W, 3) uint8."""

from __future__ import annotations

import numpy as np
import torch


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


def normalize(preprocessor, key: str, x: torch.Tensor) -> torch.Tensor:
    """The policy preprocessor's normalisation of observation ``key`` alone (identity when it has none)."""
    from lerobot.processor import TransitionKey
    from lerobot.processor.converters import create_transition

    step = _normalizer_step(preprocessor)
    if step is None:
        return x
    return step(create_transition(observation={key: x}))[TransitionKey.OBSERVATION][key]


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
