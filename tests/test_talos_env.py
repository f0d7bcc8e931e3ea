"""Talos kitchen gym env: spaces, tasks, goals, success and the LeRobot factory/preprocessing path."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import gymnasium as gym  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
import torch  # noqa: E402

pytest.importorskip("mujoco")

from gymnasium.utils.env_checker import check_env  # noqa: E402
from lerobot.envs.configs import EnvConfig  # noqa: E402
from lerobot.envs.factory import make_env  # noqa: E402
from lerobot.envs.utils import env_to_policy_features, preprocess_observation  # noqa: E402

from lerobot_efm.envs.talos_kitchen import tasks  # noqa: E402
from lerobot_efm.envs.talos_kitchen.env import (  # noqa: E402
    ENV_STATE_NAMES,
    GYM_ID,
    STATE_NAMES,
    TalosKitchenEnv,
    TalosKitchenEnvConfig,
)

SIZE = 64
POLICY_KEYS = {
    "observation.images.front": (3, SIZE, SIZE),
    "observation.state": (20,),
    "observation.environment_state": (9,),
    "observation.goal.images.front": (3, SIZE, SIZE),
    "observation.goal.state": (20,),
    "observation.goal.environment_state": (9,),
}


@pytest.fixture(scope="module")
def env():
    e = TalosKitchenEnv(task="open_door", image_size=SIZE)
    yield e
    e.close()


def _hold(obs):
    """The measured hand pose as a command (hold still)."""
    return obs["agent_pos"][10:20].copy()


def test_task_suite():
    assert len(tasks.TASK_NAMES) >= 10
    assert {"open_door", "close_door", "pull_tray", "push_tray", "move_pot_on_table"} <= set(tasks.TASKS)
    long = tasks.TASKS[tasks.LONG_TASK]  # paper Fig. 8
    # adapted to what the primitives achieve (see the tasks module docstring)
    assert (long.initial.door, long.initial.tray, long.initial.pot_on) == (
        tasks.DOOR_OPEN,
        tasks.TRAY_IN,
        "table",
    )
    assert (long.goal.door, long.goal.tray, long.goal.pot_on) == (tasks.DOOR_CLOSED, tasks.TRAY_OUT, "tray")
    for t in tasks.TASKS.values():
        assert t.initial != t.goal and t.description
    with pytest.raises(ValueError, match="open_door.*store_pot"):
        tasks.check_task("make_coffee")
    with pytest.raises(ValueError, match="valid tasks"):
        TalosKitchenEnvConfig(task="make_coffee")
    assert len(STATE_NAMES) == 20 and len(ENV_STATE_NAMES) == 9


def test_unknown_task_env_error():
    with pytest.raises(ValueError, match="valid tasks: .*'open_door'"):
        TalosKitchenEnv(task="nope")


@pytest.mark.filterwarnings("ignore::UserWarning")  # unbounded state boxes, non-normalised action box
def test_check_env(env):
    check_env(env, skip_render_check=True)
    assert env.metadata["render_fps"] == 25
    assert env.task == "open_door" and env.task_description == "open the cabinet door"
    env.reset(seed=0)
    img = env.render()
    assert img.shape == (SIZE, SIZE, 3) and img.dtype == np.uint8


def test_goal_image_state_and_success(env):
    obs, info = env.reset(seed=1)
    assert not info["is_success"]
    assert obs["agent_pos"].dtype == np.float32 and obs["agent_pos"].shape == (20,)
    np.testing.assert_allclose(obs["agent_pos"][:10], obs["agent_pos"][10:], atol=1e-5)  # command = hold
    goal_img = obs["goal.images.front"]
    assert goal_img.shape == (SIZE, SIZE, 3) and goal_img.dtype == np.uint8
    assert np.abs(goal_img.astype(int) - obs["pixels"]["front"].astype(int)).mean() > 0.5  # door moved
    # a step keeps the cached goal; holding still does not succeed
    obs2, reward, terminated, _, info = env.step(_hold(obs))
    assert not info["is_success"] and not terminated and reward == 0.0
    np.testing.assert_array_equal(obs2["goal.images.front"], goal_img)
    np.testing.assert_array_equal(obs2["goal.environment_state"], obs["goal.environment_state"])
    # the goal observations are those of the scene put in the goal state
    env.set_goal_scene()
    np.testing.assert_array_equal(env.render(), goal_img)
    obs3, reward, terminated, _, info = env.step(obs["goal.state"][:10])
    assert info["is_success"] and terminated and reward == 1.0
    np.testing.assert_allclose(obs3["environment_state"][:2], obs["goal.environment_state"][:2], atol=0.02)


def test_success_when_objects_set_to_goal_qpos():
    e = TalosKitchenEnv(task="pull_tray_load_pot", image_size=SIZE, randomize=False)
    try:
        obs, info = e.reset(seed=0)
        start, goal = obs["environment_state"], obs["goal.environment_state"]
        assert not info["is_success"]
        # the pot is placed in the tray frame: it sits on the pulled-out tray, below the table top
        np.testing.assert_allclose(goal[1] - start[1], tasks.TRAY_OUT, atol=0.01)
        from lerobot_efm.envs.talos_kitchen import scene

        np.testing.assert_allclose(
            goal[2], scene.TRAY_POS0[0] + tasks.TRAY_OUT + tasks.POT_TRAY_XY[0], atol=0.01
        )
        assert goal[4] < start[4] - 0.05
        h, d = e.h, e.data
        d.qpos[h.door_qpos], d.qpos[h.tray_qpos] = goal[0], goal[1]
        d.qpos[h.pot_qpos : h.pot_qpos + 7] = goal[2:9]
        d.qvel[:] = 0.0
        obs, reward, terminated, _, info = e.step(_hold(obs))
        assert info["is_success"] and terminated, info
    finally:
        e.close()


def test_invalid_actions(env):
    obs, _ = env.reset(seed=2)
    bad = _hold(obs)
    bad[[1, 9]] = [np.nan, np.inf]
    with pytest.raises(ValueError, match=r"y \(index 1\).*gripper \(index 9\)"):
        env.step(bad)
    far = _hold(obs)
    far[:3] = [5.0, -5.0, 9.0]  # out of the workspace: clipped, not an error
    obs, *_ = env.step(far)
    from lerobot_efm.envs.talos_kitchen.control import WORKSPACE_HIGH, WORKSPACE_LOW

    np.testing.assert_allclose(
        obs["agent_pos"][:3], [WORKSPACE_HIGH[0], WORKSPACE_LOW[1], WORKSPACE_HIGH[2]], atol=1e-6
    )


def test_all_cycles_through_suite():
    e = TalosKitchenEnv(task="all", image_size=SIZE)
    try:
        seen = []
        for i in range(len(tasks.TASK_NAMES) + 1):
            _, info = e.reset(seed=i)
            seen.append(e.task)
            assert info["task"] == e.task and e.task_description == tasks.TASKS[e.task].description
        assert seen == list(tasks.TASK_NAMES) + [tasks.TASK_NAMES[0]]
        e.reset(options={"task": tasks.LONG_TASK})
        assert e.task == tasks.LONG_TASK and e.suite == "all"
        with pytest.raises(ValueError, match="valid tasks"):
            e.reset(options={"task": "nope"})
    finally:
        e.close()


def test_default_episode_length_grows_with_the_objects_a_task_moves():
    """lerobot-eval --env.task=store_pot without --env.episode_length must not cut the 3-object task at a 1-object
    limit (it did: 600 steps, every store_pot rollout failed); an explicit limit is kept, a bad one refused."""
    length = {
        t: TalosKitchenEnvConfig(task=t).episode_length for t in ("open_door", "pot_to_tray", "store_pot")
    }
    assert length == {"open_door": 500, "pot_to_tray": 500, "store_pot": 1500}
    assert TalosKitchenEnvConfig(task="close_door_pull_tray").episode_length == 1000
    assert TalosKitchenEnvConfig(task="all").episode_length == 1500
    assert TalosKitchenEnvConfig(task="store_pot", episode_length=70).gym_kwargs["max_episode_steps"] == 70
    with pytest.raises(ValueError, match="episode_length must be >= 1, got 0"):
        TalosKitchenEnvConfig(task="open_door", episode_length=0)


def test_lerobot_factory_keys():
    cfg = TalosKitchenEnvConfig(task="all", image_size=SIZE, episode_length=50)
    assert EnvConfig.get_choice_class("talos_kitchen") is TalosKitchenEnvConfig
    assert cfg.gym_id == GYM_ID and GYM_ID in gym.registry and cfg.fps == 25
    feats = env_to_policy_features(cfg)
    assert {k: tuple(v.shape) for k, v in feats.items() if k != "action"} == POLICY_KEYS
    assert tuple(feats["action"].shape) == (10,)
    vec = make_env(cfg, n_envs=2, use_async_envs=False)[cfg.type][0]
    try:
        assert isinstance(vec, gym.vector.SyncVectorEnv)
        obs, _ = vec.reset(seed=[0, 1])
        obs, _, _, _, info = vec.step(obs["agent_pos"][:, 10:])
        assert "is_success" in info and info["is_success"].shape == (2,)
        assert vec.call("_max_episode_steps") == (50, 50)
        assert vec.metadata["render_fps"] == 25
        assert vec.call("task") == ("open_door", "open_door")
        batch = preprocess_observation(obs)
        batch["task"] = list(vec.call("task_description"))
        env_pre, _ = cfg.get_env_processors()
        batch = {k: v for k, v in env_pre(batch).items() if k.startswith("observation.")}
        assert {k: tuple(v.shape[1:]) for k, v in batch.items()} == POLICY_KEYS
        for k, v in batch.items():
            assert v.shape[0] == 2 and v.dtype == torch.float32, k
            if "images" in k:
                assert 0.0 <= float(v.min()) and float(v.max()) <= 1.0
        # goal image went through the same conversion as the camera image
        goal = batch["observation.goal.images.front"]
        assert torch.allclose(
            goal[0], torch.from_numpy(obs["goal.images.front"][0]).permute(2, 0, 1).float() / 255
        )
    finally:
        vec.close()


def test_state_obs_type_renders_nothing_and_observes_the_same_states():
    """``--env.obs_type=state`` (state policies' evaluation): no camera, no goal image, nothing rendered, and the
    same states, goals and success as the default pixels_state env."""
    cfg = TalosKitchenEnvConfig(task="open_door", image_size=SIZE, obs_type="state")
    feats = env_to_policy_features(cfg)
    assert {k: tuple(v.shape) for k, v in feats.items() if k != "action"} == {
        k: v for k, v in POLICY_KEYS.items() if "images" not in k
    }
    pix = TalosKitchenEnv(task="open_door", image_size=SIZE)
    state = TalosKitchenEnv(task="open_door", image_size=SIZE, obs_type="state")
    try:
        renders = []
        state._renderer.render = lambda data: renders.append(1)  # counts any render of an observation
        a, _ = pix.reset(seed=3)
        b, _ = state.reset(seed=3)
        assert set(b) == {"agent_pos", "environment_state", "goal.state", "goal.environment_state"}
        assert state.observation_space.contains(b)
        for _ in range(3):
            a, _, _, _, info_a = pix.step(_hold(a))
            b, _, _, _, info_b = state.step(_hold(b))
        for key in b:
            np.testing.assert_allclose(a[key], b[key], atol=1e-6, err_msg=key)
        assert info_a["is_success"] == info_b["is_success"]
        assert renders == []
    finally:
        pix.close()
        state.close()
    with pytest.raises(ValueError, match="obs_type='depth'"):
        TalosKitchenEnvConfig(task="open_door", obs_type="depth")


def test_video_frames_are_rendered_every_kth_step_and_fresh_after_a_reset():
    """``video_frame_stride=3``: of lerobot-eval's render() after the reset and every step, the frames of steps
    0, 3, 6 are rendered and the two between repeat the last; the next episode starts with a fresh frame."""
    e = TalosKitchenEnv(task="open_door", image_size=SIZE, obs_type="state", video_frame_stride=3)
    real = e._render_renderer.render
    calls = []
    e._render_renderer.render = lambda data: calls.append(1) or real(data)
    try:
        obs, _ = e.reset(seed=0)
        up = _hold(obs)
        up[2] += 0.05  # raise the hand: every frame differs from the one before
        frames = [e.render()]
        for _ in range(6):
            e.step(up)
            frames.append(e.render())
        assert len(calls) == 3
        for i in (1, 2, 4, 5):
            np.testing.assert_array_equal(frames[i], frames[i - i % 3])
        for i in (3, 6):
            assert np.abs(frames[i].astype(int) - frames[i - 3]).mean() > 0.01
        np.testing.assert_array_equal(frames[6], real(e.data))  # the current scene
        e.reset(seed=1)
        np.testing.assert_array_equal(e.render(), real(e.data))
        assert len(calls) == 4
    finally:
        e.close()


def test_video_frame_reuses_the_observations_frame_of_the_same_scene(env, monkeypatch):
    """A camera env renders the video frame at the observation's size: the observation's frame of the current
    scene is returned instead of rendering it twice; a changed scene is rendered anew."""
    real = env._renderer.render
    calls = []
    monkeypatch.setattr(env._renderer, "render", lambda data: calls.append(1) or real(data))
    obs, _ = env.reset(seed=0)  # the goal image and the observation
    assert len(calls) == 2
    np.testing.assert_array_equal(env.render(), obs["pixels"]["front"])
    obs, *_ = env.step(_hold(obs))
    np.testing.assert_array_equal(env.render(), obs["pixels"]["front"])
    assert len(calls) == 3
    env.set_goal_scene()
    np.testing.assert_array_equal(env.render(), obs["goal.images.front"])
    assert len(calls) == 4


def test_video_frame_stride_must_be_a_positive_integer():
    with pytest.raises(ValueError, match="video_frame_stride must be an integer >= 1, got 0"):
        TalosKitchenEnv(task="open_door", video_frame_stride=0)
    with pytest.raises(ValueError, match="--env.video_frame_stride must be >= 1, got -2"):
        TalosKitchenEnvConfig(task="open_door", video_frame_stride=-2)
    assert TalosKitchenEnvConfig(task="open_door", video_frame_stride=5).gym_kwargs["video_frame_stride"] == 5


def _suite_module():
    """benchmarks/talos_kitchen_suite.py, imported from its path (benchmarks/ is not a package)."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "benchmarks" / "talos_kitchen_suite.py"
    spec = importlib.util.spec_from_file_location("talos_kitchen_suite", path)
    suite = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(suite)
    return suite


def test_suite_evaluates_state_policies_without_a_camera(tmp_path):
    """benchmarks/talos_kitchen_suite.py asks lerobot-eval for the state-only env exactly when the checkpoint's
    policy reads no camera (an image policy evaluated without one would fail on a missing key)."""
    import json

    suite = _suite_module()
    for name, feats, expected in (
        ("state", {"observation.state": {"type": "STATE", "shape": [20]}}, True),
        ("image", {"observation.images.front": {"type": "VISUAL", "shape": [3, 64, 64]}}, False),
    ):
        (tmp_path / name).mkdir()
        (tmp_path / name / "config.json").write_text(json.dumps({"input_features": feats}))
        cmd = suite.eval_command(str(tmp_path / name), "open_door", 2, 64, 500, tmp_path / "out", [])
        assert ("--env.obs_type=state" in cmd) is expected, cmd


def test_suite_renders_a_video_frame_every_fifth_step_by_default(tmp_path):
    """lerobot-eval's videos were 3/4 of the suite's time: the suite asks for a frame every 5th step unless told."""
    import json

    suite = _suite_module()
    for argv, stride in (
        (["--policy", "ac=ckpt"], 5),
        (["--policy", "ac=ckpt", "--video-frame-stride=1"], 1),
    ):
        assert suite.parse_args(argv).video_frame_stride == stride
    (tmp_path / "config.json").write_text(json.dumps({"input_features": {}}))
    for stride, flags in ((5, ["--env.video_frame_stride=5"]), (1, [])):
        cmd = suite.eval_command(str(tmp_path), "open_door", 2, 64, 500, tmp_path / "out", [], stride)
        assert [c for c in cmd if "video_frame_stride" in c] == flags


def test_suite_passes_lerobot_eval_flags_on_and_names_unknown_ones():
    """`talos_kitchen_suite.py ... --policy.n_action_steps=20` reaches every lerobot-eval run; a typo is named."""
    suite = _suite_module()
    args = suite.parse_args(
        [
            "--policy",
            "ac=ckpt",
            "--tasks",
            "open_door",
            "--policy.n_action_steps=20",
            "--extra=--env.image_size=32",
        ]
    )
    assert args.policy == ["ac=ckpt"] and args.tasks == ["open_door"]
    assert args.extra == ["--env.image_size=32", "--policy.n_action_steps=20"]
    with pytest.raises(SystemExit):
        suite.parse_args(["--policy", "ac=ckpt", "--n_action_steps=20"])


def test_suite_keeps_each_cells_time_and_names_a_partial_mean(tmp_path):
    """A cell evaluated by an earlier run reports the time its lerobot-eval took (``seconds.txt``), not the
    0 s of gathering it; a mean over part of the 13 tasks says how many it covers."""
    import json

    suite = _suite_module()
    ckpt = tmp_path / "ckpt"
    ckpt.mkdir()
    (ckpt / "config.json").write_text(
        json.dumps({"input_features": {"observation.state": {"type": "STATE"}}})
    )
    args = suite.parse_args(["--policy", f"ac={ckpt}", "--tasks", "open_door", "store_pot"])
    results = []
    for task, successes in (("open_door", [1, 1]), ("store_pot", [0, 1])):
        cell = tmp_path / "ac" / task
        cell.mkdir(parents=True)
        info = {
            "per_task": [{"metrics": {"successes": successes}}],
            "overall": {"pc_success": 50.0 * sum(successes), "n_episodes": 2},
        }
        (cell / "eval_info.json").write_text(json.dumps(info))
        results.append(suite.run_one("ac", str(ckpt), task, args, tmp_path))
    (tmp_path / "ac" / "open_door" / suite.SECONDS_FILE).write_text("754.2\n")
    assert suite.run_one("ac", str(ckpt), "open_door", args, tmp_path)["seconds"] == 754.2
    assert results[1]["seconds"] is None  # evaluated before cells kept their time: unknown, not 0
    assert "| **mean** | | 75% (2 tasks) |" in suite.table(results, ["ac"])


def test_suite_merge_pools_runs_of_the_same_cell_on_other_seeds(tmp_path):
    """`--merge` of two 10-episode runs of one policy (seeds 1000-1009 and 1010-1019) gives one 20-episode rate
    per task, not the last run's; the same run given twice is refused instead of counted twice."""
    import json

    suite = _suite_module()

    def run_file(name, seed, successes):
        cell = {"label": "ac", "task": "store_pot", "n_episodes": len(successes), "seconds": 10.0}
        cell |= {"pc_success": 100.0 * sum(successes) / len(successes), "successes": successes}
        cell["command"] = f"lerobot-eval --env.task=store_pot --seed={seed}"
        path = tmp_path / f"{name}.json"
        path.write_text(json.dumps({"policies": {"ac": "ckpt"}, "results": [cell]}))
        return path

    first = run_file("a", 1000, [True, False, False, False])
    second = run_file("b", 1004, [True, True, True, False])
    md = suite.merged_table([first, second])
    assert "| **store_pot** (long) |" in md and "| 50% |" in md, md
    assert "Episodes per cell: 8." in md
    with pytest.raises(ValueError, match="store_pot is given twice"):
        suite.merged_table([first, first])
