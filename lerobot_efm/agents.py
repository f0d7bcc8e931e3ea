"""The EFM components (Critic, Actor, Planner, World) and the five agents of the paper's Table I.

Each agent is one class whose ``losses`` read like the table's *Training* column and whose ``act``
reads like its *Inference* column. Observations arrive already encoded as latents ``l``; the shared
:class:`EFMAgent` base does the encoding and builds the training rows:

* the hindsight rows (o, tau^o, tau^a, d, g) of the dataset,
* the *reached* rows (o, hold, hold, 0, o): the goal is the current observation, nothing moves,
* with ``use_rl`` the bootstrap rows (o, tau^o, tau^a, d + Critic(eps_g | g, g'), g') of eq. (5).

Distances are handled as d / L_g (one raw scalar, as in the reference).
"""

from __future__ import annotations

import abc
from dataclasses import dataclass

import torch
from torch import Tensor, nn

from .augment import random_shift
from .auxiliary import AuxiliaryStateHead
from .configuration_efm import (
    GOAL_DISTANCE_KEY,
    GOAL_PREFIX,
    OBS_PREFIX,
    RL_GOAL_PREFIX,
    TRAJ_PREFIX,
    EFMConfig,
    mirror_key,
)
from .flow import euler_integrate, flow_matching_loss, integrate, interpolate, sample_source
from .networks import ConditionalUnet1d, EnsembleMLPFlow, ObservationEncoder

# --------------------------------------------------------------------------------------------------
# Components
# --------------------------------------------------------------------------------------------------


class Critic(nn.Module):
    """Critic: U(0,1) | c -> d, a 1-D flow per member; members run as one batched ensemble.

    ``query(c, eps)`` integrates deterministically from ``eps`` (the extremum query: eps=0 is the
    minimum of P(d | c)); ``distance`` combines the members with max (pessimistic for a cost).
    """

    def __init__(self, cond_dim: int, num_critics: int, hidden_dims: tuple[int, ...]):
        super().__init__()
        self.num_critics = num_critics
        self.net = EnsembleMLPFlow(num_critics, 1, cond_dim, hidden_dims)

    def loss(self, cond: Tensor, distance: Tensor) -> Tensor:
        """Eq. (1) with x_src ~ U(0,1), x_dst = d, independently per member; returns the sum over members."""
        shape = (self.num_critics, cond.shape[0], 1)
        x_src = torch.rand(shape, device=cond.device)
        t = torch.rand(shape, device=cond.device)
        x_t, target = interpolate(x_src, distance.reshape(1, -1, 1).expand(shape), t)
        return flow_matching_loss(self.net(x_t, t, cond), target) * self.num_critics

    def query(self, cond: Tensor, eps: float | Tensor, num_steps: int, solver: str = "euler") -> Tensor:
        """Critic(eps | c) for every member: (E, B). ``eps`` is a float or an (E, B) tensor."""
        cache = self.net.condition(cond)
        x0 = torch.as_tensor(eps, dtype=cond.dtype, device=cond.device)
        x0 = x0.reshape(x0.shape + (1,)).expand(self.num_critics, cond.shape[0], 1)
        return integrate(lambda x, t: self.net.velocity(x, t, cache), x0, num_steps, solver).squeeze(-1)

    def distance(self, cond: Tensor, eps: float | Tensor, num_steps: int, solver: str = "euler") -> Tensor:
        return self.query(cond, eps, num_steps, solver).amax(dim=0)


class TrajectoryFlow(nn.Module):
    """P_src | c -> trajectory (L, C): the Actor (UNet over time) and the Planner / World (MLP)."""

    def __init__(self, length: int, channels: int, cond_dim: int, config: EFMConfig, kind: str):
        super().__init__()
        self.length, self.channels, self.source = length, channels, config.trajectory_source
        if kind == "unet":
            self.net = ConditionalUnet1d(
                channels,
                cond_dim,
                config.unet_down_dims,
                config.unet_time_embed_dim,
                config.unet_kernel_size,
                config.unet_n_groups,
            )
        else:
            self.net = _FlatMLPFlow(length * channels, cond_dim, config.mlp_hidden_dims)

    def loss(self, cond: Tensor, target: Tensor) -> Tensor:
        x_src = sample_source(self.source, tuple(target.shape), 2, device=target.device)
        t = torch.rand(target.shape[0], device=target.device)
        x_t, velocity = interpolate(x_src, target, t)
        return flow_matching_loss(self.net(x_t, t, cond), velocity)

    def sample(self, cond: Tensor, num_steps: int) -> Tensor:
        cache = self.net.condition(cond)
        x0 = sample_source(self.source, (cond.shape[0], self.length, self.channels), 2, device=cond.device)
        return euler_integrate(lambda x, t: self.net.velocity(x, t, cache), x0, num_steps)


class _FlatMLPFlow(nn.Module):
    """A single-member :class:`EnsembleMLPFlow` over flattened trajectories (B, L, C)."""

    def __init__(self, x_dim: int, cond_dim: int, hidden_dims: tuple[int, ...]):
        super().__init__()
        self.mlp = EnsembleMLPFlow(1, x_dim, cond_dim, hidden_dims)

    def condition(self, cond: Tensor) -> Tensor:
        return self.mlp.condition(cond)

    def velocity(self, x: Tensor, t: Tensor, cache: Tensor) -> Tensor:
        t = t.reshape(1, -1, 1) if t.dim() else t
        return self.mlp.velocity(x.reshape(1, x.shape[0], -1), t, cache).reshape(x.shape)

    def forward(self, x: Tensor, t: Tensor, cond: Tensor) -> Tensor:
        return self.velocity(x, t, self.condition(cond))


# --------------------------------------------------------------------------------------------------
# Training rows
# --------------------------------------------------------------------------------------------------


@dataclass
class Rows:
    """Encoded training tuples (l_o, tau^o, tau^a, d, l_g) of the paper's Sec. II-B."""

    obs: Tensor  # (N, D) latent observation l_o
    goal: Tensor  # (N, D) latent goal l_g
    distance: Tensor  # (N,) d / L_g
    actions: Tensor  # (N, L_a, A) action trajectory tau^a
    obs_traj: Tensor | None  # (N, L_o, D) latent observation trajectory tau^o (stop-gradient targets)

    def select(self, keep: Tensor) -> Rows:
        return Rows(
            self.obs[keep],
            self.goal[keep],
            self.distance[keep],
            self.actions[keep],
            None if self.obs_traj is None else self.obs_traj[keep],
        )

    def detached(self) -> Rows:
        """The same rows with latents that pass no gradient back to the encoder."""
        return Rows(self.obs.detach(), self.goal.detach(), self.distance, self.actions, self.obs_traj)

    def cat(self, other: Rows) -> Rows:
        return Rows(
            torch.cat([self.obs, other.obs]),
            torch.cat([self.goal, other.goal]),
            torch.cat([self.distance, other.distance]),
            torch.cat([self.actions, other.actions]),
            None if self.obs_traj is None else torch.cat([self.obs_traj, other.obs_traj]),
        )


@dataclass
class TrainingRows:
    """Rows for goal-conditioned models (critic, goal-conditioned actor/planner) and for goal-free ones.

    Goal-free models (FM-PS/AS planners/actors, inverse-dynamics actors) do not see g or d, so the RL
    rows, which only change g and d, would be exact duplicates for them and are left out.
    """

    goal_conditioned: Rows
    goal_free: Rows
    num_bootstrap: int = 0  # eq. (5) rows at the end of goal_conditioned
    distance_conditioned: Rows | None = None  # for the actor / planner on d, if not all of goal_conditioned
    batch_latents: tuple[Tensor, Tensor] | None = None  # (l_o, l_g) of the batch's own rows, augmented
    critic_rows: Rows | None = None  # the critic's rows, if not goal_conditioned (which may be detached)

    def for_critic(self) -> Rows:
        return self.goal_conditioned if self.critic_rows is None else self.critic_rows

    def for_distance_conditioned(self) -> Rows:
        """Rows of the components conditioned on (o, g, d): FM-AC's actor, FM-PC's planner."""
        return self.goal_conditioned if self.distance_conditioned is None else self.distance_conditioned

    def without_encoder_gradients(self) -> TrainingRows:
        """The rows the non-critic components see with ``actor_encoder_gradients=False``."""
        return TrainingRows(
            self.goal_conditioned.detached(),
            self.goal_free.detached(),
            self.num_bootstrap,
            None if self.distance_conditioned is None else self.distance_conditioned.detached(),
            self.batch_latents,
            critic_rows=self.for_critic(),
        )


# --------------------------------------------------------------------------------------------------
# Agents
# --------------------------------------------------------------------------------------------------


class EFMAgent(nn.Module, abc.ABC):
    """Encoder + components of one agent; subclasses define ``losses`` and ``act``."""

    def __init__(
        self,
        config: EFMConfig,
        rest_action: Tensor | None = None,
        auxiliary_bounds: tuple[Tensor, Tensor] | None = None,
    ):
        super().__init__()
        self.config = config
        obs = config.observation_features
        image_shapes = {k[len(OBS_PREFIX) :]: tuple(ft.shape) for k, ft in obs.items() if len(ft.shape) == 3}
        vector_dims = {k[len(OBS_PREFIX) :]: ft.shape[0] for k, ft in obs.items() if len(ft.shape) == 1}
        self.encoder = ObservationEncoder(
            image_shapes,
            vector_dims,
            config.image_latent_dim,
            config.image_encoder_channels,
            config.image_encoder_hidden_dim,
            config.image_encoder_dropout,
            config.state_encoder,
            config.state_latent_dim,
            config.state_fourier_frequencies,
        )
        self.latent_dim = self.encoder.latent_dim
        self.action_dim = config.output_features["action"].shape[0]
        # The "stay" action of velocity commands, in normalised units (raw 0); absolute commands hold a_k.
        self.register_buffer(
            "rest_action", torch.zeros(self.action_dim) if rest_action is None else rest_action.float()
        )
        if config.uses_critic:
            self.critic = Critic(2 * self.latent_dim, config.num_critics, config.mlp_hidden_dims)
        if config.auxiliary_state_key:  # a training loss, read out at inference for inspection only
            self.auxiliary_head = AuxiliaryStateHead(
                self.latent_dim, config.auxiliary_state_dim, *(auxiliary_bounds or ())
            )
        self.build_components(self.latent_dim, self.action_dim)

    @abc.abstractmethod
    def build_components(self, latent_dim: int, action_dim: int) -> None:
        """Create the agent's components (besides the shared encoder and critic)."""

    # --- helpers -----------------------------------------------------------------------------------
    def _actor(self, cond_dim: int) -> TrajectoryFlow:
        return TrajectoryFlow(self.config.action_traj_len, self.action_dim, cond_dim, self.config, "unet")

    def _obs_traj_flow(self, cond_dim: int) -> TrajectoryFlow:
        return TrajectoryFlow(self.config.obs_traj_len, self.latent_dim, cond_dim, self.config, "mlp")

    def plan_target(self, obs_traj: Tensor) -> Tensor:
        """What the Planner / World model learns: tau^o, or with ``obs_traj_relative`` tau^o - tau^o[0]
        (tau^o[0] is the current observation's EMA latent, the frame the plan starts from)."""
        return obs_traj - obs_traj[:, :1] if self.config.obs_traj_relative else obs_traj

    def plan_from(self, sample: Tensor, l_obs: Tensor) -> Tensor:
        """A sampled plan as latents: the inverse of ``plan_target`` (``l_obs`` (B, D) starts it)."""
        return sample + l_obs[:, None] if self.config.obs_traj_relative else sample

    def encode(self, batch: dict[str, Tensor], prefixes: tuple[str, ...]) -> list[Tensor]:
        """Encode several mirrored key families in one encoder call (one batched pass per camera)."""
        keys = [k[len(OBS_PREFIX) :] for k in self.config.observation_features]
        merged = {OBS_PREFIX + k: torch.cat([batch[p + k] for p in prefixes]) for k in keys}
        return list(self.encoder(merged).split(batch[prefixes[0] + keys[0]].shape[0]))

    def augment_images(self, batch: dict[str, Tensor], prefixes: tuple[str, ...]) -> dict[str, Tensor]:
        """Training only: each observation and goal image shifted at random (``image_random_shift``)."""
        pad = self.config.image_random_shift
        if not (self.training and pad and self.encoder.image_keys):
            return batch
        shifted = {p + k: random_shift(batch[p + k], pad) for p in prefixes for k in self.encoder.image_keys}
        return {**batch, **shifted}

    def critic_distance(
        self, obs: Tensor, goal: Tensor, num_steps: int | None = None, solver: str | None = None
    ) -> Tensor:
        """Critic(critic_inference_eps | o, g), integrated with ``num_steps`` steps of ``solver`` (None: the
        acting query's, ``critic_inference_steps`` / ``critic_inference_solver``)."""
        cfg = self.config
        steps = num_steps or cfg.critic_inference_steps or cfg.num_inference_steps
        solver = solver or cfg.critic_inference_solver
        return self.critic.distance(torch.cat([obs, goal], -1), cfg.critic_inference_eps, steps, solver)

    # --- training ----------------------------------------------------------------------------------
    def num_bootstrap_rows(self, batch_size: int, step: int | None) -> int:
        """Eq. (5) rows this update: none without RL or during ``rl_warmup_steps``, then ramped linearly to
        the batch size over ``rl_ramp_steps`` updates. ``step=None`` (outside a training loop) = fully on."""
        cfg = self.config
        if not (cfg.use_rl and cfg.uses_critic):
            return 0
        if step is None:
            return batch_size
        since = int(step) - cfg.rl_warmup_steps
        if since < 0:
            return 0
        if cfg.rl_ramp_steps == 0:
            return batch_size
        return min(batch_size, round(batch_size * (since + 1) / cfg.rl_ramp_steps))

    def training_rows(
        self, batch: dict[str, Tensor], target: EFMAgent, step: int | None = None
    ) -> TrainingRows:
        cfg = self.config
        n_rl = self.num_bootstrap_rows(batch["action"].shape[0], step)
        use_rl = n_rl > 0
        prefixes = (OBS_PREFIX, GOAL_PREFIX) + ((RL_GOAL_PREFIX,) if use_rl else ())
        latents = self.encode(self.augment_images(batch, prefixes), prefixes)
        l_obs, l_goal = latents[0], latents[1]
        actions = batch["action"]
        distance = batch[GOAL_DISTANCE_KEY].float() / cfg.max_goal_distance

        obs_traj = None
        if cfg.uses_obs_trajectory:
            # Planner / world targets are *stop-gradient* latents of the EMA encoder: regressing onto
            # latents that the same loss can move lets a learned encoder collapse them.
            with torch.no_grad():
                traj_batch = {
                    OBS_PREFIX + k[len(TRAJ_PREFIX) :]: v.flatten(0, 1)
                    for k, v in batch.items()
                    if k.startswith(TRAJ_PREFIX)
                }
                obs_traj = target.encoder(traj_batch).reshape(actions.shape[0], cfg.obs_traj_len, -1)
        rows = Rows(l_obs, l_goal, distance, actions, obs_traj)

        # Reached rows: g := o, d := 0, nothing moves (absolute commands hold a_k, velocities are zero).
        n = min(cfg.reached_augment_size, l_obs.shape[0])
        if n:
            hold = actions[:n, :1] if cfg.action_mode == "absolute" else self.rest_action.expand(n, 1, -1)
            reached = Rows(
                l_obs[:n],
                l_obs[:n],
                torch.zeros_like(distance[:n]),
                hold.expand(-1, cfg.action_traj_len, -1),
                None if obs_traj is None else obs_traj[:n, :1].expand(-1, cfg.obs_traj_len, -1),
            )
            rows = rows.cat(reached)
        goal_free = rows

        if not use_rl:
            return TrainingRows(rows, goal_free, batch_latents=(l_obs, l_goal))
        head = {k: v[:n_rl] for k, v in batch.items() if isinstance(v, Tensor)}
        boot, near_shortest = self.bootstrap_rows(
            head,
            target,
            l_obs[:n_rl],
            latents[2][:n_rl],
            distance[:n_rl],
            actions[:n_rl],
            None if obs_traj is None else obs_traj[:n_rl],
        )
        distance_conditioned = None if near_shortest is None else rows.cat(boot.select(near_shortest))
        return TrainingRows(rows.cat(boot), goal_free, n_rl, distance_conditioned, (l_obs, l_goal))

    @torch.no_grad()
    def bootstrap_rows(
        self, batch, target: EFMAgent, l_obs, l_rl_goal, distance, actions, obs_traj
    ) -> tuple[Rows, Tensor | None]:
        """Eq. (5): d' = d + max_e C_e^ema(eps_e | g, g'), eps_e ~ U(0, r_g), with EMA encoder and critics.

        With ``rl_actor_slack`` also which rows have d' <= (1 + slack) Critic_ema(0 | o, g'): their chunk is on
        a near-shortest route to g'. The others head elsewhere first; conditioned on d' alone an actor needs
        a long training to tell them apart, and meanwhile learns their detours.
        """
        cfg = self.config
        filtered = cfg.rl_actor_slack is not None
        prefixes = (GOAL_PREFIX, RL_GOAL_PREFIX) + ((OBS_PREFIX,) if filtered else ())
        t_goal, t_rl_goal, *t_obs = target.encode(batch, prefixes)
        steps, solver = cfg.rl_target_inference_steps or cfg.num_inference_steps, cfg.rl_target_solver
        eps = torch.rand(cfg.num_critics, l_obs.shape[0], device=l_obs.device) * cfg.rl_goal_ratio
        bridge = target.critic.query(torch.cat([t_goal, t_rl_goal], -1), eps, steps, solver).amax(0)
        if cfg.rl_bridge_floor is not None:  # a negative extrapolated bridge would lower the next minimum
            bridge = bridge.clamp(min=cfg.rl_bridge_floor)
        stitched = distance + bridge
        if cfg.rl_target_cap is not None:  # keeps the bootstrap from feeding on a runaway critic
            stitched = stitched.clamp(max=cfg.rl_target_cap)
        near_shortest = None
        if filtered:
            shortest = target.critic_distance(t_obs[0], t_rl_goal, steps, solver)
            near_shortest = stitched <= (1.0 + cfg.rl_actor_slack) * shortest
        return Rows(l_obs, l_rl_goal, stitched, actions, obs_traj), near_shortest

    def critic_loss(self, rows: Rows) -> Tensor:
        return self.critic.loss(torch.cat([rows.obs, rows.goal], -1), rows.distance)

    @abc.abstractmethod
    def losses(self, rows: TrainingRows) -> dict[str, Tensor]:
        """One flow-matching loss per component, keyed by component name."""

    def compute_loss(
        self, batch: dict[str, Tensor], target: EFMAgent, step: int | None = None
    ) -> tuple[Tensor, dict[str, float]]:
        """``step``: updates done so far (the RL warm-up and ramp read it; None = RL fully on)."""
        rows = self.training_rows(batch, target, step)
        losses = self.losses(
            rows if self.config.actor_encoder_gradients else rows.without_encoder_gradients()
        )
        if self.config.auxiliary_state_key:
            losses["auxiliary_state"] = self.auxiliary_state_loss(batch, rows.batch_latents)
        weights = {
            "critic": self.config.critic_loss_weight,
            "auxiliary_state": self.config.auxiliary_state_weight,
        }
        total = sum(weights.get(k, 1.0) * v for k, v in losses.items())
        info = {f"loss_{k}": v.item() for k, v in losses.items()}
        info["rows"] = float(rows.goal_conditioned.obs.shape[0])
        n_rl = rows.num_bootstrap
        if self.config.use_rl:
            info["rl_rows"] = float(n_rl)
        if n_rl:
            bootstrap = rows.goal_conditioned.distance[-n_rl:]
            info["rl_target_distance"] = bootstrap.mean().item() * self.config.max_goal_distance
            kept = rows.for_distance_conditioned().obs.shape[0] - (rows.goal_conditioned.obs.shape[0] - n_rl)
            info["rl_actor_rows"] = float(kept)
        return total, info

    def auxiliary_state_loss(self, batch: dict[str, Tensor], latents: tuple[Tensor, Tensor]) -> Tensor:
        """The recorded ``auxiliary_state_key`` of the observation and of the goal, regressed from their latents."""
        key = self.config.auxiliary_state_key
        state = torch.cat([batch[key], batch[mirror_key(key, GOAL_PREFIX)]])
        return self.auxiliary_head.loss(torch.cat(latents), state)

    # --- inference ---------------------------------------------------------------------------------
    @abc.abstractmethod
    def act(self, l_obs: Tensor, l_goal: Tensor) -> dict[str, Tensor]:
        """Returns at least ``action`` (B, L_a, A); also what the agent believed (distance, plans, ...)."""

    @torch.no_grad()
    def predict(self, batch: dict[str, Tensor]) -> dict[str, Tensor]:
        l_obs, l_goal = self.encode(batch, (OBS_PREFIX, GOAL_PREFIX))
        out = self.act(l_obs, l_goal)
        if "distance" in out:
            out["distance"] = out["distance"] * self.config.max_goal_distance  # in steps
        if self.config.auxiliary_state_key:
            # What the latents say about the privileged state (e.g. where the pot is), for inspection only:
            # a rollout shows whether the camera is read as well on the policy's own states as on the play's.
            out["auxiliary_state"] = self.auxiliary_head.predict(l_obs)
            out["auxiliary_goal_state"] = self.auxiliary_head.predict(l_goal)
        return out

    def select_candidates(self, plans: Tensor, scores: Tensor) -> tuple[Tensor, Tensor]:
        """Per-row argmin over candidates: plans (B, N, ...), scores (B, N) -> chosen (B, ...), index (B,)."""
        index = scores.argmin(dim=1)
        return plans[torch.arange(plans.shape[0], device=plans.device), index], index

    def repeat_candidates(self, x: Tensor) -> Tensor:
        return x.repeat_interleave(self.config.num_candidates, dim=0)


class FMGC(EFMAgent):
    """Actor: P_src | o, g -> tau^a."""

    def build_components(self, latent_dim, action_dim):
        self.actor = self._actor(2 * latent_dim)

    def losses(self, rows):
        r = rows.goal_conditioned
        return {"actor": self.actor.loss(torch.cat([r.obs, r.goal], -1), r.actions)}

    def act(self, l_obs, l_goal):
        return {"action": self.actor.sample(torch.cat([l_obs, l_goal], -1), self.config.num_inference_steps)}


class FMAC(EFMAgent):
    """Critic: U(0,1) | o, g -> d;  Actor: P_src | o, g, d -> tau^a."""

    def build_components(self, latent_dim, action_dim):
        self.actor = self._actor(2 * latent_dim + 1)

    def losses(self, rows):
        a = rows.for_distance_conditioned()
        return {
            "critic": self.critic_loss(rows.for_critic()),
            "actor": self.actor.loss(torch.cat([a.obs, a.goal, a.distance[:, None]], -1), a.actions),
        }

    def act(self, l_obs, l_goal):
        d = self.critic_distance(l_obs, l_goal)
        asked = self.config.actor_distance_scale * d
        action = self.actor.sample(
            torch.cat([l_obs, l_goal, asked[:, None]], -1), self.config.num_inference_steps
        )
        return {"action": action, "distance": d}


class FMPC(EFMAgent):
    """Critic: U(0,1) | o, g -> d;  Planner: P_src | o, g, d -> tau^o;  Actor: P_src | o, tau^o -> tau^a."""

    def build_components(self, latent_dim, action_dim):
        self.planner = self._obs_traj_flow(2 * latent_dim + 1)
        self.actor = self._actor(latent_dim * (1 + self.config.obs_traj_len))

    def losses(self, rows):
        f, p = rows.goal_free, rows.for_distance_conditioned()
        return {
            "critic": self.critic_loss(rows.for_critic()),
            "planner": self.planner.loss(
                torch.cat([p.obs, p.goal, p.distance[:, None]], -1), self.plan_target(p.obs_traj)
            ),
            "actor": self.actor.loss(torch.cat([f.obs, f.obs_traj.flatten(1)], -1), f.actions),
        }

    def act(self, l_obs, l_goal):
        steps = self.config.num_inference_steps
        d = self.critic_distance(l_obs, l_goal)
        asked = self.config.actor_distance_scale * d
        plan = self.plan_from(
            self.planner.sample(torch.cat([l_obs, l_goal, asked[:, None]], -1), steps), l_obs
        )
        action = self.actor.sample(torch.cat([l_obs, plan.flatten(1)], -1), steps)
        return {"action": action, "distance": d, "obs_plan": plan}


class FMPS(EFMAgent):
    """Critic: U(0,1) | o, g -> d;  Planner: P_src | o -> tau^o;  Actor: P_src | o, tau^o -> tau^a.

    Inference: num_candidates plans, keep argmin Critic(0 | tau^o_-1, g), batched over rows and candidates.
    """

    def build_components(self, latent_dim, action_dim):
        self.planner = self._obs_traj_flow(latent_dim)
        self.actor = self._actor(latent_dim * (1 + self.config.obs_traj_len))

    def losses(self, rows):
        f = rows.goal_free
        return {
            "critic": self.critic_loss(rows.for_critic()),
            "planner": self.planner.loss(f.obs, self.plan_target(f.obs_traj)),
            "actor": self.actor.loss(torch.cat([f.obs, f.obs_traj.flatten(1)], -1), f.actions),
        }

    def act(self, l_obs, l_goal):
        steps, n = self.config.num_inference_steps, self.config.num_candidates
        obs = self.repeat_candidates(l_obs)
        plans = self.plan_from(self.planner.sample(obs, steps), obs)  # (B*N, L_o, D)
        scores = self.critic_distance(plans[:, -1], self.repeat_candidates(l_goal)).view(-1, n)
        plans = plans.view(l_obs.shape[0], n, *plans.shape[1:])
        plan, index = self.select_candidates(plans, scores)
        action = self.actor.sample(torch.cat([l_obs, plan.flatten(1)], -1), steps)
        return {
            "action": action,
            "distance": scores.amin(1),
            "obs_plan": plan,
            "candidate_obs_plans": plans,
            "candidate_distances": scores,
            "chosen_candidate": index,
        }


class FMAS(EFMAgent):
    """Critic: U(0,1) | o, g -> d;  Actor: P_src | o -> tau^a;  World: P_src | o, tau^a -> tau^o.

    Inference: num_candidates chunks, each rolled through the world model, keep argmin Critic(0 | tau^o_-1, g).
    """

    def build_components(self, latent_dim, action_dim):
        self.actor = self._actor(latent_dim)
        self.world = self._obs_traj_flow(latent_dim + self.config.action_traj_len * action_dim)

    def losses(self, rows):
        f = rows.goal_free
        return {
            "critic": self.critic_loss(rows.for_critic()),
            "actor": self.actor.loss(f.obs, f.actions),
            "world": self.world.loss(
                torch.cat([f.obs, f.actions.flatten(1)], -1), self.plan_target(f.obs_traj)
            ),
        }

    def act(self, l_obs, l_goal):
        steps, n = self.config.num_inference_steps, self.config.num_candidates
        obs = self.repeat_candidates(l_obs)
        chunks = self.actor.sample(obs, steps)  # (B*N, L_a, A)
        futures = self.plan_from(self.world.sample(torch.cat([obs, chunks.flatten(1)], -1), steps), obs)
        scores = self.critic_distance(futures[:, -1], self.repeat_candidates(l_goal)).view(-1, n)
        chunks = chunks.view(l_obs.shape[0], n, *chunks.shape[1:])
        action, index = self.select_candidates(chunks, scores)
        futures = futures.view(l_obs.shape[0], n, *futures.shape[1:])
        return {
            "action": action,
            "distance": scores.amin(1),
            "obs_plan": futures[torch.arange(len(index)), index],
            "candidate_actions": chunks,
            "candidate_distances": scores,
            "chosen_candidate": index,
        }


AGENTS: dict[str, type[EFMAgent]] = {"gc": FMGC, "ac": FMAC, "pc": FMPC, "ps": FMPS, "as": FMAS}


def make_agent(
    config: EFMConfig,
    rest_action: Tensor | None = None,
    auxiliary_bounds: tuple[Tensor, Tensor] | None = None,
) -> EFMAgent:
    return AGENTS[config.agent](config, rest_action, auxiliary_bounds)
