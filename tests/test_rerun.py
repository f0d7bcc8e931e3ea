"""Rerun recordings: policy rollouts (lerobot_efm.scripts.log_rollouts) and hindsight samples
(lerobot_efm.scripts.log_dataset) written to .rrd files, then read back with rerun's own reader."""

import numpy as np
import pytest
import rerun as rr
import torch
from conftest import REPO_ID, tiny_config
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from rerun.experimental import RrdReader
from test_lerobot_cli import train

from lerobot_efm.envs.talos_kitchen.env import STATE_NAMES, TalosKitchenEnvConfig
from lerobot_efm.scripts import log_dataset, log_rollouts
from lerobot_efm.viz import RolloutLogger, get_env_viz, read_rrd


@pytest.fixture(scope="module")
def checkpoints(tmp_path_factory, state_dataset_root):
    """Tiny lerobot-train runs (2 steps) of a critic agent (FM-AC) and a candidate-sampling one (FM-PS)."""
    out = {}
    for policy_type in ("efm_ac", "efm_ps"):
        run_dir = tmp_path_factory.mktemp("rerun_runs") / policy_type
        train(state_dataset_root, run_dir, policy_type, "--steps=2", "--save_freq=2", "--policy.use_rl=true")
        out[policy_type] = run_dir / "checkpoints" / "last" / "pretrained_model"
    return out


def temporal(rows, timeline="step"):
    return [r for r in rows if r.get(timeline) is not None]


def scalars(rows):
    return np.array([r["Scalars:scalars"] for r in temporal(rows)], dtype=np.float64)


def check_episode(data, i, length, n_action_steps, num_candidates=None):
    ep = f"episode_{i}"
    for name in (
        "reward",
        "success",
        "action",
        "info/distance",
        "camera/render",
    ):  # one row per env step, steps 0..length-1
        assert [r["step"] for r in temporal(data[f"{ep}/{name}"])] == list(range(length)), name
    # observations: every step plus the final observation
    for name in ("world/agent", "obs/state", "goal_obs/state"):
        assert [r["step"] for r in temporal(data[f"{ep}/{name}"])] == list(range(length + 1)), name
    assert len(temporal(data[f"{ep}/world/goal_agent"])) == length + 1
    path = temporal(data[f"{ep}/world/agent_path"])[-1]["LineStrips3D:strips"][0]
    assert len(path) == length + 1 and all(p[2] == 0.0 for p in path)  # 2-D state padded with z = 0

    replans = list(range(0, length, n_action_steps))
    critic = temporal(data[f"{ep}/distance/critic"])
    assert [r["step"] for r in critic] == replans
    assert np.isfinite(scalars(data[f"{ep}/distance/critic"])).all()
    chunks = sorted(k for k in data if k.startswith(f"{ep}/action_chunk/"))
    assert chunks == [f"{ep}/action_chunk/r{t:04d}" for t in replans]
    chunk = scalars(data[chunks[0]])
    assert chunk.shape == (8, 2) and np.isfinite(chunk).all()  # L_a waypoints x action dims, unnormalised
    strips = temporal(data[f"{ep}/world/action_chunk"])
    assert [r["step"] for r in strips] == replans
    assert np.isfinite(np.array(strips[0]["LineStrips3D:strips"][0])).all()
    if num_candidates is not None:
        cands = temporal(data[f"{ep}/world/candidates"])
        assert [r["step"] for r in cands] == replans
        for row in cands:
            assert len(row["LineStrips3D:strips"]) == num_candidates
            radii = np.array(row["LineStrips3D:radii"])
            assert (radii == radii.max()).sum() == 1  # the chosen candidate is highlighted
            assert np.isfinite(np.array(row["LineStrips3D:strips"], dtype=np.float64)).all()
        assert scalars(data[f"{ep}/distance/candidates"]).shape == (len(replans), num_candidates)
        assert len(temporal(data[f"{ep}/world/obs_plan"])) == len(replans)


@pytest.mark.parametrize(
    "policy_type, limit, num_candidates",
    [("efm_ac", "--env.episode_length=25", None), ("efm_ps", "--max_steps=20", 4)],
)
def test_rollout_rrd(checkpoints, tmp_path, policy_type, limit, num_candidates):
    output = tmp_path / "rollout.rrd"
    results = log_rollouts.main(
        [
            f"--policy.path={checkpoints[policy_type]}",
            "--env.type=efm_point_reach",
            "--eval.n_episodes=2",
            f"--output={output}",
            "--seed=3",
            limit,
        ]
    )
    assert len(results) == 2 and output.exists()
    data = read_rrd(output)
    expected = 25 if "episode_length" in limit else 20  # untrained policies do not reach the goal
    for i, res in enumerate(results):
        assert res["length"] == expected and res["seed"] == 3 + i
        check_episode(data, i, res["length"], n_action_steps=6, num_candidates=num_candidates)
    assert "scene/wall" in data and "scene/arena" in data
    scene = read_rrd(output, keep=lambda entity: entity.startswith("scene/"))  # only what is asked for
    assert scene == {k: v for k, v in data.items() if k.startswith("scene/")}
    reader = RrdReader(output)
    assert (
        len(reader.recordings()) == 1 and len(reader.blueprints()) == 1
    )  # the default layout travels with it


def test_success_backfills_true_remaining_steps(tmp_path):
    """The logger alone: images, goals and the true steps left, back-filled once an episode succeeded."""
    output = tmp_path / "log.rrd"
    rec = rr.RecordingStream("test")
    rec.save(output)
    log = RolloutLogger(rec, "efm_point_reach", fps=20)
    log.begin_episode(0)
    img = torch.rand(1, 3, 8, 8)
    for t in range(5):
        log.log_observation(
            t,
            {
                "observation.state": torch.tensor([[0.1 * t, 0.2]]),
                "observation.goal.state": torch.tensor([[0.5, 0.2]]),
                "observation.images.top": img,
                "observation.goal.images.top": img,
            },
        )
        if t == 0:
            log.log_prediction(t, {"distance": torch.tensor([5.0])})
        log.log_action(t, np.array([0.1 * (t + 1), 0.2]))
        log.log_outcome(t, float(t == 4), t == 4, {"distance": 0.5 - 0.1 * t})
    log.end_episode(5, True)
    rec.send_blueprint(log.blueprint())
    rec.flush()
    rec.disconnect()
    data = read_rrd(output)
    remaining = temporal(data["episode_0/distance/true_remaining"])
    assert [r["step"] for r in remaining] == list(range(6))
    assert [r["Scalars:scalars"][0] for r in remaining] == [5.0, 4.0, 3.0, 2.0, 1.0, 0.0]
    assert temporal(data["episode_0/distance/critic"])[0]["Scalars:scalars"] == [5.0]
    assert len(temporal(data["episode_0/camera/top"])) == 5
    assert len(temporal(data["episode_0/goal/top"])) == 1  # a constant goal image is logged once per episode
    assert temporal(data["episode_0/success"])[-1]["Scalars:scalars"] == [1.0]
    first = temporal(data["episode_0/reward"])[1]
    assert first["time"].total_seconds() == pytest.approx(1 / 20)  # seconds timeline from the env fps


@pytest.mark.parametrize("policy_type", ["efm_ps", "efm_ac"])
def test_log_dataset_rrd(state_dataset, state_dataset_root, tmp_path, policy_type):
    output = tmp_path / "samples.rrd"
    logged = log_dataset.main(
        [
            f"--dataset.repo_id={REPO_ID}",
            f"--dataset.root={state_dataset_root}",
            f"--policy.type={policy_type}",
            "--policy.device=cpu",
            "--policy.max_goal_distance=40",
            "--policy.obs_traj_stride=4",
            "--num_samples=5",
            "--seed=1",
            f"--output={output}",
        ]
    )
    assert len(logged) == 5
    data = read_rrd(output)
    states = np.array(state_dataset.hf_dataset["observation.state"], dtype=np.float32)
    actions = np.array(state_dataset.hf_dataset["action"], dtype=np.float32)
    assert [r["Scalars:scalars"][0] for r in temporal(data["summary/d"], "sample")] == [
        s["d"] for s in logged
    ]
    for s in logged:
        root, k, d = f"sample_{s['sample']}", s["row"], int(s["d"])
        assert 0 <= d <= 40
        assert data[f"{root}/d"][0]["Scalars:scalars"] == [float(d)]
        np.testing.assert_allclose(
            data[f"{root}/world/obs"][0]["Points3D:positions"][0][:2], states[k], atol=1e-6
        )
        np.testing.assert_allclose(
            data[f"{root}/world/goal"][0]["Points3D:positions"][0][:2], states[k + d], atol=1e-6
        )
        strip = np.array(data[f"{root}/world/action_traj"][0]["LineStrips3D:strips"][0])
        assert strip.shape == (8, 3)  # L_a = 8, S_a = 1, held at the goal
        np.testing.assert_allclose(strip[:, :2], actions[[k + min(j, d) for j in range(8)]], atol=1e-6)
        if policy_type == "efm_ps":  # tau^o: L_o = 3 states S_o = 4 frames apart, clamped at the goal
            traj = np.array(data[f"{root}/world/obs_traj"][0]["LineStrips3D:strips"][0])
            np.testing.assert_allclose(traj[:, :2], states[[k + min(4 * j, d) for j in range(3)]], atol=1e-6)
        else:
            assert f"{root}/world/obs_traj" not in data
    assert len(RrdReader(output).blueprints()) == 1


def test_log_dataset_with_video(video_dataset_root, tmp_path):
    output = tmp_path / "video_samples.rrd"
    log_dataset.main(
        [
            f"--dataset.repo_id={REPO_ID}",
            f"--dataset.root={video_dataset_root}",
            "--policy.type=efm_pc",
            "--policy.device=cpu",
            "--policy.max_goal_distance=20",
            "--policy.obs_traj_stride=4",
            "--num_samples=2",
            f"--output={output}",
        ]
    )
    data = read_rrd(output)
    for n in range(2):
        for path in ("images/top", "goal_images/top", "traj_images/top/0", "traj_images/top/2"):
            row = data[f"sample_{n}/{path}"][0]
            assert row["Image:format"][0]["width"] == 32 and len(row["Image:buffer"][0]) == 32 * 32 * 3


# --- Talos kitchen ------------------------------------------------------------------------------------


def talos_bounds_stats() -> dict[str, dict[str, np.ndarray]]:
    """MIN_MAX statistics from the talos_kitchen ranges (hand workspace box, rot6d in [-1, 1], gripper [0, 1],
    door [-2, 0] rad, tray [TRAY_STOP, 0] m, pot inside the workspace, quaternion in [-1, 1]): an untrained policy
    then commands poses all over the workspace instead of one point."""
    from lerobot_efm.envs.talos_kitchen.control import WORKSPACE_HIGH, WORKSPACE_LOW
    from lerobot_efm.envs.talos_kitchen.tasks import TRAY_STOP

    pose_lo = np.concatenate([WORKSPACE_LOW, -np.ones(6), [0.0]]).astype(np.float32)
    pose_hi = np.concatenate([WORKSPACE_HIGH, np.ones(6), [1.0]]).astype(np.float32)
    env_lo = np.concatenate([[-2.0, TRAY_STOP], WORKSPACE_LOW, -np.ones(4)]).astype(np.float32)
    env_hi = np.concatenate([[0.0, 0.0], WORKSPACE_HIGH, np.ones(4)]).astype(np.float32)
    return {
        "observation.state": {"min": np.tile(pose_lo, 2), "max": np.tile(pose_hi, 2)},
        "observation.environment_state": {"min": env_lo, "max": env_hi},
        "action": {"min": pose_lo, "max": pose_hi},
    }


@pytest.fixture(scope="module")
def talos_checkpoint(tmp_path_factory):
    """An untrained tiny FM-AC for talos_kitchen (features from the env config, 32 px images), saved as
    lerobot-train saves ``pretrained_model`` (config, weights, pre/post-processors with their stats)."""
    from lerobot.policies import make_policy, make_pre_post_processors

    out = tmp_path_factory.mktemp("talos_policy") / "pretrained_model"
    cfg = tiny_config("efm_ac", use_rl=True)
    policy = make_policy(cfg, env_cfg=TalosKitchenEnvConfig(image_size=32))
    preprocessor, postprocessor = make_pre_post_processors(cfg, dataset_stats=talos_bounds_stats())
    for part in (policy, preprocessor, postprocessor):
        part.save_pretrained(out)
    return out


def test_talos_hand_slices_follow_the_state_names():
    viz = get_env_viz("talos_kitchen")
    state = np.arange(len(STATE_NAMES), dtype=np.float32)
    points = viz.state_points(state)
    np.testing.assert_array_equal(
        points["hand_commanded"], [STATE_NAMES.index(n) for n in ("cmd_x", "cmd_y", "cmd_z")]
    )
    np.testing.assert_array_equal(points["hand_measured"], [STATE_NAMES.index(n) for n in ("x", "y", "z")])
    np.testing.assert_array_equal(
        viz.action_points(np.arange(20.0).reshape(2, 10)), [[0, 1, 2], [10, 11, 12]]
    )


def talos_open_door_rollout(checkpoint, output, length: int, *flags: str) -> list[dict]:
    """One ``length``-step open_door episode of ``checkpoint`` logged to ``output`` (32 px camera)."""
    return log_rollouts.main(
        [
            f"--policy.path={checkpoint}",
            "--env.type=talos_kitchen",
            "--env.task=open_door",
            "--env.image_size=32",
            f"--env.episode_length={length}",
            "--eval.n_episodes=1",
            f"--output={output}",
            *flags,
        ]
    )


def test_talos_rollout_rrd(talos_checkpoint, tmp_path):
    """lerobot-efm-log-rollouts in the MuJoCo Talos kitchen: hand trajectories, predicted chunks and object states."""
    output, length = tmp_path / "talos.rrd", 12
    results = talos_open_door_rollout(talos_checkpoint, output, length)
    assert [r["length"] for r in results] == [length]
    data = read_rrd(output)
    ep, steps = "episode_0", list(range(length + 1))  # every step plus the final observation
    paths = {}
    for name in ("hand_commanded", "hand_measured", "pot", "door_handle", "tray_handle"):
        rows = temporal(data[f"{ep}/world/{name}"])
        assert [r["step"] for r in rows] == steps, name
        points = np.array([r["Points3D:positions"][0] for r in rows], dtype=np.float64)
        assert points.shape == (length + 1, 3) and np.isfinite(points).all(), name
        paths[name] = points
        assert len(temporal(data[f"{ep}/world/goal_{name}"])) == length + 1
        assert np.array(temporal(data[f"{ep}/world/{name}_path"])[-1]["LineStrips3D:strips"][0]).shape == (
            length + 1,
            3,
        )
    # the points are the state's positions (not zero-padded slices of something else): the hand is above the
    # floor near the robot, the pot on the table (z 0.85 m), the hand moves (an untrained policy commands poses)
    assert (paths["hand_measured"][:, 2] > 0.5).all() and (paths["hand_commanded"][:, 2] > 0.5).all()
    assert np.abs(paths["pot"][:, 2] - 0.85).max() < 0.05
    assert np.ptp(paths["hand_commanded"], axis=0).max() > 1e-3
    chunks = temporal(data[f"{ep}/world/action_chunk"])
    assert [r["step"] for r in chunks] == list(range(0, length, 6))  # n_action_steps = 6
    for row in chunks:
        strip = np.array(row["LineStrips3D:strips"][0], dtype=np.float64)
        assert (
            strip.shape == (8, 3) and np.isfinite(strip).all()
        )  # L_a waypoints of the hand position command
    for name in ("door", "tray", "pot_x", "pot_y", "pot_z"):
        assert [r["step"] for r in temporal(data[f"{ep}/objects/{name}"])] == steps, name
        assert len(temporal(data[f"{ep}/objects/goal_{name}"])) == length + 1
    door_goal = scalars(data[f"{ep}/objects/goal_door"])
    assert (door_goal < -0.5).all()  # open_door: the goal has the door open, the start has it closed
    assert abs(scalars(data[f"{ep}/objects/door"])[0, 0]) < 0.05
    assert "scene/table" in data and "scene/workspace" in data
    assert len(RrdReader(output).blueprints()) == 1
    # the grasp state rides in the env infos: scalars in the rrd, closures classified in the results
    for key in ("held", "touched", "grip_closure", "grip_command"):
        assert [r["step"] for r in temporal(data[f"{ep}/info/{key}"])] == list(range(length)), key
    commands = scalars(data[f"{ep}/info/grip_command"])[:, 0]
    grasps = results[0]["grasps"]
    assert grasps["closures"] == int(np.sum(np.diff(np.r_[0, commands > 0.5].astype(int)) == 1))
    assert grasps["closures"] == sum(grasps[k] for k in ("held", "abandoned", "touched", "missed"))
    texts = [str(r.get("TextLog:text")) for r in temporal(data[f"{ep}/events"])]
    assert sum("closure" in t for t in texts) == grasps["closures"], texts


@pytest.fixture(scope="module")
def talos_image_checkpoint(tmp_path_factory):
    """An untrained tiny camera + proprioception FM-AC with an auxiliary object-state head; its door reading is
    the middle of the statistics' range (zero last-layer row): known for any camera frame."""
    from lerobot.configs.types import FeatureType, PolicyFeature
    from lerobot.policies import make_pre_post_processors
    from lerobot.policies.factory import get_policy_class

    out = tmp_path_factory.mktemp("talos_image_policy") / "pretrained_model"
    stats = talos_bounds_stats()
    cfg = tiny_config(
        "efm_ac",
        input_features={
            "observation.images.front": PolicyFeature(type=FeatureType.VISUAL, shape=(3, 32, 32)),
            "observation.state": PolicyFeature(type=FeatureType.STATE, shape=(len(STATE_NAMES),)),
        },
        output_features={"action": PolicyFeature(type=FeatureType.ACTION, shape=(10,))},
        auxiliary_state_key="observation.environment_state",
    )
    policy = get_policy_class("efm_ac")(cfg, dataset_stats=stats)
    for agent in (policy.model, policy.ema_model):
        with torch.no_grad():
            agent.auxiliary_head.net[-1].weight[0] = 0.0
            agent.auxiliary_head.net[-1].bias[0] = 0.0
    preprocessor, postprocessor = make_pre_post_processors(cfg, dataset_stats=stats)
    for part in (policy, preprocessor, postprocessor):
        part.save_pretrained(out)
    return out


def test_talos_rollout_logs_what_the_camera_policy_reads(talos_image_checkpoint, tmp_path):
    """The auxiliary head's reading of observation and goal is plotted next to the true object state at each
    replan, and the episode's result says how far off it was, per dimension."""
    output, length = tmp_path / "talos_image.rrd", 12
    results = talos_open_door_rollout(talos_image_checkpoint, output, length, "--render=false")
    stats = talos_bounds_stats()["observation.environment_state"]
    middle = (stats["min"][0] + stats["max"][0]) / 2  # the door reading of the zeroed row, in radians
    data = read_rrd(output)
    ep, replans = "episode_0", [0, 6]  # n_action_steps = 6

    def series(name):
        return {r["step"]: r["Scalars:scalars"][0] for r in temporal(data[f"{ep}/objects/{name}"])}

    for name in ("read_door", "read_goal_door", "read_pot_x", "read_goal_pot_x"):
        assert sorted(series(name)) == replans, name
    np.testing.assert_allclose(list(series("read_door").values()), middle, atol=1e-5)
    # the observation is read from the current frame (the hand moved), the goal from the fixed goal image
    pot_x, goal_pot_x = series("read_pot_x"), series("read_goal_pot_x")
    assert abs(pot_x[0] - pot_x[6]) > 1e-6 and goal_pot_x[0] == pytest.approx(goal_pot_x[6], abs=1e-6)
    errors = results[0]["auxiliary_readout_error"]
    assert len(errors["observation"]) == len(errors["goal"]) == len(stats["min"])
    door, goal_door = series("door"), series("goal_door")
    np.testing.assert_allclose(
        errors["observation"][0], np.mean([abs(middle - door[s]) for s in replans]), atol=1e-5
    )
    np.testing.assert_allclose(errors["goal"][0], abs(middle - goal_door[0]), atol=1e-5)
    np.testing.assert_allclose(
        errors["observation"][2], np.mean([abs(pot_x[s] - series("pot_x")[s]) for s in replans]), atol=1e-5
    )
    assert abs(goal_door[0] - door[0]) > 0.5  # open_door: observation and goal errors differ if swapped


def test_planar_push_is_drawn_as_effector_disc_and_walls(tmp_path):
    """Planar push states are [eff_x, eff_y, obj_x, obj_y]: two points on the maze floor (not one xyz point),
    the maze's walls as boxes."""
    from lerobot_efm.envs.planar_push.demonstrators import record_planar_push_dataset
    from lerobot_efm.envs.planar_push.maze import wall_boxes

    root = tmp_path / "push"
    record_planar_push_dataset("full", root, 120, repo_id="local/push_viz")
    output = tmp_path / "samples.rrd"
    logged = log_dataset.main(
        [
            "--dataset.repo_id=local/push_viz",
            f"--dataset.root={root}",
            "--env_type=planar_push",
            "--policy.type=efm_ac",
            "--policy.device=cpu",
            "--policy.max_goal_distance=40",
            "--num_samples=3",
            f"--output={output}",
        ]
    )
    states = np.array(LeRobotDataset("local/push_viz", root=root).hf_dataset["observation.state"], np.float32)
    data = read_rrd(output)
    for s in logged:
        points = np.array(data[f"sample_{s['sample']}/world/obs"][0]["Points3D:positions"])
        np.testing.assert_allclose(points[:, :2], states[s["row"]].reshape(2, 2), atol=1e-6)
        assert np.all(points[:, 2] == 0.0)
    scene = tmp_path / "scene.rrd"
    rec = rr.RecordingStream("scene_test")
    rec.save(scene)
    get_env_viz("planar_push").scene(rec)
    rec.flush()
    boxes = read_rrd(scene)["scene/walls"][0]
    assert len(boxes["Boxes3D:centers"]) == len(wall_boxes())


def test_ogbench_actions_are_velocities_not_drawn_as_points():
    viz = get_env_viz("ogbench")
    assert viz.action_points is None
    np.testing.assert_allclose(viz.state_points(np.array([[1.5, -2.0]]))["agent"], [[1.5, -2.0, 0.0]])


def test_unnormalize_inverts_the_policy_preprocessor(state_dataset):
    """Planned states and chunks are drawn in raw units through LeRobot's public UnnormalizerProcessorStep built
    from the pre-processor's own normaliser (its state dict), not through private helpers."""
    import copy

    from lerobot.policies.factory import make_policy, make_pre_post_processors

    from lerobot_efm.hindsight import HindsightGoalDataset
    from lerobot_efm.viz.unnormalize import unnormalize

    cfg = tiny_config("efm_ac")
    wrapped = HindsightGoalDataset(state_dataset, cfg)
    make_policy(cfg, ds_meta=wrapped.meta)  # fills the config's features, as lerobot-train does
    stats = copy.deepcopy(wrapped.meta.stats)
    for key in [k for k in stats if k.endswith("state") or k == "action"]:  # not the identity
        stats[key]["min"], stats[key]["max"] = np.array([0.0, -1.0]), np.array([2.0, 3.0])
    pre, post = make_pre_post_processors(cfg, dataset_stats=stats)
    raw = torch.tensor([[0.3, -0.2], [-0.5, 0.1]])
    normalized = pre({"observation.state": raw, "observation.goal.state": raw})["observation.state"]
    assert not torch.allclose(normalized, raw)
    torch.testing.assert_close(unnormalize(pre, "observation.state", normalized), raw)
    action = torch.tensor([[0.2, -0.4]])
    torch.testing.assert_close(unnormalize(pre, "action", action), post(action))
