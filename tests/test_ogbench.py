"""OGBench adapter: local pointmaze generation (raw format), LeRobot conversion, hindsight sampling, env type."""

import gymnasium as gym
import numpy as np
import pytest
import torch
from conftest import tiny_config
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env, make_env_config
from lerobot.envs.utils import env_to_policy_features, preprocess_observation

from lerobot_efm.hindsight import HindsightGoalDataset
from lerobot_efm.ogbench import OGBENCH_GYM_ID, OGBenchEnv, OGBenchEnvConfig
from lerobot_efm.ogbench.convert import convert_arrays, convert_npz, load_raw
from lerobot_efm.ogbench.generate import (
    cells_at_distance,
    evaluate_oracle,
    free_cells,
    generate_pointmaze,
    oracle_direction,
    save_pointmaze_npz,
)
from lerobot_efm.ogbench.generate import (
    main as generate_main,
)

NAV, STITCH = "pointmaze-large-navigate-v0", "pointmaze-large-stitch-v0"
STEPS = 101


@pytest.fixture(scope="module")
def raw():
    return {name: generate_pointmaze(name, 3, STEPS, seed=0) for name in (NAV, STITCH)}


@pytest.fixture(scope="module")
def maze():
    env = OGBenchEnv(NAV)
    yield env.maze
    env.close()


@pytest.mark.parametrize("name", [NAV, STITCH])
def test_raw_format(raw, maze, name):
    data = raw[name]
    n = 3 * STEPS
    assert set(data) == {"observations", "actions", "terminals", "qpos", "qvel"}
    for key in ("observations", "actions", "qpos", "qvel"):
        assert data[key].shape == (n, 2) and data[key].dtype == np.float32, key
    assert data["terminals"].dtype == bool and np.flatnonzero(data["terminals"]).tolist() == [100, 201, 302]
    assert np.all(np.abs(data["actions"]) <= 1.0) and np.abs(data["actions"]).max() == 1.0  # noisy, clipped
    np.testing.assert_array_equal(data["observations"], data["qpos"])  # point obs = qpos
    # Transitions follow the point dynamics (qpos += 0.2 * action, stopped by walls) inside episodes.
    step = np.linalg.norm(np.diff(data["observations"], axis=0), axis=1)[~data["terminals"][:-1]]
    assert step.max() <= 0.2 * np.sqrt(2) + 1e-4 and step.mean() > 0.05
    for xy in data["observations"][::7]:  # never inside a wall cell
        assert maze.maze_map[maze.xy_to_ij(xy)] == 0
    again = generate_pointmaze(name, 3, STEPS, seed=0)
    assert all(np.array_equal(again[k], data[k]) for k in data)  # seeded: reproducible
    other = generate_pointmaze(name, 1, STEPS, seed=1)
    assert not np.array_equal(other["observations"], data["observations"][:STEPS])


def test_maze_cells(maze):
    cells, vertices = free_cells(maze.maze_map)
    assert len(cells) == int((maze.maze_map == 0).sum()) and (1, 1) in vertices and len(vertices) < len(cells)
    assert (1, 2) not in vertices and (2, 1) not in vertices  # corridor cells of the large maze
    assert cells_at_distance(maze.maze_map, (1, 1), 2) == [(3, 1), (1, 3)]


def test_noise_free_stitch_reaches_a_cell_four_steps_away(maze):
    """Without noise the recipe is the pure BFS oracle: unit actions, ending in a cell 4 BFS steps away."""
    data = generate_pointmaze(STITCH, 3, 151, noise=0.0, seed=3)
    np.testing.assert_allclose(np.linalg.norm(data["actions"], axis=1), 1.0, atol=1e-3)
    for ep in data["observations"].reshape(3, 151, 2):
        start, end = maze.xy_to_ij(ep[0]), maze.xy_to_ij(ep[-1])
        assert end in cells_at_distance(maze.maze_map, start, 4), (start, end)


def test_npz_files_load_with_ogbench(tmp_path):
    import ogbench

    train_path, val_path = save_pointmaze_npz(STITCH, tmp_path, num_episodes=10, episode_steps=STEPS, seed=2)
    assert (train_path.name, val_path.name) == (f"{STITCH}.npz", f"{STITCH}-val.npz")
    _, train, val = ogbench.make_env_and_datasets(STITCH, dataset_path=str(train_path))
    assert train["observations"].shape == (10 * (STEPS - 1), 2) and val["observations"].shape == (
        STEPS - 1,
        2,
    )
    np.testing.assert_array_equal(train["next_observations"][0], train["observations"][1])


def test_convert_round_trip_and_hindsight(raw, tmp_path):
    data = raw[STITCH]
    ds = convert_arrays(data, tmp_path / "lr", "local/ogbench_test", task=STITCH)
    ds = LeRobotDataset("local/ogbench_test", root=tmp_path / "lr")
    assert ds.num_episodes == 3 and ds.num_frames == 3 * STEPS and ds.fps == 10
    assert ds.features["observation.state"]["shape"] == (2,) and ds.features["action"]["names"] == [
        "vx",
        "vy",
    ]
    states = torch.stack([ds[i]["observation.state"] for i in range(0, ds.num_frames, 50)])
    np.testing.assert_array_equal(states.numpy(), data["observations"][::50])
    assert ds[STEPS]["episode_index"] == 1 and ds[STEPS]["frame_index"] == 0 and ds[0]["task"] == STITCH

    cfg = tiny_config(
        "efm_ac", action_mode="velocity", obs_traj_len=4, obs_traj_stride=16, max_goal_distance=200
    )
    wrapped = HindsightGoalDataset(ds, cfg)
    for k in (0, 60, STEPS + 90, 3 * STEPS - 1):
        item = wrapped[k]
        d = int(item["observation.goal_distance"])
        assert item["action"].shape == (8, 2) and item["observation.goal.state"].shape == (2,)
        assert torch.all(item["action"][d:] == 0)  # velocity: no command past the goal
        torch.testing.assert_close(
            item["observation.goal.state"], torch.from_numpy(data["observations"][k + d])
        )


def test_cli_generate_and_convert(tmp_path, capsys):
    root = tmp_path / "nav"
    generate_main(
        [f"--ogbench_dataset={NAV}", "--num_episodes=2", "--episode_steps=50", f"--dataset.root={root}"]
    )
    assert "2 episodes, 100 frames" in capsys.readouterr().out
    assert LeRobotDataset(f"local/{NAV}", root=root).num_frames == 100
    ds = convert_npz(tmp_path / "nav-npz" / f"{NAV}.npz", tmp_path / "again", fps=20)
    assert ds.num_episodes == 2 and ds.fps == 20


def test_bad_npz_errors_name_the_key(tmp_path):
    np.savez(tmp_path / "nokey.npz", observations=np.zeros((4, 2)), terminals=np.ones(4, bool))
    with pytest.raises(KeyError, match=r"nokey\.npz.*'actions'"):
        load_raw(tmp_path / "nokey.npz")
    np.savez(
        tmp_path / "shape.npz",
        observations=np.zeros((4, 2)),
        actions=np.zeros((3, 2)),
        terminals=np.ones(4, bool),
    )
    with pytest.raises(ValueError, match=r"shape\.npz.*'actions'"):
        load_raw(tmp_path / "shape.npz")
    np.savez(
        tmp_path / "open.npz",
        observations=np.zeros((4, 2)),
        actions=np.zeros((4, 2)),
        terminals=np.zeros(4, bool),
    )
    with pytest.raises(ValueError, match="'terminals'"):
        load_raw(tmp_path / "open.npz")
    with pytest.raises(FileNotFoundError, match="missing.npz"):
        load_raw(tmp_path / "missing.npz")


def test_config_registered_and_features():
    cfg = make_env_config("ogbench", dataset=STITCH, task="task2")
    assert isinstance(cfg, OGBenchEnvConfig) and EnvConfig.get_choice_class("ogbench") is OGBenchEnvConfig
    assert cfg.gym_id == OGBENCH_GYM_ID and OGBENCH_GYM_ID in gym.registry and cfg.episode_length == 1000
    feats = env_to_policy_features(cfg)
    assert set(feats) == {"action", "observation.state", "observation.goal.state"}
    assert feats["observation.goal.state"].shape == (2,)


def test_bad_names_list_valid_ones():
    with pytest.raises(ValueError, match="pointmaze-large-navigate-v0"):
        OGBenchEnvConfig(dataset="pointmaze-huge-navigate-v0")
    with pytest.raises(ValueError, match="task5"):
        OGBenchEnvConfig(task="task6")
    with pytest.raises(ValueError, match="pointmaze-large-stitch-v0"):
        generate_pointmaze("antmaze-large-navigate-v0", 1, 10)


def test_make_env_keys_and_seeded_task_cycle():
    cfg = OGBenchEnvConfig(task="all")
    vec = make_env(cfg, n_envs=1)[cfg.type][0]
    try:
        obs, info = vec.reset(seed=[7])
        assert vec.call("task_id") == (3,) and "task3" in vec.call("task_description")[0]  # 7 % 5 + 1
        batch = preprocess_observation(obs)
        assert set(batch) == {"observation.state", "observation.goal.state"}
        assert (
            batch["observation.state"].shape == (1, 2) and batch["observation.state"].dtype == torch.float32
        )
        goal = obs["goal.state"].copy()
        for _ in range(5):
            obs, reward, terminated, truncated, info = vec.step(np.array([[1.0, 0.0]], np.float32))
        assert (
            "is_success" in info and not info["is_success"][0] and vec.call("_max_episode_steps") == (1000,)
        )
        np.testing.assert_array_equal(obs["goal.state"], goal)
        again, _ = vec.reset(seed=[7])  # the global-RNG noise of start/goal is reproducible
        np.testing.assert_array_equal(again["goal.state"], goal)
    finally:
        vec.close()


def test_oracle_succeeds_and_terminates():
    env = gym.make(OGBENCH_GYM_ID, task="task1")
    steps = 0
    for seed in (0, 1):
        obs, _ = env.reset(seed=seed)
        start = obs["agent_pos"].copy()
        for steps in range(1, 1001):  # noqa: B007 (read after the loop)
            obs, reward, terminated, truncated, info = env.step(
                oracle_direction(env.unwrapped.maze, exact_goal=True)
            )
            if terminated or truncated:
                break
        assert terminated and info["is_success"] and reward == 1.0 and steps < 400
        assert (
            np.linalg.norm(obs["agent_pos"] - obs["goal.state"])
            <= 1.0
            < np.linalg.norm(start - obs["goal.state"])
        )
    frame = env.render()
    assert frame.dtype == np.uint8 and frame.shape == (9 * 24, 12 * 24, 3)
    env.close()


def test_progress_reward_counts_maze_cells_closed():
    env = OGBenchEnv(NAV, task="task3", reward="progress")
    env.reset(seed=0)
    start_cells, total = env._cells_from_goal(), 0.0
    assert start_cells >= 5  # a task across the maze
    for t in range(1000):
        _, reward, terminated, _, info = env.step(oracle_direction(env.maze, exact_goal=True))
        total += reward
        if t == 40:  # partway: exactly the share of BFS cells closed so far
            assert total == pytest.approx(1 - env._cells_from_goal() / start_cells)
            assert 0 < total < 1
        if terminated:
            break
    assert info["is_success"] and total == pytest.approx(1.0)
    env.reset(seed=1)
    assert sum(env.step(np.zeros(2))[1] for _ in range(30)) == 0.0  # holding still closes nothing
    with pytest.raises(ValueError, match="progress"):
        OGBenchEnvConfig(reward="dense")
    env.close()
    reference = evaluate_oracle(NAV, episodes_per_task=1)  # the reference row of the agent tables
    assert reference == pytest.approx({"pc_success": 100.0, "pc_closed": 100.0})


def test_bad_action_raises():
    env = OGBenchEnv(NAV, task="task2")
    env.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env.step(np.array([np.nan, 0.0]))
    before = env.maze.get_xy().copy()
    env.step(np.array([5.0, 0.0]))  # clipped to 1: a 0.2 move
    assert abs(env.maze.get_xy()[0] - before[0]) <= 0.2 + 1e-6
    env.close()
