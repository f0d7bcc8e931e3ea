"""Configurations of the five Extremum Flow Matching agents (paper Table I) as LeRobot policy types.

``efm_gc``, ``efm_ac``, ``efm_pc``, ``efm_ps`` and ``efm_as`` share every field of :class:`EFMConfig`;
they differ only in which components they train (Critic, Actor, Planner, World). Defaults follow the
authors' reference implementation (planar-push trajectory settings, its network sizes and optimiser).
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from typing import ClassVar

from lerobot.configs import NormalizationMode, PreTrainedConfig
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.optim import AdamWConfig
from lerobot.optim.optimizers import OptimizerConfig
from lerobot.optim.schedulers import CosineDecayWithWarmupSchedulerConfig
from lerobot.utils.constants import OBS_PREFIX

from .flow import SOLVERS

# Batch-key prefixes the hindsight wrapper adds. Each mirrors every ``observation.<key>``:
GOAL_PREFIX = OBS_PREFIX + "goal."  # the hindsight goal g = o_{k+d}
RL_GOAL_PREFIX = OBS_PREFIX + "rl_goal."  # g' drawn from the whole dataset (RL bootstrap, eq. 5)
TRAJ_PREFIX = OBS_PREFIX + "traj."  # the observation trajectory tau^o (L_o frames)
MIRROR_PREFIXES = (GOAL_PREFIX, RL_GOAL_PREFIX, TRAJ_PREFIX)
GOAL_DISTANCE_KEY = OBS_PREFIX + "goal_distance"  # d, in steps (not normalised by the processor)


def is_mirror_key(key: str) -> bool:
    return key.startswith(MIRROR_PREFIXES) or key == GOAL_DISTANCE_KEY


def mirror_key(key: str, prefix: str) -> str:
    """``observation.images.front`` -> ``observation.goal.images.front`` (for ``prefix=GOAL_PREFIX``)."""
    if not key.startswith(OBS_PREFIX) or is_mirror_key(key):
        raise ValueError(f"{key!r} is not a plain observation key.")
    return prefix + key[len(OBS_PREFIX) :]


@OptimizerConfig.register_subclass("efm_adamw")
@dataclass
class FusedAdamWConfig(AdamWConfig):
    """LeRobot's AdamW with torch's fused kernel: the same update, about 4x faster per step on CPU than
    the default per-tensor loop (measured 19 ms -> 4.4 ms for 8.8 M parameters on 2 cores)."""

    fused: bool = True


@dataclass
class EFMConfig(PreTrainedConfig):
    """Shared configuration of the EFM agents. Every field can be set from the CLI as ``--policy.<field>``.

    Trajectories (paper Sec. II-B):
        obs_traj_len: L_o, number of future observations in the planned trajectory tau^o (incl. the current one).
        obs_traj_stride: S_o, frames between two observations of tau^o.
        action_traj_len: L_a, number of actions in the predicted chunk tau^a. Must be divisible by
            2**len(unet_down_dims) (8 by default) because of the UNet.
        action_traj_stride: S_a, frames between two actions of tau^a (the chunk is sub-sampled in time).
        max_goal_distance: L_g, the hindsight goal is d ~ U{0..min(L_g, frames left)} frames ahead; the critic
            predicts d / L_g.
        action_mode: "absolute" (position commands: the chunk holds the goal command once the goal is reached)
            or "velocity" (the chunk becomes zero past the goal), as in the reference.
        cache_frames: decode every camera frame of the training dataset once, resized to the policy's image
            shape, and keep them in RAM as uint8 (N x C x H x W bytes a camera) instead of decoding the frames
            of every sample; pays when decoding bounds the step rate (small images on a CPU). Camera frames of
            another size than ``input_features`` are resized either way (OpenCV, as at deployment).

    Inference:
        num_inference_steps: Euler steps of every flow integration (reference: 20).
        critic_inference_eps: the extremum query eps of Critic(eps | o, g); 0 gives the minimum distance.
        critic_inference_solver, critic_inference_steps: ODE solver ("euler" or "heun") and steps (None =
            ``num_inference_steps``) of that query when acting (FM-AC / FM-PC conditioning, FM-PS / FM-AS
            scores, goal advance); "euler" with ``num_inference_steps`` is the paper's. A learnt critic flow is
            curved: 20 Euler steps overestimate the minimum by 4-8 frames where 5 Heun steps are within ~1.
        actor_distance_scale: FM-AC's actor and FM-PC's planner are conditioned on this times the critic's
            distance (1.0 = the paper). Below 1 asks for a faster route than the critic believes in: a probe
            of a critic that overestimates, e.g. after eq. 5's bootstrap (the reported distance stays the
            critic's).
        num_candidates: number of sampled plans scored by the critic in FM-PS / FM-AS (rejection sampling).
        n_action_steps: control steps executed from each predicted chunk before replanning (receding horizon);
            with action_traj_stride > 1 the chunk is interpolated to the control rate first.

    RL recursive bootstrap (paper eq. 5):
        use_rl: add rows (o, tau, d + Critic(eps_g | g, g'), g') with g' drawn from the whole dataset.
        rl_goal_ratio: r_g, eps_g ~ U(0, r_g) (reference: 0.3).
        rl_warmup_steps: updates trained without bootstrap rows, so that the EMA critic bootstraps only once it
            has learnt something (0 = from the first update, the paper's setting; a barely trained critic gives
            eq. 5 noise targets, which cost short CPU budgets more than the stitching gains).
        rl_ramp_steps: after the warm-up the number of bootstrap rows grows linearly from 0 to the batch size
            over these updates (0 = all at once).
        rl_target_cap: cap of eq. 5's target d + bridge, in units of ``max_goal_distance`` (None = uncapped, the
            paper's setting). The target feeds on the EMA critic's own output: uncapped, a short CPU run's
            cross-region estimates ran away to 10x the expert's steps (the reference's stay under ~2).
        rl_bridge_floor: lower bound of the bridge Critic_ema(eps_g | g, g') in eq. 5, in units of
            ``max_goal_distance`` (None = unbounded, the paper's setting; 0 = a time to the goal is never
            negative). Integrated from eps near 0 the flow extrapolates below its data, and a bootstrap that adds
            such a negative bridge teaches the next one a lower minimum: with r_g = 0.1 a 12k-step planar run
            collapsed to -1300 steps on every evaluation pair (r_g = 0.3 hides this by inflating the targets).
        rl_actor_slack: FM-AC's actor and FM-PC's planner learn only from the bootstrap rows whose target
            d' <= (1 + slack) * Critic_ema(0 | o, g'), i.e. whose chunk is on a near-shortest route to g'; the
            critics still learn from every row (None = every row for all, the paper's setting). A short run's
            actor cannot yet tell detours from d' alone and learns them (pointmaze stitch: 40 -> 14 %).
        rl_target_solver, rl_target_inference_steps: ODE solver ("euler" or "heun") and steps (None =
            ``num_inference_steps``) of the EMA critic queries of the bootstrap (eq. 5's bridge and the slack
            filter); "euler" with ``num_inference_steps`` is the paper's. Each row integrates the critic ensemble
            once or twice, most of a use-RL step's cost with large critics; a learnt critic flow is curved, so
            20 Euler steps overestimate the bridge by ~6 frames where 5 Heun steps (10 evaluations) are within ~1
            (``benchmarks/critic_ode_steps.py``).

    Deployment (a robot's observations carry no goal; :mod:`lerobot_efm.goal_source`):
        goal_path: a goal file (safetensors of one observation's ``observation.*`` keys, ``lerobot-efm-goal``).
        goal_dataset_root, goal_repo_id, goal_episode, goal_frame: or a frame of a LeRobot dataset (frame -1: the
            episode's last). The goal is inserted into every observation that has none, e.g. under
            ``lerobot-rollout --policy.path=CKPT --policy.goal_path=goal.safetensors``.
            ``goal_path`` may list several files, comma-separated: a multi-step task, each goal kept until
        goal_advance_distance: the critic's distance to it (in steps) falls under this; then the next one.
        goal_advance_key: or when this key is pressed (a LeRobot key name: a character, "enter", "space",
            "right", ...; read by LeRobot's keyboard listener, the terminal's on a headless machine; None: off).
            With a key, FM-GC (no critic) can follow a sequence too.

    Training:
        num_critics: critics trained side by side; every value uses their max (pessimistic for a distance).
        critic_loss_weight: weight of each critic's flow loss (reference: 0.1).
        reached_augment_size: rows re-appended with g := o, d := 0 and a "stay" action chunk (reference: 32).
        trajectory_source: source of the trajectory flows, "unit_ball" (reference) or "gaussian".
        obs_traj_relative: the Planner (FM-PC, FM-PS) and World model (FM-AS) learn tau^o - o, the plan's
            displacements from the current latent, and add o back when sampling (False = absolute latents, the
            reference). Absolute, a short run's planner adds position noise to what does not move: a planar
            FM-PS planner at 12k steps moved a resting disc by 0.08 in 20 frames (the data: 0.00), and the
            critic's argmin picked those teleports.
        ema_cutoff: cutoff period (in updates) of the low-pass EMA of all weights; EMA weights are used at
            inference and saved. ema_warmup_updates: the cutoff ramps up linearly over these first updates.

    Networks:
        unet_down_dims, unet_time_embed_dim, unet_kernel_size, unet_n_groups: the 1-D UNet actor.
        mlp_hidden_dims: hidden layers of the MLP flows (critics, planner, world model).
        image_latent_dim, image_encoder_channels, image_encoder_hidden_dim, image_encoder_dropout: IMPALA-small
            encoder, one per camera.
        image_random_shift: during training, shift every camera and goal image by up to this many pixels
            (edges replicated, :mod:`lerobot_efm.augment`; 0 = off, the reference's setting). Talos image FM-AC
            with 4: 14 % over 13 tasks (without, another play: 13 %; ``benchmarks/results/talos_kitchen.md``).
        image_crop: the region of every camera image (and goal image) the policy takes, as fractions of the frame
            [top, left, height, width], cropped before the resize to the image feature's shape, in training and at
            deployment (:mod:`lerobot_efm.frames`). None = the whole frame. A crop to the workspace of a wide
            camera gives its objects more of the policy's pixels. Deploy and evaluate with the camera at a larger
            resolution than the policy's image size: a frame of exactly that size is taken as cropped already (as
            the training batches are).
        auxiliary_state_key: a recorded ``observation.*`` vector that is *not* an input (e.g. a simulator's
            ``observation.environment_state``), regressed from the latent of every observation and goal during
            training (:mod:`lerobot_efm.auxiliary`): it tells an image encoder what to look for. None = off (the
            reference). auxiliary_state_weight: its loss weight; auxiliary_state_dim: its size, read from the
            dataset statistics when training starts and saved with the checkpoint. Talos image FM-AC: 34 % over
            13 tasks with it, 14 % without (``benchmarks/results/talos_kitchen.md``).
        state_encoder: "identity" (reference), "mlp" or "fourier" for vector observations; state_latent_dim
            for "mlp". "fourier" appends sin/cos(2^k pi x) for k < state_fourier_frequencies to each normalised
            coordinate (no parameters): a critic on raw positions reads a maze as open space for long.
        actor_encoder_gradients: whether the actor / planner / world-model losses train the encoder (True: the
            reference, one encoder trained by every loss). False: they read the latents detached, so only the
            critic (and ``auxiliary_state_key``'s loss) shapes the encoder, as pixel-based SAC-AE / DrQ do: an
            imitation loss rewards latents that tell play segments apart (and so their pace), the critic's
            rewards latents that measure progress to the goal.
    """

    n_obs_steps: int = 1

    obs_traj_len: int = 3
    obs_traj_stride: int = 10
    action_traj_len: int = 8
    action_traj_stride: int = 1
    max_goal_distance: int = 600
    action_mode: str = "absolute"
    cache_frames: bool = False

    num_inference_steps: int = 20
    critic_inference_eps: float = 0.0
    critic_inference_solver: str = "euler"
    critic_inference_steps: int | None = None
    actor_distance_scale: float = 1.0
    num_candidates: int = 64
    n_action_steps: int = 6

    use_rl: bool = False
    rl_goal_ratio: float = 0.3
    rl_warmup_steps: int = 0
    rl_ramp_steps: int = 0
    rl_target_cap: float | None = None
    rl_bridge_floor: float | None = None
    rl_actor_slack: float | None = None
    rl_target_solver: str = "euler"
    rl_target_inference_steps: int | None = None

    goal_path: str | None = None
    goal_dataset_root: str | None = None
    goal_repo_id: str | None = None
    goal_episode: int = 0
    goal_frame: int = -1
    goal_advance_distance: float = 10.0
    goal_advance_key: str | None = None

    num_critics: int = 2
    critic_loss_weight: float = 0.1
    reached_augment_size: int = 32
    trajectory_source: str = "unit_ball"
    obs_traj_relative: bool = False
    ema_cutoff: float = 1000.0
    ema_warmup_updates: int = 100

    unet_down_dims: tuple[int, ...] = (64, 128, 256)
    unet_time_embed_dim: int = 32
    unet_kernel_size: int = 3
    unet_n_groups: int = 8
    mlp_hidden_dims: tuple[int, ...] = (1024, 1024, 1024)
    image_latent_dim: int = 64
    image_encoder_channels: tuple[int, ...] = (16, 32, 32)
    image_encoder_hidden_dim: int = 512
    image_encoder_dropout: float = 0.2
    image_random_shift: int = 0
    image_crop: tuple[float, ...] | None = None
    auxiliary_state_key: str | None = None
    auxiliary_state_weight: float = 1.0
    auxiliary_state_dim: int = 0
    state_encoder: str = "identity"
    state_latent_dim: int = 128
    state_fourier_frequencies: int = 6
    actor_encoder_gradients: bool = True

    # LeRobot normalises observations, goals (with the statistics of the observation they mirror) and
    # actions; MIN_MAX maps positions to [-1, 1] like the reference's raw planar coordinates.
    normalization_mapping: dict[str, NormalizationMode] = field(
        default_factory=lambda: {
            "VISUAL": NormalizationMode.IDENTITY,
            "STATE": NormalizationMode.MIN_MAX,
            "ENV": NormalizationMode.MIN_MAX,
            "ACTION": NormalizationMode.MIN_MAX,
        }
    )

    optimizer_lr: float = 1e-4
    optimizer_betas: tuple[float, float] = (0.9, 0.999)
    optimizer_weight_decay: float = 1e-6
    optimizer_grad_clip_norm: float = 1.0
    scheduler_warmup_steps: int = 100
    scheduler_decay_steps: int = 200_000

    # Which components the agent trains (Table I); fixed by each registered subclass, not a field.
    agent: ClassVar[str] = ""

    def __post_init__(self):
        super().__post_init__()
        try:
            self._validate()
        except ValueError as e:
            # draccus (every LeRobot CLI) re-raises this as "Couldn't instantiate class ... using the given
            # arguments" without the reason: say it here, where it is known.
            logging.getLogger(__name__).error("%s: %s", type(self).__name__, e)
            raise

    def _validate(self) -> None:
        self.unet_down_dims = tuple(self.unet_down_dims)
        self.mlp_hidden_dims = tuple(self.mlp_hidden_dims)
        self.image_encoder_channels = tuple(self.image_encoder_channels)
        self.image_crop = None if self.image_crop is None else tuple(float(x) for x in self.image_crop)
        crop = self.image_crop
        checks = {
            "obs_traj_len": self.obs_traj_len >= 1,
            "obs_traj_stride": self.obs_traj_stride >= 1,
            "action_traj_len": self.action_traj_len >= 1,
            "action_traj_stride": self.action_traj_stride >= 1,
            "max_goal_distance": self.max_goal_distance >= 1,
            "num_inference_steps": self.num_inference_steps >= 1,
            "num_candidates": self.num_candidates >= 1,
            "num_critics": self.num_critics >= 1,
            "reached_augment_size": self.reached_augment_size >= 0,
            "rl_goal_ratio": 0.0 <= self.rl_goal_ratio <= 1.0,
            "rl_warmup_steps": self.rl_warmup_steps >= 0,
            "rl_ramp_steps": self.rl_ramp_steps >= 0,
            "rl_target_cap": self.rl_target_cap is None or self.rl_target_cap > 0,
            "rl_bridge_floor": self.rl_bridge_floor is None or self.rl_bridge_floor >= 0,
            "rl_actor_slack": self.rl_actor_slack is None or self.rl_actor_slack >= 0,
            "rl_target_solver": self.rl_target_solver in SOLVERS,
            "rl_target_inference_steps": self.rl_target_inference_steps is None
            or self.rl_target_inference_steps >= 1,
            "critic_inference_eps": 0.0 <= self.critic_inference_eps <= 1.0,
            "critic_inference_solver": self.critic_inference_solver in SOLVERS,
            "critic_inference_steps": self.critic_inference_steps is None or self.critic_inference_steps >= 1,
            "actor_distance_scale": self.actor_distance_scale > 0.0,
            "state_fourier_frequencies": self.state_fourier_frequencies >= 0,
            "image_random_shift": self.image_random_shift >= 0,
            "image_crop": crop is None
            or (
                len(crop) == 4
                and min(crop) >= 0.0
                and crop[2] > 0.0
                and crop[3] > 0.0
                and crop[0] + crop[2] <= 1.0
                and crop[1] + crop[3] <= 1.0
            ),
            "auxiliary_state_key": self.auxiliary_state_key is None
            or (
                self.auxiliary_state_key.startswith(OBS_PREFIX)
                and not is_mirror_key(self.auxiliary_state_key)
            ),
            "auxiliary_state_weight": self.auxiliary_state_weight >= 0.0,
            "auxiliary_state_dim": self.auxiliary_state_dim >= 0,
            "goal_advance_distance": self.goal_advance_distance >= 0.0,
            "goal_advance_key": self.goal_advance_key is None or bool(self.goal_advance_key.strip()),
            "n_action_steps": 1
            <= self.n_action_steps
            <= (self.action_traj_len - 1) * self.action_traj_stride + 1,
        }
        bad = [name for name, ok in checks.items() if not ok]
        if bad:
            raise ValueError(
                f"Invalid EFM config value(s): {', '.join(f'{n}={getattr(self, n)!r}' for n in bad)}."
            )
        multiple = 2 ** len(self.unet_down_dims)
        if self.action_traj_len % multiple:
            raise ValueError(
                f"action_traj_len={self.action_traj_len} must be divisible by {multiple} "
                f"(2**len(unet_down_dims)) for the UNet actor."
            )
        if self.action_mode not in ("absolute", "velocity"):
            raise ValueError(f"action_mode must be 'absolute' or 'velocity', got {self.action_mode!r}.")
        if self.state_encoder not in ("identity", "mlp", "fourier"):
            raise ValueError(
                f"state_encoder must be 'identity', 'mlp' or 'fourier', got {self.state_encoder!r}."
            )
        if self.trajectory_source not in ("unit_ball", "gaussian"):
            raise ValueError(
                f"trajectory_source must be 'unit_ball' or 'gaussian', got {self.trajectory_source!r}."
            )
        if self.use_rl and not self.uses_critic:
            raise ValueError(f"use_rl needs a critic; {type(self).__name__} (FM-GC) has none.")
        if not (self.actor_encoder_gradients or self.uses_critic or self.auxiliary_state_key):
            raise ValueError(
                f"actor_encoder_gradients=False leaves {type(self).__name__} (FM-GC) no loss that trains the "
                "encoder: set auxiliary_state_key, or keep actor_encoder_gradients=True."
            )

    # --- agent composition (Table I) ---------------------------------------------------------------
    @property
    def uses_critic(self) -> bool:
        return self.agent in ("ac", "pc", "ps", "as")

    @property
    def uses_obs_trajectory(self) -> bool:
        """Planner / world model targets are observation trajectories tau^o."""
        return self.agent in ("pc", "ps", "as")

    # --- features ----------------------------------------------------------------------------------
    @property
    def observation_features(self) -> dict[str, PolicyFeature]:
        """Input features the agent encodes (the goal and trajectory mirrors excluded)."""
        return {k: ft for k, ft in self.input_features.items() if not is_mirror_key(k)}

    @property
    def mirror_prefixes(self) -> tuple[str, ...]:
        """Mirrored key families the hindsight wrapper produces for this agent."""
        return (
            (GOAL_PREFIX,)
            + ((RL_GOAL_PREFIX,) if self.use_rl else ())
            + ((TRAJ_PREFIX,) if self.uses_obs_trajectory else ())
        )

    def add_mirror_features(self) -> None:
        """Declare the goal (and RL goal, trajectory) keys as inputs shaped like the observation they mirror,
        so LeRobot's normaliser handles them and checkpoints record them."""
        mirrors = {
            mirror_key(k, p): ft for p in self.mirror_prefixes for k, ft in self.observation_features.items()
        }
        self.input_features = {**self.input_features, **mirrors}

    def validate_features(self) -> None:
        obs = self.observation_features
        if not obs:
            raise ValueError(
                "EFM policies need at least one observation.* input feature; the config has none."
            )
        for key, ft in obs.items():
            if ft.type is FeatureType.VISUAL and len(ft.shape) != 3:
                raise ValueError(f"Image feature {key!r} must have shape (C, H, W), got {ft.shape}.")
            if ft.type is not FeatureType.VISUAL and len(ft.shape) != 1:
                raise ValueError(f"Vector feature {key!r} must have shape (D,), got {ft.shape}.")
        if "action" not in self.output_features:
            raise ValueError("EFM policies need an 'action' output feature; the dataset/env provides none.")
        if self.auxiliary_state_key in obs:
            raise ValueError(
                f"auxiliary_state_key={self.auxiliary_state_key!r} is already an input of the policy; "
                "the auxiliary loss is for a recorded vector the policy does not see (e.g. a camera policy's "
                "observation.environment_state)."
            )

    # --- LeRobot hooks -----------------------------------------------------------------------------
    @property
    def trajectory_window(self) -> int:
        """Frames a start needs after it, as in the reference: max(L_o*S_o, L_a*S_a)."""
        return max(self.obs_traj_len * self.obs_traj_stride, self.action_traj_len * self.action_traj_stride)

    @property
    def drop_n_last_frames(self) -> int:
        """Honoured by lerobot-train's EpisodeAwareSampler: start frames leave room for a full window."""
        return self.trajectory_window

    @property
    def observation_delta_indices(self) -> None:
        return None  # the hindsight wrapper fetches exactly the frames it needs

    @property
    def action_delta_indices(self) -> None:
        return None

    @property
    def reward_delta_indices(self) -> None:
        return None

    def get_optimizer_preset(self) -> FusedAdamWConfig:
        return FusedAdamWConfig(
            lr=self.optimizer_lr,
            betas=self.optimizer_betas,
            weight_decay=self.optimizer_weight_decay,
            grad_clip_norm=self.optimizer_grad_clip_norm,
        )

    def get_scheduler_preset(self) -> CosineDecayWithWarmupSchedulerConfig:
        return CosineDecayWithWarmupSchedulerConfig(
            num_warmup_steps=self.scheduler_warmup_steps,
            num_decay_steps=self.scheduler_decay_steps,
            peak_lr=self.optimizer_lr,
            decay_lr=0.0,
        )


@PreTrainedConfig.register_subclass("efm_gc")
@dataclass
class EFMGCConfig(EFMConfig):
    """FM-GC: goal-conditioned flow actor, Actor(P_src | o, g) (imitation baseline, no critic)."""

    agent: ClassVar[str] = "gc"


@PreTrainedConfig.register_subclass("efm_ac")
@dataclass
class EFMACConfig(EFMConfig):
    """FM-AC: Critic(0 | o, g) = d~, then Actor(P_src | o, g, d~)."""

    agent: ClassVar[str] = "ac"


@PreTrainedConfig.register_subclass("efm_pc")
@dataclass
class EFMPCConfig(EFMConfig):
    """FM-PC: Critic(0 | o, g) = d~, Planner(P_src | o, g, d~) = tau^o, Actor(P_src | o, tau^o)."""

    agent: ClassVar[str] = "pc"


@PreTrainedConfig.register_subclass("efm_ps")
@dataclass
class EFMPSConfig(EFMConfig):
    """FM-PS: num_candidates plans from Planner(P_src | o), keep argmin Critic(0 | tau^o_-1, g), Actor(o, tau^o)."""

    agent: ClassVar[str] = "ps"


@PreTrainedConfig.register_subclass("efm_as")
@dataclass
class EFMASConfig(EFMConfig):
    """FM-AS: num_candidates chunks from Actor(P_src | o), World(o, tau^a) = tau^o, keep argmin Critic(0 | tau^o_-1, g)."""

    agent: ClassVar[str] = "as"
