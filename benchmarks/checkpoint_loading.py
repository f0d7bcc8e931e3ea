"""Load a lerobot-train checkpoint of an efm_* policy for an in-process benchmark (shared by the scripts here)."""

from __future__ import annotations

from pathlib import Path


def load_policy(checkpoint: Path, device: str = "cpu", overrides: dict | None = None):
    """The policy in eval mode and its saved pre-/post-processors on ``device``; ``overrides`` set config fields
    (values cast to the field's type) before the weights load, e.g. ``{"critic_inference_eps": "0.5"}``."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies import make_pre_post_processors
    from lerobot.policies.factory import get_policy_class

    import lerobot_efm  # noqa: F401  (registers the policies)

    cfg = PreTrainedConfig.from_pretrained(checkpoint)
    cfg.device = device
    for name, value in (overrides or {}).items():
        setattr(cfg, name, type(getattr(cfg, name))(value))
    policy = get_policy_class(cfg.type).from_pretrained(checkpoint, config=cfg).eval()
    pre, post = make_pre_post_processors(
        policy_cfg=cfg,
        pretrained_path=str(checkpoint),
        preprocessor_overrides={"device_processor": {"device": device}},
    )
    return policy, pre, post
