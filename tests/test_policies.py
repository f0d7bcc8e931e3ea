"""Every EFM policy: forward, select_action (receding horizon), predict_action_chunk, EMA, save/load,
candidate selection with batch > 1, and the errors users get on bad input."""

import math

import pytest
import torch
from conftest import EFM_TYPES, tiny_config
from lerobot.policies.factory import get_policy_class, make_policy, make_pre_post_processors
from torch.utils.data import DataLoader

from lerobot_efm.hindsight import HindsightGoalDataset
from lerobot_efm.modeling_efm import _to_control_rate

VARIANTS = [(t, False) for t in EFM_TYPES] + [(t, True) for t in EFM_TYPES if t != "efm_gc"]


def build(dataset, policy_type, **overrides):
    cfg = tiny_config(policy_type, **overrides)
    wrapped = HindsightGoalDataset(dataset, cfg)
    policy = make_policy(cfg, ds_meta=wrapped.meta)
    pre, post = make_pre_post_processors(cfg, dataset_stats=wrapped.meta.stats)
    batch = pre(next(iter(DataLoader(wrapped, batch_size=6, shuffle=True))))
    return policy, pre, post, batch


def inference_inputs(batch, n=2):
    keep = (
        "observation.state",
        "observation.images.top",
        "observation.goal.state",
        "observation.goal.images.top",
    )
    return {k: v[:n] for k, v in batch.items() if k in keep}


@pytest.mark.parametrize("policy_type,use_rl", VARIANTS)
def test_forward_backward_update_and_act(state_dataset, policy_type, use_rl):
    # An MLP state encoder, so that the encoder has weights whose gradients can be checked (the default
    # identity encoder has none).
    policy, _, post, batch = build(
        state_dataset, policy_type, use_rl=use_rl, state_encoder="mlp", state_latent_dim=8
    )
    loss, info = policy.forward(batch)
    assert loss.dim() == 0 and math.isfinite(loss.item())
    components = {
        "efm_gc": {"actor"},
        "efm_ac": {"critic", "actor"},
        "efm_pc": {"critic", "planner", "actor"},
        "efm_ps": {"critic", "planner", "actor"},
        "efm_as": {"critic", "actor", "world"},
    }[policy_type]
    assert {k[5:] for k in info if k.startswith("loss_")} == components
    # rows = batch + reached (+ bootstrap rows with use_rl)
    assert info["rows"] == 6 + 4 + (6 if use_rl else 0)
    loss.backward()
    encoder_params = list(policy.model.encoder.parameters())
    assert encoder_params and all(p.grad is not None and p.grad.abs().sum() > 0 for p in encoder_params)
    before = [p.clone() for p in policy.ema_model.parameters()]
    with torch.no_grad():
        for p in policy.model.parameters():
            p.add_(0.01)
    policy.update()
    assert any(not torch.equal(b, p) for b, p in zip(before, policy.ema_model.parameters(), strict=True))

    policy.eval()
    policy.reset()
    obs = inference_inputs(batch)
    chunk = policy.predict_action_chunk(obs)
    assert chunk.shape == (2, policy.config.action_traj_len, 2)
    action = policy.select_action(obs)
    assert action.shape == (2, 2) and torch.isfinite(post(action)).all()


def test_receding_horizon_replans_every_n_action_steps(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_ac", n_action_steps=3)
    policy.eval()
    calls = []
    original = policy.predict_action_chunk
    policy.predict_action_chunk = lambda b: calls.append(1) or original(b)
    obs = inference_inputs(batch)
    for _ in range(7):
        policy.select_action(obs)
    assert len(calls) == 3  # steps 0, 3, 6
    policy.reset()
    policy.select_action(obs)
    assert len(calls) == 4


def test_action_stride_interpolates_absolute_and_holds_velocity():
    chunk = torch.tensor([[[0.0], [3.0], [6.0]]])
    assert _to_control_rate(chunk, 3, "absolute").flatten().tolist() == [0, 1, 2, 3, 4, 5, 6]
    assert _to_control_rate(chunk, 2, "velocity").flatten().tolist() == [0, 0, 3, 3, 6, 6]


@pytest.mark.parametrize("policy_type", ["efm_ps", "efm_as"])
def test_rejection_sampling_picks_each_rows_best_candidate(state_dataset, policy_type):
    policy, _, _, batch = build(state_dataset, policy_type, num_candidates=7)
    policy.eval()
    obs = inference_inputs(batch, n=4)
    chunk = policy.predict_action_chunk(obs)
    pred = policy.last_prediction
    scores, index = pred["candidate_distances"], pred["chosen_candidate"]
    assert scores.shape == (4, 7)
    goals = obs["observation.goal.state"]  # identity encoder: the goal latent is the normalised goal state
    critic = policy.ema_model.critic_distance

    def score(last_obs, row):  # one candidate against its own row's goal, outside the batched code path
        return critic(last_obs[None], goals[row][None])[0]

    if policy_type == "efm_as":
        assert torch.equal(chunk, pred["candidate_actions"][torch.arange(4), index])
        for b in range(4):  # the chosen future, scored against row b's goal, is row b's best score
            assert torch.allclose(score(pred["obs_plan"][b, -1], b), scores[b].min(), atol=1e-5)
            assert scores[b, index[b]] == scores[b].min()
    else:
        plans = pred["candidate_obs_plans"]
        independent = torch.stack(
            [torch.stack([score(plans[b, j, -1], b) for j in range(7)]) for b in range(4)]
        )
        assert torch.allclose(scores, independent, atol=1e-5)
        assert torch.equal(index, independent.argmin(1))
        assert torch.equal(pred["obs_plan"], plans[torch.arange(4), index])


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_save_load_round_trip(state_dataset, tmp_path, policy_type):
    policy, _, _, batch = build(state_dataset, policy_type)
    with torch.no_grad():  # online and EMA weights must differ, or a swap or re-sync on load is invisible
        for p in policy.model.parameters():
            p.add_(0.1 * torch.randn_like(p))
    policy.update()
    policy.save_pretrained(tmp_path)
    loaded = get_policy_class(policy_type).from_pretrained(tmp_path)
    assert loaded.config.type == policy_type
    saved, restored = policy.state_dict(), loaded.state_dict()
    assert saved.keys() == restored.keys()
    for name, value in saved.items():
        assert torch.equal(value, restored[name]), name
    assert any(
        not torch.equal(restored["model." + n], restored["ema_model." + n])
        for n, _ in loaded.model.named_parameters()
    )
    obs = inference_inputs(batch)
    policy.eval()
    torch.manual_seed(3)
    expected = policy.predict_action_chunk(obs)
    torch.manual_seed(3)
    assert torch.allclose(loaded.predict_action_chunk(obs), expected)


def test_video_observations(video_dataset):
    policy, _, _, batch = build(video_dataset, "efm_pc", use_rl=True)
    assert batch["observation.traj.images.top"].shape[1:] == (3, 3, 32, 32)
    loss, _ = policy.forward(batch)
    loss.backward()
    assert policy.model.encoder.images["images__top"].head[-1].weight.grad is not None
    policy.eval()
    assert policy.select_action(inference_inputs(batch)).shape == (2, 2)


@pytest.mark.parametrize("policy_type", EFM_TYPES)
def test_policy_and_config_classes_as_lerobots_generic_test_reads_them(policy_type):
    """LeRobot's ``test_get_policy_and_config_classes`` checks the config class against the ``config``
    annotation of ``__init__``: a string annotation (``from __future__ import annotations``) makes it raise."""
    import inspect

    from lerobot.policies.factory import make_policy_config

    policy_cls = get_policy_class(policy_type)
    config = make_policy_config(policy_type)
    assert policy_cls.name == policy_type and isinstance(config, policy_cls.config_class)
    assert issubclass(
        policy_cls.config_class, inspect.signature(policy_cls.__init__).parameters["config"].annotation
    )


def test_unbatched_robot_observation_with_goal_is_batched_by_the_preprocessor(state_dataset):
    """A robot hands one unbatched observation (and its goal): the pre-processor batches the goal keys too."""
    policy, pre, post, batch = build(state_dataset, "efm_ac")
    policy.eval()
    raw = {"observation.state": torch.tensor([0.1, -0.2]), "observation.goal.state": torch.tensor([0.3, 0.4])}
    processed = pre(raw)
    assert processed["observation.goal.state"].shape == processed["observation.state"].shape == (1, 2)
    assert post(policy.select_action(processed)).shape == (1, 2)
    assert pre(dict(batch))["observation.goal.state"].shape == batch["observation.goal.state"].shape


def test_missing_goal_at_inference_names_the_key(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_ac")
    with pytest.raises(KeyError, match="observation.goal.state"):
        policy.select_action({"observation.state": batch["observation.state"][:1]})


def test_nan_input_is_refused_with_the_key(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_ac")
    batch["observation.goal.state"][0, 0] = float("nan")
    with pytest.raises(ValueError, match="observation.goal.state.*NaN"):
        policy.forward(batch)
    obs = inference_inputs(batch)
    with pytest.raises(ValueError, match="observation.goal.state"):
        policy.select_action(obs)


def test_feature_shape_mismatch_names_key_and_expected_shape(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_gc")
    obs = inference_inputs(batch)
    obs["observation.state"] = torch.zeros(2, 5)
    with pytest.raises(ValueError, match=r"observation.state.*\(5,\).*\(2,\)"):
        policy.select_action(obs)


def test_training_without_hindsight_keys_explains_the_hook(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_ac")
    plain = {k: v for k, v in batch.items() if not k.startswith("observation.goal")}
    with pytest.raises(KeyError, match="make_train_eval_datasets"):
        policy.forward(plain)


def test_action_chunk_shape_checked(state_dataset):
    policy, _, _, batch = build(state_dataset, "efm_ac")
    batch["action"] = batch["action"][:, 0]
    with pytest.raises(ValueError, match="'action'.*expected"):
        policy.forward(batch)


def test_config_contract_and_validation():
    cfg = tiny_config("efm_ac")
    for field in [
        "obs_traj_len",
        "obs_traj_stride",
        "action_traj_len",
        "action_traj_stride",
        "max_goal_distance",
        "num_inference_steps",
        "use_rl",
        "rl_goal_ratio",
        "num_candidates",
        "n_action_steps",
    ]:
        assert hasattr(cfg, field), field
    with pytest.raises(ValueError, match="use_rl"):
        tiny_config("efm_gc", use_rl=True)
    with pytest.raises(ValueError, match="action_traj_len=12.*divisible by 8"):
        tiny_config("efm_ac", action_traj_len=12)
    with pytest.raises(ValueError, match="rl_goal_ratio"):
        tiny_config("efm_ac", rl_goal_ratio=1.5)
    with pytest.raises(ValueError, match="state_encoder.*'conv'"):
        tiny_config("efm_ac", state_encoder="conv")


def test_ema_follows_reference_low_pass(state_dataset):
    policy, _, _, _ = build(state_dataset, "efm_gc", ema_cutoff=100.0, ema_warmup_updates=1)
    param, ema = next(policy.model.parameters()), next(policy.ema_model.parameters())
    with torch.no_grad():
        ema.zero_()
        param.fill_(1.0)
    policy.update()
    omega = 2 * math.pi / 100
    alpha = (1 - omega / 2) / (1 + omega / 2)  # 0.9391 for a cutoff of 100 updates
    assert torch.allclose(ema, torch.full_like(ema, 1 - alpha), atol=1e-6)


def test_velocity_reached_rows_use_the_normalised_zero_action(state_dataset):
    policy, _, _, _ = build(state_dataset, "efm_ac", action_mode="velocity")
    stats = state_dataset.meta.stats["action"]
    lo, hi = torch.as_tensor(stats["min"]).float(), torch.as_tensor(stats["max"]).float()
    expected = 2 * (0 - lo) / (hi - lo) - 1  # MIN_MAX of a raw 0 command
    assert torch.allclose(policy.model.rest_action, expected, atol=1e-5)


def test_model_card_is_lerobots_template_with_an_efm_section(state_dataset, monkeypatch):
    """push_to_hub's card: LeRobot's standard sections (from its template) plus the agent, the goal keys and the
    paper; offline (HF_HUB_OFFLINE) it is built without the Hub's validation."""
    from huggingface_hub import constants

    monkeypatch.setattr(constants, "HF_HUB_OFFLINE", True)
    policy, *_ = build(state_dataset, "efm_ac", use_rl=True)
    card = policy.generate_model_card("user/play", "efm_ac", None, ["mine"], dataset_meta=state_dataset.meta)
    text = str(card)
    for section in ("## Model Details", "## Training Dataset", "## How to Get Started with the Model"):
        assert section in text, section  # LeRobot's template
    efm = text.index("## Extremum Flow Matching: FM-AC-use-RL")
    assert efm < text.index("## Model Details") and "observation.goal.*" in text and "2505.19717" in text
    assert {"mine", "extremum-flow-matching", "lerobot", "efm_ac"} <= set(card.data.tags)
