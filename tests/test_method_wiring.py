"""The wiring that makes EFM *EFM*, pinned by values rather than shapes (issue 11, items 1-6).

Every test here fails on one named wiring bug (see each docstring). The networks are the tiny ones of
``conftest.py``, the batches are built by hand (state-only, 2-D), so each expected value is computed
independently of the code under test: critics with a known output (a constant or linear velocity makes the
Euler flow exact), stubbed candidate generators, and a small learning run on a 2-D point.
"""

import copy
import math

import numpy as np
import pytest
import torch
from conftest import EFM_TYPES, tiny_config
from lerobot.configs.types import FeatureType, PolicyFeature
from lerobot.policies.factory import get_policy_class, make_pre_post_processors
from torch import nn
from torch.testing import assert_close

from lerobot_efm.agents import make_agent

STATE, IMAGE = "observation.state", "observation.images.top"
GOAL, RL_GOAL, TRAJ = "observation.goal.state", "observation.rl_goal.state", "observation.traj.state"
DIST = "observation.goal_distance"
CRITIC_TYPES = [t for t in EFM_TYPES if t != "efm_gc"]


def state_config(policy_type, **overrides):
    features = dict(
        input_features={STATE: PolicyFeature(type=FeatureType.STATE, shape=(2,))},
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(2,))},
    )
    return tiny_config(policy_type, **{**features, **overrides})


def make(policy_type, **overrides):
    return get_policy_class(policy_type)(state_config(policy_type, **overrides))


def hand_batch(cfg, n, seed=0):
    """A hindsight training batch with every key the agent reads; values are arbitrary but distinct."""
    g = torch.Generator().manual_seed(seed)

    def uniform(*shape):
        return torch.rand(*shape, generator=g) * 2 - 1

    batch = {
        STATE: uniform(n, 2),
        GOAL: uniform(n, 2),
        DIST: torch.randint(1, cfg.max_goal_distance + 1, (n,), generator=g).float(),
        "action": uniform(n, cfg.action_traj_len, 2),
    }
    if cfg.use_rl:
        batch[RL_GOAL] = uniform(n, 2)
    if cfg.uses_obs_trajectory:
        batch[TRAJ] = uniform(n, cfg.obs_traj_len, 2)
    return batch


def perturb(module, scale=1.0):
    with torch.no_grad():
        for p in module.parameters():
            p.add_(scale * torch.randn_like(p))


def set_constant_critic(critic, offsets):
    """Critic_e(eps | c) = eps + offsets[e] exactly: zero last-layer weights leave the bias as the velocity."""
    with torch.no_grad():
        critic.net.weights[-1].zero_()
        critic.net.biases[-1].copy_(torch.tensor(offsets).reshape(-1, 1, 1))


class LinearVelocity(nn.Module):
    """A critic network whose velocity is c_e + w_e . cond, constant in x and t, so that
    Critic_e(eps | cond) = eps + c_e + w_e . cond exactly under Euler integration."""

    def __init__(self, w, c):
        super().__init__()
        self.register_buffer("w", w)  # (E, cond_dim)
        self.register_buffer("c", c)  # (E,)

    def condition(self, cond):
        return (cond @ self.w.T).T.unsqueeze(-1) + self.c.reshape(-1, 1, 1)

    def velocity(self, x, t, cache):
        return cache.expand_as(x)


# --------------------------------------------------------------------------------------------------
# 1. Eq. (5): d' = d + max_e Critic_e^EMA(eps_e | l_g, l_g'), eps_e ~ U(0, r_g), without gradient
# --------------------------------------------------------------------------------------------------


def test_bootstrap_distance_is_d_plus_the_ema_critics_max():
    """Fails if the bootstrap target uses the online critic, min instead of max over members, drops d,
    or changes the rest of the tuple (o, tau^a and g' of eq. 5)."""
    policy = make("efm_ac", use_rl=True, rl_goal_ratio=0.0, num_critics=3)
    set_constant_critic(policy.ema_model.critic, [0.2, 0.7, 0.4])
    set_constant_critic(policy.model.critic, [3.0, 4.0, 5.0])  # the online critic must not be the target
    batch = hand_batch(policy.config, 6)
    rows = policy.model.training_rows(batch, policy.ema_model).goal_conditioned
    boot = slice(-6, None)
    assert_close(rows.distance[boot], batch[DIST] / policy.config.max_goal_distance + 0.7, atol=1e-6, rtol=0)
    # identity encoder: latents are the (normalised) states
    assert_close(rows.obs[boot], batch[STATE])
    assert_close(rows.goal[boot], batch[RL_GOAL])
    assert torch.equal(rows.actions[boot], batch["action"])


def test_bootstrap_eps_is_drawn_uniformly_in_0_rg():
    """Fails if eps_g is not drawn per row in [0, r_g] (e.g. U(0, 1), a constant r_g, or eps = 0)."""
    policy = make("efm_ac", use_rl=True, rl_goal_ratio=0.3, num_critics=2)
    set_constant_critic(policy.ema_model.critic, [0.5, 0.1])  # member 0 is the max whatever eps is
    batch = hand_batch(policy.config, 64)
    rows = policy.model.training_rows(batch, policy.ema_model).goal_conditioned
    bridge = rows.distance[-64:] - batch[DIST] / policy.config.max_goal_distance
    assert bridge.min() >= 0.5 - 1e-6 and bridge.max() <= 0.8 + 1e-6
    assert bridge.max() - bridge.min() > 0.2  # spread over the interval (64 draws)
    assert abs(bridge.mean().item() - 0.65) < 0.05


def test_bootstrap_bridge_is_conditioned_on_the_ema_latents_of_g_and_g_prime():
    """Fails if the bridge is computed from (o, g') or (g', g) instead of (g, g'), or with the online encoder."""
    policy = make(
        "efm_ac", use_rl=True, rl_goal_ratio=0.0, num_critics=2, state_encoder="mlp", state_latent_dim=8
    )
    perturb(policy.model.encoder)  # online latents differ from the EMA ones
    w, c = torch.randn(2, 16), torch.tensor([0.3, -0.2])
    policy.ema_model.critic.net = LinearVelocity(w, c)
    batch = hand_batch(policy.config, 8)
    rows = policy.model.training_rows(batch, policy.ema_model).goal_conditioned

    with torch.no_grad():
        ema_latent = policy.ema_model.encoder
        cond = torch.cat([ema_latent({STATE: batch[GOAL]}), ema_latent({STATE: batch[RL_GOAL]})], -1)
    expected = batch[DIST] / policy.config.max_goal_distance + (cond @ w.T + c).amax(1)
    assert_close(rows.distance[-8:], expected, atol=1e-5, rtol=1e-5)


def test_bootstrap_target_carries_no_gradient():
    """With a target network that *could* take gradients, none reaches it and the bootstrap distances are
    constants; the rows' o and g' latents are trained through the online encoder. Fails without the
    stop-gradient on eq. (5)."""
    cfg = state_config("efm_ac", use_rl=True, state_encoder="mlp", state_latent_dim=8)
    model = make_agent(cfg)
    target = copy.deepcopy(model)  # requires_grad left on, unlike EFMPolicy.ema_model
    batch = hand_batch(cfg, 6)
    rows = model.training_rows(batch, target).goal_conditioned
    assert not rows.distance.requires_grad
    assert rows.obs[-6:].requires_grad and rows.goal[-6:].requires_grad
    loss, _ = model.compute_loss(batch, target)
    loss.backward()
    assert all(p.grad is None for p in target.parameters())
    grads = [p.grad for p in model.encoder.parameters()]
    assert grads and all(g is not None and g.abs().sum() > 0 for g in grads)


@pytest.mark.parametrize("policy_type", ["efm_ac", "efm_pc"])
def test_rl_actor_slack_keeps_near_shortest_bootstrap_rows_for_the_actor_only(policy_type):
    """With r_g = 0 and a linear EMA critic, d' = d + C(0 | g, g'); slack 0.5 keeps for the actor / planner the
    bootstrap rows with d' <= 1.5 C(0 | o, g'), while the critic learns from all. Fails if the filter is
    ignored, compares against another pair than (o, g'), or reaches the critic's rows."""
    policy = make(policy_type, use_rl=True, rl_goal_ratio=0.0, rl_actor_slack=0.5, reached_augment_size=2)
    w, c = 0.2 * torch.randn(2, 4, generator=torch.Generator().manual_seed(3)), torch.tensor([0.5, 0.3])
    policy.ema_model.critic.net = LinearVelocity(w, c)
    n = 48
    batch = hand_batch(policy.config, n)

    def critic(a, b):
        return (torch.cat([a, b], -1) @ w.T + c).amax(1)

    d = batch[DIST] / policy.config.max_goal_distance
    stitched = d + critic(batch[GOAL], batch[RL_GOAL])
    keep = stitched <= 1.5 * critic(batch[STATE], batch[RL_GOAL])
    assert 0 < keep.sum() < n
    rows = policy.model.training_rows(batch, policy.ema_model)
    critic_rows, actor_rows = rows.goal_conditioned, rows.for_distance_conditioned()
    assert critic_rows.obs.shape[0] == n + 2 + n
    assert actor_rows.obs.shape[0] == n + 2 + int(keep.sum())
    assert_close(actor_rows.distance[n + 2 :], stitched[keep])
    assert_close(actor_rows.goal[n + 2 :], batch[RL_GOAL][keep])
    assert torch.equal(actor_rows.actions[n + 2 :], batch["action"][keep])

    flow = policy.model.actor if policy_type == "efm_ac" else policy.model.planner
    loss, seen = flow.loss, []
    flow.loss = lambda cond, target: (seen.append(cond.shape[0]), loss(cond, target))[1]
    _, info = policy.model.compute_loss(batch, policy.ema_model)
    assert seen == [n + 2 + int(keep.sum())]
    assert info["rl_actor_rows"] == keep.sum().item()
    with pytest.raises(ValueError, match="rl_actor_slack=-0.1"):
        state_config(policy_type, use_rl=True, rl_actor_slack=-0.1)


# --------------------------------------------------------------------------------------------------
# 2. EMA wiring (the lerobot-train side is in tests/test_resume_exact.py and tests/test_lerobot_cli.py)
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_inference_acts_with_the_ema_model(policy_type):
    """Fails if predict_action_chunk (hence select_action) uses ``model`` instead of ``ema_model``."""
    policy = make(policy_type)
    policy.eval()
    batch = hand_batch(policy.config, 3)
    obs = {STATE: batch[STATE], GOAL: batch[GOAL]}

    def chunk():
        torch.manual_seed(5)
        return policy.predict_action_chunk(obs)

    reference = chunk()
    perturb(policy.model)
    assert torch.equal(chunk(), reference)  # the online weights do not act
    perturb(policy.ema_model, 0.1)
    assert not torch.allclose(chunk(), reference)


def test_ema_follows_the_ramped_low_pass_over_several_updates():
    """update() k: cutoff T_k = ema_cutoff * min(1, k / ema_warmup_updates), omega = 2 pi / T_k,
    alpha = (1 - omega/2) / (1 + omega/2), ema <- alpha ema + (1 - alpha) theta; buffers are copied.
    Fails without the ramp, with an off-by-one in k, or with buffers averaged or left behind."""
    policy = make("efm_pc", ema_cutoff=40.0, ema_warmup_updates=4)
    expected = {n: p.detach().clone() for n, p in policy.ema_model.named_parameters()}
    for k in range(1, 7):
        perturb(policy.model, 0.1)
        with torch.no_grad():
            policy.model.rest_action.add_(1.0)
        policy.update()
        omega = 2 * math.pi / (40.0 * min(1.0, k / 4))
        alpha = max(0.0, (1 - omega / 2) / (1 + omega / 2))
        online = dict(policy.model.named_parameters())
        ema = dict(policy.ema_model.named_parameters())
        for name in expected:
            expected[name] = alpha * expected[name] + (1 - alpha) * online[name].detach()
            assert_close(ema[name], expected[name], rtol=1e-5, atol=1e-6, msg=f"update {k}: {name}")
        assert torch.equal(policy.ema_model.rest_action, policy.model.rest_action)
        assert policy.ema_updates.item() == k


# --------------------------------------------------------------------------------------------------
# 3. Training rows and loss composition
# --------------------------------------------------------------------------------------------------


def test_training_rows_hindsight_reached_and_goal_free():
    """Hindsight rows (o, tau^o, tau^a, d / L_g, g); reached rows (o, held tau^o_0, held a_k, 0, o); goal-free
    rows = those two without the eq. (5) rows; tau^o are stop-gradient latents of the EMA encoder.
    Fails if a goal latent is replaced by the observation latent (or the reverse in reached rows), if d is
    not scaled by L_g, if reached rows do not hold, if the RL rows leak into the goal-free rows, or if the
    planner/world targets come from the online encoder."""
    policy = make("efm_pc", use_rl=True, state_encoder="mlp", state_latent_dim=8, reached_augment_size=3)
    perturb(policy.model.encoder)  # online != EMA encoder
    cfg, b, n = policy.config, 5, 3
    batch = hand_batch(cfg, b)
    rows = policy.model.training_rows(batch, policy.ema_model)
    gc, free = rows.goal_conditioned, rows.goal_free
    with torch.no_grad():
        l_obs = policy.model.encoder({STATE: batch[STATE]})
        l_goal = policy.model.encoder({STATE: batch[GOAL]})
        traj = policy.ema_model.encoder({STATE: batch[TRAJ].flatten(0, 1)}).reshape(b, cfg.obs_traj_len, -1)

    hind, reached = slice(0, b), slice(b, b + n)
    assert_close(gc.obs[hind], l_obs)
    assert_close(gc.goal[hind], l_goal)
    assert_close(gc.distance[hind], batch[DIST] / cfg.max_goal_distance)
    assert torch.equal(gc.actions[hind], batch["action"])
    assert_close(gc.obs_traj[hind], traj)

    assert_close(gc.obs[reached], l_obs[:n])
    assert_close(gc.goal[reached], l_obs[:n])  # g := o
    assert torch.equal(gc.distance[reached], torch.zeros(n))
    assert torch.equal(
        gc.actions[reached], batch["action"][:n, :1].expand(-1, cfg.action_traj_len, -1)
    )  # hold a_k
    assert_close(gc.obs_traj[reached], traj[:n, :1].expand(-1, cfg.obs_traj_len, -1))  # nothing moves

    assert gc.obs.shape[0] == 2 * b + n and free.obs.shape[0] == b + n
    for field in ("obs", "goal", "distance", "actions", "obs_traj"):
        assert torch.equal(getattr(free, field), getattr(gc, field)[: b + n]), field
    assert not gc.obs_traj.requires_grad and gc.obs.requires_grad and gc.goal.requires_grad


def test_reached_rows_rest_for_velocity_commands():
    """Velocity commands stop at the goal: reached rows carry the normalised zero command, not a_k."""
    cfg = state_config("efm_ac", action_mode="velocity", reached_augment_size=3)
    rest = torch.tensor([0.25, -0.5])
    model = make_agent(cfg, rest_action=rest)
    batch = hand_batch(cfg, 5)
    rows = model.training_rows(batch, model).goal_conditioned
    assert torch.equal(rows.actions[5:8], rest.expand(3, cfg.action_traj_len, 2))
    assert torch.equal(rows.distance[5:8], torch.zeros(3))


# Table I, training column: what each component is conditioned on and regresses to. "gc": rows with goals
# (hindsight + reached + eq. 5), "free": rows without the eq. (5) duplicates; "d" is the distance column.
TABLE_I = {
    "efm_gc": {"actor": ("gc", ["obs", "goal"], "actions")},
    "efm_ac": {
        "critic": ("gc", ["obs", "goal"], "distance"),
        "actor": ("gc", ["obs", "goal", "d"], "actions"),
    },
    "efm_pc": {
        "critic": ("gc", ["obs", "goal"], "distance"),
        "planner": ("gc", ["obs", "goal", "d"], "obs_traj"),
        "actor": ("free", ["obs", "obs_traj"], "actions"),
    },
    "efm_ps": {
        "critic": ("gc", ["obs", "goal"], "distance"),
        "planner": ("free", ["obs"], "obs_traj"),
        "actor": ("free", ["obs", "obs_traj"], "actions"),
    },
    "efm_as": {
        "critic": ("gc", ["obs", "goal"], "distance"),
        "actor": ("free", ["obs"], "actions"),
        "world": ("free", ["obs", "actions"], "obs_traj"),
    },
}


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_each_component_trains_on_its_table_i_conditioning(policy_type):
    """Fails if an actor/planner/world is conditioned on the wrong latents (e.g. the goal replaced by the
    observation), regresses to the wrong target, or a goal-free model sees the eq. (5) rows."""
    policy = make(policy_type, use_rl=policy_type != "efm_gc")
    agent = policy.model
    rows = agent.training_rows(hand_batch(policy.config, 4), policy.ema_model)
    seen = {}
    for name in TABLE_I[policy_type]:

        def record(cond, target, _name=name):
            seen[_name] = (cond, target)
            return cond.sum() * 0

        getattr(agent, name).loss = record
    losses = agent.losses(rows)
    assert set(losses) == set(TABLE_I[policy_type])
    for name, (which, cond_parts, target_field) in TABLE_I[policy_type].items():
        r = rows.goal_conditioned if which == "gc" else rows.goal_free
        parts = {
            "obs": r.obs,
            "goal": r.goal,
            "d": r.distance[:, None],
            "actions": r.actions.flatten(1),
            "obs_traj": None if r.obs_traj is None else r.obs_traj.flatten(1),
        }
        cond, target = seen[name]
        assert torch.equal(cond, torch.cat([parts[p] for p in cond_parts], -1)), name
        assert torch.equal(target, getattr(r, target_field)), name


PLAN_MODELS = {"efm_pc": "planner", "efm_ps": "planner", "efm_as": "world"}


@pytest.mark.parametrize("policy_type", list(PLAN_MODELS))
def test_obs_traj_relative_learns_displacements_and_plans_from_the_observation(policy_type):
    """With ``obs_traj_relative`` the Planner / World model regresses tau^o - tau^o[0] (the actor still sees
    absolute latents) and a sample s becomes the plan o + s. Fails if the target stays absolute, is taken
    from another frame, or the observation is not added back (or added twice) at inference."""
    name = PLAN_MODELS[policy_type]
    policy = make(policy_type, obs_traj_relative=True, num_candidates=2)
    agent, cfg = policy.model, policy.config
    rows = agent.training_rows(hand_batch(cfg, 4), policy.ema_model)
    seen = {}

    def record(cond, target, _name):
        seen[_name] = (cond, target)
        return cond.sum() * 0

    for component in TABLE_I[policy_type]:
        getattr(agent, component).loss = lambda c, t, _n=component: record(c, t, _n)
    agent.losses(rows)
    r = rows.goal_conditioned if policy_type == "efm_pc" else rows.goal_free
    assert torch.equal(seen[name][1], r.obs_traj - r.obs_traj[:, :1])
    assert not torch.equal(seen[name][1], r.obs_traj)
    if "actor" in seen and policy_type != "efm_as":
        assert torch.equal(seen["actor"][0], torch.cat([r.obs, r.obs_traj.flatten(1)], -1))

    ema = policy.ema_model
    step = torch.tensor([0.1, -0.2])
    displacement = step * torch.arange(cfg.obs_traj_len).reshape(1, -1, 1)
    getattr(ema, name).sample = lambda cond, steps: displacement.expand(cond.shape[0], -1, -1).clone()
    obs = torch.tensor([[0.3, 0.4], [-0.5, 0.6]])
    out = ema.predict({STATE: obs, GOAL: -obs})
    assert_close(out["obs_plan"], obs[:, None] + displacement)


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_total_loss_weights_the_critic_only(policy_type):
    """total = critic_loss_weight * L_critic + the other losses. Fails if the weight is dropped or applied
    to another component."""
    policy = make(policy_type, critic_loss_weight=0.25, use_rl=policy_type != "efm_gc")
    agent = policy.model
    values = {name: torch.tensor(float(2 + i)) for i, name in enumerate(TABLE_I[policy_type])}
    agent.losses = lambda rows: dict(values)
    total, info = agent.compute_loss(hand_batch(policy.config, 4), policy.ema_model)
    expected = sum(0.25 * v if k == "critic" else v for k, v in values.items())
    assert total.item() == pytest.approx(expected.item())
    assert {k: info[f"loss_{k}"] for k in values} == {k: v.item() for k, v in values.items()}


# --------------------------------------------------------------------------------------------------
# 4. FM-PS / FM-AS: per-row candidate selection
# --------------------------------------------------------------------------------------------------

# Three rows, four candidates ending at obs + OFFSETS[j]; each row's goal is closest to another candidate,
# so a batch-wide argmin, or scoring a row against another row's goal, picks a wrong one.
ROW_OBS = torch.tensor([[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]])
OFFSETS = torch.tensor([[1.0, 0.0], [0.0, 1.0], [-1.0, 0.0], [0.0, -1.0]])
BEST = torch.tensor([2, 1, 3])
ROW_GOALS = ROW_OBS + 0.8 * OFFSETS[BEST]


def candidate_ids(obs_rep):
    """Row and candidate number of each repeated observation (independent of the repetition order)."""
    rows = (obs_rep[:, None] == ROW_OBS[None]).all(-1).float().argmax(1)
    counts, cand = {}, []
    for r in rows.tolist():
        cand.append(counts.get(r, 0))
        counts[r] = cand[-1] + 1
    return rows, torch.tensor(cand)


def path(start, end, length):
    w = torch.linspace(0, 1, length).reshape(1, -1, 1)
    return start[:, None] * (1 - w) + end[:, None] * w


def stub_critic(agent):
    agent.critic_distance = lambda obs, goal: (obs - goal).norm(dim=-1)


def test_fm_ps_selects_each_rows_plan_against_its_own_goal_and_acts_on_it():
    """Fails on a batch-wide argmin, on candidates scored against another row's goal, or if the actor
    acts on another plan than the chosen one."""
    policy = make("efm_ps", num_candidates=4)
    agent, cfg = policy.ema_model, policy.config

    def planner(cond, steps):
        rows, cand = candidate_ids(cond)
        return path(ROW_OBS[rows], ROW_OBS[rows] + OFFSETS[cand], cfg.obs_traj_len)

    actor_cond = []

    def actor(cond, steps):
        actor_cond.append(cond)
        return torch.zeros(cond.shape[0], cfg.action_traj_len, 2)

    agent.planner.sample, agent.actor.sample = planner, actor
    stub_critic(agent)
    out = agent.predict({STATE: ROW_OBS, GOAL: ROW_GOALS})
    assert torch.equal(out["chosen_candidate"], BEST)
    chosen = path(ROW_OBS, ROW_OBS + OFFSETS[BEST], cfg.obs_traj_len)
    assert_close(out["obs_plan"], chosen)
    assert_close(out["distance"], torch.full((3,), 0.2 * cfg.max_goal_distance))
    assert_close(actor_cond[0], torch.cat([ROW_OBS, chosen.flatten(1)], -1))


def test_fm_as_selects_each_rows_chunk_against_its_own_goal():
    """Fails on a batch-wide argmin, on candidates scored against another row's goal, or if the returned
    chunk or predicted future is not the chosen candidate's."""
    policy = make("efm_as", num_candidates=4)
    agent, cfg = policy.ema_model, policy.config

    def actor(cond, steps):  # candidate j of a row moves towards obs + OFFSETS[j]
        rows, cand = candidate_ids(cond)
        return path(ROW_OBS[rows], ROW_OBS[rows] + OFFSETS[cand], cfg.action_traj_len)

    def world(cond, steps):  # absolute commands: the point ends where the chunk ends
        obs, chunk = cond[:, :2], cond[:, 2:].reshape(cond.shape[0], cfg.action_traj_len, 2)
        return path(obs, chunk[:, -1], cfg.obs_traj_len)

    agent.actor.sample, agent.world.sample = actor, world
    stub_critic(agent)
    out = agent.predict({STATE: ROW_OBS, GOAL: ROW_GOALS})
    assert torch.equal(out["chosen_candidate"], BEST)
    assert_close(out["action"], path(ROW_OBS, ROW_OBS + OFFSETS[BEST], cfg.action_traj_len))
    assert_close(out["obs_plan"], path(ROW_OBS, ROW_OBS + OFFSETS[BEST], cfg.obs_traj_len))
    assert_close(out["distance"], torch.full((3,), 0.2 * cfg.max_goal_distance))


# --------------------------------------------------------------------------------------------------
# 5. The goal matters
# --------------------------------------------------------------------------------------------------


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_two_goals_give_two_chunks(policy_type):
    """Same seed, same observations, two goals: different chunks (and, with a critic, different distances
    on every row). Fails if inference conditions on the observation in place of the goal."""
    policy = make(policy_type, num_candidates=16)
    policy.eval()
    batch = hand_batch(policy.config, 6)

    def act(goal):
        torch.manual_seed(11)
        chunk = policy.predict_action_chunk({STATE: batch[STATE], GOAL: goal})
        return chunk, policy.last_prediction

    (c1, p1), (c2, p2) = act(batch[GOAL]), act(-batch[GOAL])
    assert not torch.allclose(c1, c2)
    if policy_type != "efm_gc":
        assert ((p1["distance"] - p2["distance"]).abs() > 1e-6).all()


@pytest.mark.parametrize("policy_type", ["efm_ac", "efm_pc"])
def test_goal_conditions_the_actor_or_planner_beyond_the_distance(policy_type):
    """With the critic's answer pinned, the goal must still change the chunk: FM-AC's actor and FM-PC's
    planner read (o, g, d), not only d. Fails if their goal latent is replaced by the observation's."""
    policy = make(policy_type)
    policy.eval()
    policy.ema_model.critic_distance = lambda obs, goal: torch.full((obs.shape[0],), 0.3)
    batch = hand_batch(policy.config, 4)

    def act(goal):
        torch.manual_seed(11)
        return policy.predict_action_chunk({STATE: batch[STATE], GOAL: goal})

    assert not torch.allclose(act(batch[GOAL]), act(-batch[GOAL]))


@pytest.mark.parametrize("policy_type", ["efm_ac", "efm_pc"])
def test_actor_distance_scale_conditions_on_that_fraction_of_the_critics_distance(policy_type):
    """FM-AC's actor / FM-PC's planner read actor_distance_scale * d~ while the reported distance stays d~.
    Fails if the scale is ignored, applied twice, or leaks into the distance the goal sequencer reads."""
    policy = make(policy_type, actor_distance_scale=0.5)
    policy.eval()
    agent = policy.ema_model
    agent.critic_distance = lambda obs, goal: torch.full((obs.shape[0],), 0.8)
    flow = agent.actor if policy_type == "efm_ac" else agent.planner
    sample, conditions = flow.sample, []
    flow.sample = lambda cond, steps: (conditions.append(cond[:, -1].clone()), sample(cond, steps))[1]
    batch = hand_batch(policy.config, 3)
    policy.predict_action_chunk({STATE: batch[STATE], GOAL: batch[GOAL]})
    assert_close(conditions[0], torch.full((3,), 0.4))
    assert_close(policy.last_prediction["distance"], torch.full((3,), 0.8 * policy.config.max_goal_distance))
    with pytest.raises(ValueError, match="actor_distance_scale=0.0"):
        state_config(policy_type, actor_distance_scale=0.0)


@pytest.mark.parametrize("policy_type", CRITIC_TYPES)
def test_acting_queries_the_critic_with_the_inference_solver_and_steps(policy_type):
    """Every critic query when acting (FM-AC / FM-PC conditioning, FM-PS / FM-AS scores) integrates with
    critic_inference_solver and critic_inference_steps; the defaults are the paper's Euler with
    num_inference_steps. Fails if an agent's act() bypasses them."""
    policy = make(policy_type, critic_inference_solver="heun", critic_inference_steps=3)
    policy.eval()
    critic, calls = policy.ema_model.critic, []
    query = critic.query

    def recording_query(cond, eps, steps, solver="euler"):
        calls.append((steps, solver))
        return query(cond, eps, steps, solver)

    critic.query = recording_query
    batch = hand_batch(policy.config, 2)
    policy.predict_action_chunk({STATE: batch[STATE], GOAL: batch[GOAL]})
    assert calls and set(calls) == {(3, "heun")}, calls
    calls.clear()
    cfg = policy.ema_model.config  # the acting EMA agent's (a copy)
    cfg.critic_inference_solver, cfg.critic_inference_steps = "euler", None
    policy.predict_action_chunk({STATE: batch[STATE], GOAL: batch[GOAL]})
    assert calls and set(calls) == {(cfg.num_inference_steps, "euler")}, calls
    with pytest.raises(ValueError, match="critic_inference_solver='rk4'"):
        state_config(policy_type, critic_inference_solver="rk4")
    with pytest.raises(ValueError, match="critic_inference_steps=0"):
        state_config(policy_type, critic_inference_steps=0)


def _spearman(a, b):
    ra, rb = a.argsort().argsort().double(), b.argsort().argsort().double()
    ra, rb = ra - ra.mean(), rb - rb.mean()
    return float((ra * rb).sum() / (ra.norm() * rb.norm()))


def test_fm_ac_learns_to_head_for_held_out_goals():
    """A few hundred updates on hindsight-relabelled play of a 2-D point (open square, absolute position
    commands, the PointReach operator): for held-out (o, g) pairs the first chunk heads towards g and the
    critic's distance rank-correlates with the path length (the straight-line distance here). Fails if
    the goal does not reach the actor or critic in training or inference."""
    from lerobot_efm.synthetic import play_episode

    rng = np.random.default_rng(0)
    episodes = [play_episode(rng, 200, wall=False) for _ in range(20)]
    states = torch.tensor(np.stack([s for s, _ in episodes]), dtype=torch.float32)
    commands = torch.tensor(np.stack([a for _, a in episodes]), dtype=torch.float32)
    policy = make(
        "efm_ac", ema_cutoff=20.0, ema_warmup_updates=10, num_inference_steps=5, mlp_hidden_dims=(64, 64)
    )
    cfg = policy.config
    n_ep, length, _ = states.shape
    g = torch.Generator().manual_seed(1)

    def sample(n):
        """Hindsight relabelling as lerobot_efm.hindsight does it: d ~ U{0..min(L_g, left)}, actions held past d."""
        ep = torch.randint(0, n_ep, (n,), generator=g)
        k = torch.randint(0, length - cfg.trajectory_window, (n,), generator=g)
        d = (
            (torch.rand(n, generator=g) * (torch.clamp(length - 1 - k, max=cfg.max_goal_distance) + 1))
            .floor()
            .long()
        )
        offsets = torch.minimum(torch.arange(cfg.action_traj_len)[None], d[:, None])
        actions = commands[ep[:, None], k[:, None] + offsets]
        return {STATE: states[ep, k], GOAL: states[ep, k + d], DIST: d.float(), "action": actions}

    optimizer = torch.optim.Adam(policy.get_optim_params(), lr=2e-3)
    policy.train()
    for _ in range(300):
        loss, _ = policy.forward(sample(32))
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        policy.update()

    policy.eval()
    test_rng = np.random.default_rng(5)
    obs, goals = [], []
    while len(obs) < 48:  # held out: random pairs, not dataset frames
        o = test_rng.uniform(-0.8, 0.8, 2)
        angle, dist = test_rng.uniform(0, 2 * np.pi), test_rng.uniform(0.15, 0.9)
        goal = o + dist * np.array([np.cos(angle), np.sin(angle)])
        if np.all(np.abs(goal) < 0.9):
            obs.append(o)
            goals.append(goal)
    obs, goals = (
        torch.tensor(np.array(obs), dtype=torch.float32),
        torch.tensor(np.array(goals), dtype=torch.float32),
    )
    torch.manual_seed(3)
    chunk = policy.predict_action_chunk({STATE: obs, GOAL: goals})
    heading = torch.nn.functional.cosine_similarity(chunk[:, -1] - obs, goals - obs, dim=-1)
    assert (heading > 0).float().mean() >= 0.75 and heading.mean() >= 0.4, heading
    assert _spearman(policy.last_prediction["distance"], (goals - obs).norm(dim=-1)) >= 0.6


# --------------------------------------------------------------------------------------------------
# 6. Processor: mirrored keys use the statistics of the observation they mirror
# --------------------------------------------------------------------------------------------------


def test_processor_normalises_mirrors_with_the_observation_stats(tmp_path):
    """goal / RL goal / trajectory state keys are min-max normalised with observation.state's statistics,
    observation.goal_distance stays in raw steps, camera keys (and their mirrors) are untouched; the same
    after saving and reloading the processor. Fails if a mirror family lacks its statistics (it would pass
    through raw) or uses other statistics."""
    image = PolicyFeature(type=FeatureType.VISUAL, shape=(3, 8, 8))
    cfg = state_config(
        "efm_pc",
        use_rl=True,
        device="cpu",
        input_features={STATE: PolicyFeature(type=FeatureType.STATE, shape=(2,)), IMAGE: image},
    )
    lo, hi = torch.tensor([-2.0, 0.0]), torch.tensor([2.0, 10.0])
    stats = {
        STATE: {"min": lo, "max": hi, "mean": torch.zeros(2), "std": torch.ones(2)},
        IMAGE: {
            "min": torch.zeros(3, 1, 1),
            "max": torch.ones(3, 1, 1),
            "mean": torch.full((3, 1, 1), 0.5),
            "std": torch.full((3, 1, 1), 0.2),
        },
        "action": {"min": -torch.ones(2), "max": torch.ones(2), "mean": torch.zeros(2), "std": torch.ones(2)},
    }
    pre, post = make_pre_post_processors(cfg, dataset_stats=stats)
    g = torch.Generator().manual_seed(0)
    raw_state = lambda *shape: lo + (hi - lo) * torch.rand(*shape, 2, generator=g)  # noqa: E731
    batch = {
        STATE: raw_state(3),
        GOAL: raw_state(3),
        RL_GOAL: raw_state(3),
        TRAJ: raw_state(3, cfg.obs_traj_len),
        DIST: torch.tensor([5.0, 17.0, 33.0]),
        "action": torch.zeros(3, cfg.action_traj_len, 2),
    }
    for prefix in ("observation.", "observation.goal.", "observation.rl_goal."):
        batch[prefix + "images.top"] = torch.rand(3, 3, 8, 8, generator=g)
    batch["observation.traj.images.top"] = torch.rand(3, cfg.obs_traj_len, 3, 8, 8, generator=g)

    def check(out):
        for key in (STATE, GOAL, RL_GOAL, TRAJ):
            assert_close(out[key], 2 * (batch[key] - lo) / (hi - lo) - 1, msg=key)
        assert torch.equal(out[DIST], batch[DIST])
        for key in [k for k in batch if "images" in k]:
            assert torch.equal(out[key], batch[key]), key

    check(pre({k: v.clone() for k, v in batch.items()}))
    pre.save_pretrained(tmp_path)
    post.save_pretrained(tmp_path)
    reloaded, _ = make_pre_post_processors(cfg, pretrained_path=str(tmp_path))
    check(reloaded({k: v.clone() for k, v in batch.items()}))


# --------------------------------------------------------------------------------------------------
# actor_encoder_gradients: which losses train the encoder
# --------------------------------------------------------------------------------------------------


def _encoder_gradients_by_loss(policy):
    """{loss name: does it reach the encoder's parameters?} for one training batch through compute_loss."""
    agent, captured = policy.model, {}
    losses = agent.losses
    agent.losses = lambda rows: captured.update(losses(rows)) or captured
    agent.compute_loss(hand_batch(policy.config, 6), policy.ema_model)
    params = list(agent.encoder.parameters())
    reached = {}
    for name, loss in captured.items():
        grads = torch.autograd.grad(loss, params, retain_graph=True, allow_unused=True)
        reached[name] = any(g is not None and g.abs().sum() > 0 for g in grads)
    return reached


@pytest.mark.parametrize("policy_type", CRITIC_TYPES)
def test_without_actor_encoder_gradients_only_the_critic_trains_the_encoder(policy_type):
    """``actor_encoder_gradients=False``: actor / planner / world losses leave the encoder alone, the critic's
    trains it. Fails if a component's latents are not detached, or if the critic's are."""
    torch.manual_seed(0)
    reference = _encoder_gradients_by_loss(make(policy_type, state_encoder="mlp"))
    assert all(reference.values()), reference  # the reference: every loss trains the encoder
    detached = _encoder_gradients_by_loss(
        make(policy_type, state_encoder="mlp", actor_encoder_gradients=False)
    )
    assert detached == {name: name == "critic" for name in reference}, detached


def test_fm_gc_without_actor_encoder_gradients_needs_another_encoder_loss():
    with pytest.raises(ValueError, match="actor_encoder_gradients=False"):
        state_config("efm_gc", actor_encoder_gradients=False)
    state_config("efm_gc", actor_encoder_gradients=False, auxiliary_state_key="observation.environment_state")
