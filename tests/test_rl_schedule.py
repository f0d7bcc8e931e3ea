"""The RL warm-up and ramp options: no eq. (5) rows before ``rl_warmup_steps`` updates, then a linear ramp of
their number to the batch size over ``rl_ramp_steps``; the defaults (0, 0) are the paper's setting."""

import pytest
import torch
from conftest import tiny_config
from lerobot.policies.factory import make_policy, make_pre_post_processors
from torch.utils.data import DataLoader

from lerobot_efm.hindsight import HindsightGoalDataset


def _policy_and_batch(dataset, **overrides):
    cfg = tiny_config("efm_ac", use_rl=True, **overrides)
    wrapped = HindsightGoalDataset(dataset, cfg)
    policy = make_policy(cfg, ds_meta=wrapped.meta)
    pre, _ = make_pre_post_processors(cfg, dataset_stats=wrapped.meta.stats)
    return policy, pre(next(iter(DataLoader(wrapped, batch_size=8, shuffle=True))))


def test_schedule_counts():
    from lerobot_efm.agents import make_agent

    model = make_agent(
        _with_features(tiny_config("efm_ac", use_rl=True, rl_warmup_steps=10, rl_ramp_steps=4))
    )
    counts = [model.num_bootstrap_rows(8, s) for s in (0, 9, 10, 11, 12, 13, 14, 100)]
    assert counts == [0, 0, 2, 4, 6, 8, 8, 8]
    assert model.num_bootstrap_rows(8, None) == 8  # outside a training loop: fully on
    paper = make_agent(_with_features(tiny_config("efm_ac", use_rl=True)))
    assert [paper.num_bootstrap_rows(8, s) for s in (0, 1, 5000)] == [8, 8, 8]
    no_rl = make_agent(_with_features(tiny_config("efm_ac", rl_warmup_steps=0)))
    assert no_rl.num_bootstrap_rows(8, 10_000) == 0


def _with_features(cfg):
    from lerobot.configs.types import FeatureType, PolicyFeature

    cfg.input_features = {"observation.state": PolicyFeature(FeatureType.STATE, (2,))}
    cfg.output_features = {"action": PolicyFeature(FeatureType.ACTION, (2,))}
    return cfg


def test_policy_forward_follows_the_update_counter(state_dataset):
    """EFMPolicy.forward reads its EMA update counter: rows grow from batch + reached to + all bootstrap rows."""
    policy, batch = _policy_and_batch(state_dataset, rl_warmup_steps=2, rl_ramp_steps=2)
    rows = []
    for _ in range(5):
        _, info = policy.forward(batch)
        rows.append((info["rows"], info["rl_rows"], "rl_target_distance" in info))
        policy.update()
    base = 8 + 4  # batch + reached rows (tiny config: reached_augment_size=4)
    assert rows == [
        (base, 0, False),
        (base, 0, False),
        (base + 4, 4, True),
        (base + 8, 8, True),
        (base + 8, 8, True),
    ]


def test_bootstrap_targets_are_capped(state_dataset, monkeypatch):
    """rl_target_cap bounds eq. 5's target d + bridge (units of max_goal_distance); None leaves it as it is."""
    policy, batch = _policy_and_batch(state_dataset, rl_target_cap=1.5)
    critic = policy.ema_model.critic
    monkeypatch.setattr(critic, "query", lambda cond, eps, *_: torch.full((eps.shape[0], cond.shape[0]), 5.0))
    capped = policy.model.training_rows(batch, policy.ema_model).goal_conditioned.distance[-8:]
    assert torch.all(capped == 1.5)
    policy.config.rl_target_cap = None
    uncapped = policy.model.training_rows(batch, policy.ema_model).goal_conditioned.distance[-8:]
    assert torch.all(uncapped >= 5.0)


def test_bootstrap_bridges_are_floored(state_dataset, monkeypatch):
    """rl_bridge_floor keeps a negative (extrapolated) bridge from lowering eq. 5's target below d; None keeps
    the paper's unbounded sum."""
    policy, batch = _policy_and_batch(state_dataset, rl_bridge_floor=0.0)
    critic = policy.ema_model.critic
    monkeypatch.setattr(
        critic, "query", lambda cond, eps, *_: torch.full((eps.shape[0], cond.shape[0]), -2.0)
    )
    d = batch["observation.goal_distance"].float()[:8] / policy.config.max_goal_distance
    floored = policy.model.training_rows(batch, policy.ema_model).goal_conditioned.distance[-8:]
    torch.testing.assert_close(floored, d)
    policy.config.rl_bridge_floor = None
    unbounded = policy.model.training_rows(batch, policy.ema_model).goal_conditioned.distance[-8:]
    torch.testing.assert_close(unbounded, d - 2.0)


def test_invalid_schedule_is_rejected():
    with pytest.raises(ValueError, match="rl_target_cap=0"):
        tiny_config("efm_ac", use_rl=True, rl_target_cap=0.0)
    with pytest.raises(ValueError, match="rl_bridge_floor=-0.5"):
        tiny_config("efm_ac", use_rl=True, rl_bridge_floor=-0.5)
    with pytest.raises(ValueError, match="rl_warmup_steps=-1"):
        tiny_config("efm_ac", use_rl=True, rl_warmup_steps=-1)
    with pytest.raises(ValueError, match="rl_ramp_steps=-3"):
        tiny_config("efm_ac", use_rl=True, rl_ramp_steps=-3)


def test_bootstrap_rows_take_the_batch_head(state_dataset):
    """Ramped bootstrap rows are the first n rows of the batch: same observations and actions, RL goals."""
    policy, batch = _policy_and_batch(state_dataset, rl_warmup_steps=0, rl_ramp_steps=4)
    rows = policy.model.training_rows(batch, policy.ema_model, step=1).goal_conditioned  # 8 * 2/4 = 4 rows
    n, base = 4, 8 + 4
    assert rows.obs.shape[0] == base + n
    torch.testing.assert_close(rows.obs[base:], rows.obs[:n])
    torch.testing.assert_close(rows.actions[base:], batch["action"][:n])
    torch.testing.assert_close(rows.goal[base:], batch["observation.rl_goal.state"][:n])  # identity encoder


def test_bootstrap_queries_use_the_target_solver_and_steps(state_dataset, monkeypatch):
    """Eq. 5's bridge and the slack filter integrate the EMA critic with rl_target_solver and
    rl_target_inference_steps; the defaults are the paper's: Euler with num_inference_steps."""
    policy, batch = _policy_and_batch(
        state_dataset, rl_actor_slack=0.5, rl_target_solver="heun", rl_target_inference_steps=3
    )
    critic, calls = policy.ema_model.critic, []
    query = critic.query

    def recording_query(cond, eps, steps, solver="euler"):
        calls.append((steps, solver))
        return query(cond, eps, steps, solver)

    monkeypatch.setattr(critic, "query", recording_query)
    policy.model.training_rows(batch, policy.ema_model)
    assert calls == [(3, "heun"), (3, "heun")]  # bridge, then the slack filter's Critic(0 | o, g')
    calls.clear()
    policy.config.rl_target_solver, policy.config.rl_target_inference_steps = "euler", None
    policy.model.training_rows(batch, policy.ema_model)
    assert calls == [(policy.config.num_inference_steps, "euler")] * 2


def test_invalid_target_solver_is_rejected():
    with pytest.raises(ValueError, match="rl_target_solver='rk4'"):
        tiny_config("efm_ac", use_rl=True, rl_target_solver="rk4")
    with pytest.raises(ValueError, match="rl_target_inference_steps=0"):
        tiny_config("efm_ac", use_rl=True, rl_target_inference_steps=0)
