"""PointReach env: dynamics, tasks, and the LeRobot factory/preprocessing path to policy keys."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env, make_env_config
from lerobot.envs.utils import env_to_policy_features, preprocess_observation

from lerobot_efm.envs import POINT_REACH_GYM_ID, PointReachEnv, PointReachEnvConfig
from lerobot_efm.envs.point_reach import (
    MAX_STEP,
    TASKS,
    WALL_HALF_WIDTH,
    WALL_TOP,
    in_wall,
    move_point,
    render_scene,
)


def _policy_obs(cfg, vec, obs):
    """What lerobot_eval.rollout hands to the policy preprocessor."""
    batch = preprocess_observation(obs)
    batch["task"] = list(vec.call("task_description"))
    env_pre, _ = cfg.get_env_processors()
    return {k: v for k, v in env_pre(batch).items() if k.startswith("observation.")}


def test_config_registered_and_features():
    cfg = make_env_config("efm_point_reach", task="around_wall")
    assert isinstance(cfg, PointReachEnvConfig)
    assert EnvConfig.get_choice_class("efm_point_reach") is PointReachEnvConfig
    assert cfg.type == "efm_point_reach" and cfg.gym_id == POINT_REACH_GYM_ID == "lerobot_efm/PointReach-v0"
    assert (cfg.fps, cfg.episode_length, cfg.obs_type) == (20, 200, "state")
    assert POINT_REACH_GYM_ID in gym.registry
    feats = env_to_policy_features(cfg)
    assert set(feats) == {"action", "observation.state", "observation.goal.state"}
    img_feats = env_to_policy_features(PointReachEnvConfig(obs_type="pixels_state", image_size=32))
    assert img_feats["observation.images.top"].shape == (3, 32, 32)
    assert img_feats["observation.goal.images.top"].shape == (3, 32, 32)


def test_factory_state_keys():
    cfg = PointReachEnvConfig()
    vec = make_env(cfg, n_envs=2)[cfg.type][0]
    try:
        assert isinstance(vec, gym.vector.SyncVectorEnv)
        obs, _ = vec.reset(seed=[0, 1])
        obs, _, _, _, info = vec.step(obs["goal.state"])
        batch = _policy_obs(cfg, vec, obs)
        assert set(batch) == {"observation.state", "observation.goal.state"}
        for v in batch.values():
            assert v.shape == (2, 2) and v.dtype == torch.float32
        assert "is_success" in info
        assert vec.call("_max_episode_steps") == (200, 200)
        assert vec.metadata["render_fps"] == 20
    finally:
        vec.close()


def test_factory_pixel_keys_and_goal_image():
    cfg = PointReachEnvConfig(obs_type="pixels_state", image_size=32, task="short")
    vec = make_env(cfg, n_envs=2)[cfg.type][0]
    try:
        obs, _ = vec.reset(seed=[3, 4], options={"start": [0.5, 0.5], "goal": [0.5, 0.5]})
        batch = _policy_obs(cfg, vec, obs)
        assert set(batch) == {
            "observation.state",
            "observation.goal.state",
            "observation.images.top",
            "observation.goal.images.top",
        }
        img, goal_img = batch["observation.images.top"], batch["observation.goal.images.top"]
        assert img.shape == goal_img.shape == (2, 3, 32, 32) and goal_img.dtype == torch.float32
        assert 0.0 <= float(goal_img.min()) and float(goal_img.max()) <= 1.0
        torch.testing.assert_close(img, goal_img)  # point at the goal: same picture
        obs, *_ = vec.step(np.array([[-0.5, 0.9], [0.9, 0.9]], dtype=np.float32))
        batch = _policy_obs(cfg, vec, obs)
        assert not torch.equal(batch["observation.images.top"], batch["observation.goal.images.top"])
    finally:
        vec.close()


def test_wall_blocks_and_gap_allows_crossing():
    env = PointReachEnv(task="around_wall")
    obs, _ = env.reset(seed=0, options={"start": [-0.3, -0.5], "goal": [0.3, -0.5]})
    for _ in range(40):  # push straight into the wall
        obs, *_ = env.step(np.array([0.3, -0.5]))
    np.testing.assert_allclose(obs["agent_pos"], [-WALL_HALF_WIDTH, -0.5], atol=1e-6)
    env.reset(seed=0, options={"start": [-0.3, 0.7], "goal": [0.3, 0.7]})
    for _ in range(20):
        _, _, terminated, _, info = env.step(np.array([0.3, 0.7]))
        if terminated:
            break
    assert info["is_success"] and terminated


def test_no_tunnelling_random_moves():
    rng = np.random.default_rng(0)
    p = np.array([-0.5, -0.5])
    for _ in range(5000):
        cmd = rng.uniform(-1, 1, 2) if rng.random() < 0.5 else p + rng.normal(0, 0.1, 2)
        q = move_point(p, cmd)
        assert np.linalg.norm(q - p) <= MAX_STEP + 1e-9 and np.all(np.abs(q) <= 1.0)
        assert not in_wall(q)
        if q[0] * p[0] < 0:  # crossed x = 0: only allowed above the wall
            assert min(p[1], q[1]) >= WALL_TOP
        p = q


def test_success_flag_and_truncation():
    env = gym.make(POINT_REACH_GYM_ID, max_episode_steps=5)
    obs, info = env.reset(seed=1, options={"start": [0.5, 0.5], "goal": [0.52, 0.5]})
    assert info["is_success"]  # already within the radius
    obs, reward, terminated, truncated, info = env.step(obs["goal.state"])
    assert info["is_success"] and terminated and reward == 1.0 and not truncated
    env.reset(seed=1, options={"start": [-0.8, -0.8], "goal": [0.8, 0.8]})
    for _ in range(5):
        _, _, terminated, truncated, info = env.step(np.array([-0.8, -0.8]))
    assert truncated and not terminated and not info["is_success"]


def test_nan_action_raises():
    env = PointReachEnv()
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="action"):
        env.step(np.zeros(3))


@pytest.mark.parametrize("task", sorted(TASKS))
def test_named_tasks(task):
    env = gym.make(POINT_REACH_GYM_ID, task=task)
    assert env.unwrapped.task == task and env.unwrapped.task_description
    for seed in range(10):
        obs, info = env.reset(seed=seed)
        start, goal = obs["agent_pos"], obs["goal.state"]
        assert not in_wall(start) and not in_wall(goal) and np.all(np.abs(goal) <= 1)
        assert np.linalg.norm(start - goal) >= 0.5 and not info["is_success"]
        if task == "around_wall":
            assert start[0] < 0 < goal[0] and max(start[1], goal[1]) < WALL_TOP
    obs2, _ = env.reset(seed=9)
    np.testing.assert_array_equal(obs2["goal.state"], goal)  # seeded resets are reproducible


def test_unknown_task_lists_valid_ones():
    with pytest.raises(ValueError, match="around_wall"):
        PointReachEnv(task="nope")
    with pytest.raises(ValueError, match="random"):
        PointReachEnvConfig(task="nope")
    with pytest.raises(ValueError, match="pixels_state"):
        PointReachEnvConfig(obs_type="rgb")


def test_render_and_env_checker():
    from gymnasium.utils.env_checker import check_env

    env = PointReachEnv(obs_type="pixels_state", image_size=32)
    check_env(env, skip_render_check=True)
    env.reset(seed=0)
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
    assert env.metadata["render_fps"] == 20
    img = render_scene([0.0, 0.8], 32)
    assert img.shape == (32, 32, 3) and img.dtype == np.uint8
