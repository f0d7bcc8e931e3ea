"""LeRobot glue of the EFM agents: ``forward`` (training loss), ``select_action`` (receding horizon),
``predict_action_chunk``, the EMA weights used at inference, input checks and the model card.

The learning itself lives in :mod:`lerobot_efm.agents`.
"""

# No `from __future__ import annotations`: LeRobot (and its generic policy tests) read the `config` annotation of
# `__init__` as a class.
import contextlib
import copy
import math
from collections import deque

import torch
from huggingface_hub import ModelCard
from huggingface_hub import constants as hf_constants
from lerobot.policies.pretrained import PreTrainedPolicy
from torch import Tensor

from .agents import EFMAgent, make_agent
from .auxiliary import auxiliary_bounds
from .configuration_efm import (
    GOAL_DISTANCE_KEY,
    GOAL_PREFIX,
    OBS_PREFIX,
    EFMACConfig,
    EFMASConfig,
    EFMConfig,
    EFMGCConfig,
    EFMPCConfig,
    EFMPSConfig,
    mirror_key,
)
from .goal_source import (
    advance_deploy_goal,
    advance_deploy_goal_on_key,
    has_goal_source,
    load_goals,
    set_deploy_goal,
    set_image_shapes,
)

PAPER = "Rouxel et al., *Extremum Flow Matching for Offline Goal Conditioned Reinforcement Learning*, arXiv:2505.19717 (2025)"
AGENT_NAMES = {"gc": "FM-GC", "ac": "FM-AC", "pc": "FM-PC", "ps": "FM-PS", "as": "FM-AS"}


class EFMPolicy(PreTrainedPolicy):
    """Base of the five EFM policies. ``self.model`` is trained; ``self.ema_model`` (its low-pass copy)
    computes the RL bootstrap targets, acts at inference and is saved with it."""

    config_class = EFMConfig
    name = "efm"

    def __init__(self, config: EFMConfig, dataset_stats: dict | None = None, **kwargs):
        super().__init__(config)
        config.validate_features()
        config.add_mirror_features()
        self.config = config
        self.model: EFMAgent = make_agent(
            config, _normalized_rest_action(config, dataset_stats), _auxiliary_bounds(config, dataset_stats)
        )
        self.ema_model: EFMAgent = copy.deepcopy(self.model).requires_grad_(False).eval()
        self.register_buffer("ema_updates", torch.zeros((), dtype=torch.long))
        # deployment: the goal named by --policy.goal_* (none: clear any earlier policy's) for the pre-processor
        goals = load_goals(config) if has_goal_source(config) else None
        if goals and len(goals) > 1 and not config.uses_critic and not config.goal_advance_key:
            raise ValueError(
                f"a sequence of {len(goals)} goals advances on the critic's distance; "
                f"{config.type} has no critic: set --policy.goal_advance_key to advance on a key press"
            )
        set_deploy_goal(goals, config.goal_advance_key)
        set_image_shapes(
            {k: tuple(ft.shape) for k, ft in config.observation_features.items() if ".images." in k},
            config.image_crop,
        )
        self.reset()

    # --- LeRobot API -------------------------------------------------------------------------------
    def get_optim_params(self):
        return self.model.parameters()

    def reset(self):
        """Called at every environment reset: forget the chunk being executed."""
        self._action_queue: deque[Tensor] = deque(maxlen=self.config.n_action_steps)
        self.last_prediction: dict[str, Tensor] | None = None

    def train(self, mode: bool = True):
        super().train(mode)
        self.ema_model.eval()  # targets and inference never use dropout
        return self

    def forward(self, batch: dict[str, Tensor]) -> tuple[Tensor, dict]:
        self._check_training_batch(batch)
        loss, info = self.model.compute_loss(batch, self.ema_model, step=int(self.ema_updates.item()))
        return loss, info

    @torch.no_grad()
    def predict_action_chunk(self, batch: dict[str, Tensor]) -> Tensor:
        """The whole predicted chunk tau^a (B, L_a, A), one entry every ``action_traj_stride`` frames.

        What the agent believed (critic distance in steps, planned observations, candidates) is kept in
        ``self.last_prediction`` for visualisation.
        """
        self._check_inference_batch(batch)
        prediction = self.ema_model.predict(batch)
        self.last_prediction = prediction
        return prediction["action"]

    @torch.no_grad()
    def select_action(self, batch: dict[str, Tensor]) -> Tensor:
        """Receding horizon: execute ``n_action_steps`` control steps of the chunk, then replan.

        With a sequence of deploy-time goals, a critic distance under ``goal_advance_distance`` moves on to the
        next goal: one step of this chunk is executed, then the policy replans towards the new goal. A press of
        ``goal_advance_key`` moves on too, dropping the rest of the chunk."""
        if advance_deploy_goal_on_key():
            self._action_queue.clear()
        if not self._action_queue:
            chunk = self.predict_action_chunk(batch)
            steps = _to_control_rate(chunk, self.config.action_traj_stride, self.config.action_mode)
            n = self.config.n_action_steps
            distance = self.last_prediction.get("distance")
            if distance is not None and advance_deploy_goal(
                float(distance.max()), self.config.goal_advance_distance
            ):
                n = 1
            self._action_queue.extend(steps[:, :n].transpose(0, 1))
        return self._action_queue.popleft()

    @torch.no_grad()
    def update(self):
        """After each optimiser step: first-order low-pass of every weight (the reference's EMA), with a
        cutoff period ramping up linearly over the first ``ema_warmup_updates`` updates."""
        self.ema_updates += 1
        cfg = self.config
        ramp = min(1.0, self.ema_updates.item() / max(cfg.ema_warmup_updates, 1))
        omega = 2 * math.pi / max(cfg.ema_cutoff * ramp, 1e-6)
        alpha = max(0.0, (1 - omega / 2) / (1 + omega / 2))
        ema_params = list(self.ema_model.parameters())
        torch._foreach_lerp_(ema_params, list(self.model.parameters()), 1.0 - alpha)
        for ema_buf, buf in zip(self.ema_model.buffers(), self.model.buffers(), strict=True):
            ema_buf.copy_(buf)

    # --- input checks ------------------------------------------------------------------------------
    def _check_training_batch(self, batch: dict[str, Tensor]) -> None:
        cfg = self.config
        goal_keys = [mirror_key(k, GOAL_PREFIX) for k in cfg.observation_features]
        if GOAL_DISTANCE_KEY not in batch or any(k not in batch for k in goal_keys):
            missing = [k for k in [GOAL_DISTANCE_KEY, *goal_keys] if k not in batch]
            raise KeyError(
                f"{self.name} training batch lacks the hindsight keys {missing}. EFM policies train on batches "
                "from lerobot_efm.hindsight.HindsightGoalDataset; under lerobot-train the plugin wraps the dataset "
                "by patching lerobot.scripts.lerobot_train.make_train_eval_datasets (lerobot_efm/train_hook.py). "
                "If you see this under lerobot-train, that hook no longer applies to your lerobot version."
            )
        for prefix in cfg.mirror_prefixes:
            for key in cfg.observation_features:
                _require(batch, mirror_key(key, prefix), "training batch")
        if cfg.auxiliary_state_key:
            for key in (cfg.auxiliary_state_key, mirror_key(cfg.auxiliary_state_key, GOAL_PREFIX)):
                _require(batch, key, "training batch (auxiliary_state_key)")
        action = _require(batch, "action", "training batch")
        expected = (cfg.action_traj_len, cfg.output_features["action"].shape[0])
        if action.dim() != 3 or tuple(action.shape[1:]) != expected:
            raise ValueError(
                f"Batch key 'action' has shape {tuple(action.shape)}; expected (B, {expected[0]}, {expected[1]}) (L_a, action dim)."
            )
        self._check_observation_shapes(batch, OBS_PREFIX)
        self._check_observation_shapes(batch, GOAL_PREFIX)
        _check_finite(batch)

    def _check_inference_batch(self, batch: dict[str, Tensor]) -> None:
        for key in self.config.observation_features:
            _require(batch, key, "observation")
            goal = mirror_key(key, GOAL_PREFIX)
            if goal not in batch:
                raise KeyError(
                    f"{self.name} needs the goal observation {goal!r} (mirror of {key!r}) at inference; the batch has "
                    f"{sorted(k for k in batch if k.startswith('observation.'))}. Give the goal as observation.goal.* keys "
                    "(an EFM environment provides them in its observations)."
                )
        self._check_observation_shapes(batch, OBS_PREFIX)
        self._check_observation_shapes(batch, GOAL_PREFIX)
        _check_finite(batch)

    def _check_observation_shapes(self, batch: dict[str, Tensor], prefix: str) -> None:
        for key, ft in self.config.observation_features.items():
            name = key if prefix == OBS_PREFIX else mirror_key(key, prefix)
            shape = tuple(batch[name].shape[1:])
            if shape != tuple(ft.shape):
                raise ValueError(
                    f"Feature {name!r} has shape {shape} but this policy was built for {tuple(ft.shape)} "
                    f"(config.input_features[{key!r}]): the data does not match the checkpoint."
                )

    # --- Hub ---------------------------------------------------------------------------------------
    def generate_model_card(
        self, dataset_repo_id, model_type, license, tags, cfg=None, dataset_meta=None
    ) -> ModelCard:
        """LeRobot's model card (its template: details, inputs, dataset, configuration, how to run, evaluation)
        with an Extremum Flow Matching section after its summary: the agent, the goal keys, the paper."""
        tags = sorted(set(tags or []) | {"extremum-flow-matching", "goal-conditioned"})
        with _hub_validation_skipped_offline():
            card = super().generate_model_card(dataset_repo_id, model_type, license, tags, cfg, dataset_meta)
        first_section = card.text.find("\n## ")
        at = first_section if first_section >= 0 else len(card.text)
        card.text = card.text[:at] + "\n" + self._efm_card_section(dataset_repo_id, cfg) + card.text[at:]
        return card

    def _efm_card_section(self, dataset_repo_id: str, cfg) -> str:
        c = self.config
        agent = AGENT_NAMES[c.agent] + ("-use-RL" if c.use_rl else ("-no-RL" if c.uses_critic else ""))
        steps = f"{cfg.steps} steps, batch {cfg.batch_size}" if cfg is not None else "unknown budget"
        return f"""## Extremum Flow Matching: {agent}

A goal-conditioned policy of the **{agent}** agent from {PAPER}, trained with
[lerobot_efm](https://pypi.org/project/lerobot_policy_efm/) on `{dataset_repo_id}` ({steps}) with hindsight goals.
It acts from the current observation and a goal observation, given as `observation.goal.*` keys that mirror every
input (`{", ".join(sorted(c.observation_features))}` -> `observation.goal.*`). On a robot, whose observations
carry no goal: `lerobot-rollout --policy.path=<this repo> --policy.goal_path=goal.safetensors` (a goal file
written by `lerobot-efm-goal`) after `pip install lerobot_policy_efm`.

| setting | value |
|---|---|
| L_o / S_o | {c.obs_traj_len} / {c.obs_traj_stride} |
| L_a / S_a | {c.action_traj_len} / {c.action_traj_stride} |
| L_g | {c.max_goal_distance} |
| Euler steps | {c.num_inference_steps} |

```bibtex
@inproceedings{{rouxel2025extremum,
  title={{Extremum Flow Matching for Offline Goal Conditioned Reinforcement Learning}},
  author={{Rouxel, Quentin and Donoso, Clemente and Chen, Fei and Ivaldi, Serena and Mouret, Jean-Baptiste}},
  booktitle={{IEEE-RAS International Conference on Humanoid Robots}},
  year={{2025}}
}}
```
"""


@contextlib.contextmanager
def _hub_validation_skipped_offline():
    """LeRobot's card generation validates the card against the Hub, which an offline run cannot reach."""
    if not hf_constants.HF_HUB_OFFLINE:
        yield
        return
    validate = ModelCard.validate
    ModelCard.validate = lambda self, repo_type=None: None
    try:
        yield
    finally:
        ModelCard.validate = validate


class EFMGCPolicy(EFMPolicy):
    config_class = EFMGCConfig
    name = "efm_gc"


class EFMACPolicy(EFMPolicy):
    config_class = EFMACConfig
    name = "efm_ac"


class EFMPCPolicy(EFMPolicy):
    config_class = EFMPCConfig
    name = "efm_pc"


class EFMPSPolicy(EFMPolicy):
    config_class = EFMPSConfig
    name = "efm_ps"


class EFMASPolicy(EFMPolicy):
    config_class = EFMASConfig
    name = "efm_as"


# --------------------------------------------------------------------------------------------------
# helpers
# --------------------------------------------------------------------------------------------------


def _require(batch: dict[str, Tensor], key: str, what: str) -> Tensor:
    if key not in batch:
        raise KeyError(f"Missing key {key!r} in the {what}; present keys: {sorted(batch)}.")
    return batch[key]


def _check_finite(batch: dict[str, Tensor]) -> None:
    for key, value in batch.items():
        if isinstance(value, Tensor) and value.is_floating_point() and not torch.isfinite(value).all():
            bad = (~torch.isfinite(value)).sum().item()
            raise ValueError(
                f"Batch key {key!r} contains {bad} NaN/inf value(s); EFM policies need finite inputs."
            )


def _to_control_rate(chunk: Tensor, stride: int, action_mode: str) -> Tensor:
    """(B, L_a, A) waypoints every ``stride`` frames -> (B, (L_a-1)*stride+1, A) per-frame commands:
    linear interpolation for absolute commands, zero-order hold for velocities."""
    if stride == 1:
        return chunk
    if action_mode == "velocity":
        return chunk.repeat_interleave(stride, dim=1)
    frac = torch.arange(stride, device=chunk.device, dtype=chunk.dtype) / stride  # (S,)
    start, end = chunk[:, :-1, None], chunk[:, 1:, None]  # (B, L-1, 1, A)
    between = start + (end - start) * frac[None, None, :, None]
    return torch.cat([between.flatten(1, 2), chunk[:, -1:]], dim=1)


def _auxiliary_bounds(config: EFMConfig, dataset_stats: dict | None) -> tuple[Tensor, Tensor] | None:
    """min / max of the auxiliary target in the training recording; sets ``auxiliary_state_dim`` (saved with the
    config) so that a checkpoint loads without the statistics."""
    key = config.auxiliary_state_key
    if key is None:
        return None
    if dataset_stats is None:
        if config.auxiliary_state_dim < 1:
            raise ValueError(
                f"auxiliary_state_key={key!r} needs the dataset statistics (its size and range) or a checkpoint's "
                "auxiliary_state_dim; neither was given."
            )
        return None  # a checkpoint: its saved buffers hold the range
    low, high = auxiliary_bounds(key, dataset_stats)
    config.auxiliary_state_dim = low.numel()
    return low, high


def _normalized_rest_action(config: EFMConfig, dataset_stats: dict | None) -> Tensor | None:
    """The raw zero command in normalised units (the 'stay' action of velocity-controlled robots)."""
    if config.action_mode != "velocity" or not dataset_stats or "action" not in dataset_stats:
        return None
    from lerobot.processor import NormalizerProcessorStep
    from lerobot.processor.converters import create_transition

    step = NormalizerProcessorStep(
        features={"action": config.output_features["action"]},
        norm_map=config.normalization_mapping,
        stats={"action": dataset_stats["action"]},
    )
    zero = torch.zeros(config.output_features["action"].shape[0])
    return step(create_transition(action=zero))["action"].float()
