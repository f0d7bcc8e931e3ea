"""Deploy-time goals: a goal file (lerobot-efm-goal) or a dataset frame, named by --policy.goal_* flags, reaches
goal-less robot observations through a checkpoint's saved pre-processor, as lerobot-rollout builds it."""

import logging

import pytest
import torch
from conftest import REPO_ID, tiny_config
from lerobot.configs.policies import PreTrainedConfig
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.policies.factory import get_policy_class, make_policy, make_pre_post_processors
from safetensors.torch import save_file

from lerobot_efm.goal_source import deploy_goal, deploy_goal_index, set_deploy_goal, to_goal_keys
from lerobot_efm.hindsight import HindsightGoalDataset
from lerobot_efm.scripts.goal import main as goal_cli


@pytest.fixture(autouse=True)
def _no_goal_left_behind():
    yield
    set_deploy_goal(None)


def checkpoint(dataset, tmp_path, policy_type="efm_ac"):
    """A saved checkpoint (weights, config, pre/post-processors) as lerobot-train writes it."""
    cfg = tiny_config(policy_type)
    wrapped = HindsightGoalDataset(dataset, cfg)
    policy = make_policy(cfg, ds_meta=wrapped.meta)
    pre, post = make_pre_post_processors(cfg, dataset_stats=wrapped.meta.stats)
    path = tmp_path / "pretrained_model"
    policy.save_pretrained(path)
    pre.save_pretrained(path)
    post.save_pretrained(path)
    return path


def deploy(path, *flags):
    """What lerobot-rollout does with --policy.path=PATH plus --policy.<flags>."""
    cfg = PreTrainedConfig.from_pretrained(path, cli_overrides=list(flags))
    policy = get_policy_class(cfg.type).from_pretrained(path, config=cfg).eval()
    pre, post = make_pre_post_processors(
        cfg, pretrained_path=str(path), preprocessor_overrides={"device_processor": {"device": "cpu"}}
    )
    return policy, pre, post


def test_goal_file_from_a_dataset_frame_reaches_goal_less_observations(
    state_dataset, state_dataset_root, tmp_path
):
    path = checkpoint(state_dataset, tmp_path)
    goal_file = goal_cli(
        [
            f"--dataset.root={state_dataset_root}",
            f"--dataset.repo_id={REPO_ID}",
            "--dataset.episode=1",
            "--dataset.frame=-1",
            f"--output={tmp_path / 'goal.safetensors'}",
        ]
    )
    episode = LeRobotDataset(REPO_ID, root=state_dataset_root, episodes=[1])
    expected = episode[len(episode) - 1]["observation.state"]

    policy, pre, post = deploy(path, f"--goal_path={goal_file}")
    assert torch.equal(deploy_goal()["observation.goal.state"], expected)
    robot = {
        "observation.state": torch.tensor([[0.1, -0.2]])
    }  # batched, as prepare_observation_for_inference
    processed = pre(dict(robot))
    reference = pre({**robot, "observation.goal.state": expected[None]})
    assert torch.allclose(processed["observation.goal.state"], reference["observation.goal.state"])
    assert post(policy.select_action(processed)).shape == (1, 2)
    # a goal the observation brings (an env's) wins over the deploy-time one
    own = torch.tensor([[0.5, 0.5]])
    assert not torch.allclose(
        pre({**robot, "observation.goal.state": own})["observation.goal.state"],
        processed["observation.goal.state"],
    )


def test_goal_image_from_a_video_dataset_frame(video_dataset, video_dataset_root, tmp_path):
    path = checkpoint(video_dataset, tmp_path)
    policy, pre, _ = deploy(
        path,
        f"--goal_dataset_root={video_dataset_root}",
        f"--goal_repo_id={REPO_ID}",
        "--goal_episode=0",
        "--goal_frame=10",
    )
    frame = LeRobotDataset(REPO_ID, root=video_dataset_root, episodes=[0])[10]
    robot = {"observation.state": torch.zeros(2, 2), "observation.images.top": torch.rand(2, 3, 32, 32)}
    processed = pre(robot)
    assert processed["observation.goal.images.top"].shape == (2, 3, 32, 32)
    assert torch.allclose(processed["observation.goal.images.top"][1], frame["observation.images.top"])
    assert torch.equal(
        processed["observation.goal.images.top"][0], processed["observation.goal.images.top"][1]
    )
    assert policy.select_action(processed).shape == (2, 2)


def test_a_policy_without_goal_source_clears_an_earlier_goal(state_dataset, state_dataset_root, tmp_path):
    path = checkpoint(state_dataset, tmp_path)
    deploy(path, f"--goal_dataset_root={state_dataset_root}", f"--goal_repo_id={REPO_ID}")
    assert deploy_goal()
    deploy(path)
    assert not deploy_goal()


def test_bad_goals_are_refused_naming_the_key_and_shapes(state_dataset, state_dataset_root, tmp_path):
    path = checkpoint(state_dataset, tmp_path)
    wrong = tmp_path / "wrong.safetensors"
    save_file({"observation.state": torch.zeros(3)}, str(wrong))
    with pytest.raises(
        ValueError, match=r"'observation.state' has shape \(3,\); the checkpoint expects \(2,\)"
    ):
        deploy(path, f"--goal_path={wrong}")
    other = tmp_path / "other.safetensors"
    save_file({"observation.velocity": torch.zeros(2)}, str(other))
    with pytest.raises(KeyError, match="lacks 'observation.state'"):
        deploy(path, f"--goal_path={other}")
    with pytest.raises(FileNotFoundError, match="missing.safetensors"):
        deploy(path, f"--goal_path={tmp_path / 'missing.safetensors'}")
    with pytest.raises(ValueError, match="goal episode 7 out of range.*3 episodes"):
        deploy(
            path, f"--goal_dataset_root={state_dataset_root}", f"--goal_repo_id={REPO_ID}", "--goal_episode=7"
        )


def test_goal_image_of_another_resolution_is_resized_with_a_warning(caplog):
    from lerobot.configs.types import FeatureType, PolicyFeature

    features = {"observation.goal.images.top": PolicyFeature(FeatureType.VISUAL, (3, 32, 32))}
    hwc = torch.randint(0, 256, (16, 16, 3), dtype=torch.uint8)  # a camera frame as a robot returns it
    with caplog.at_level(logging.WARNING):
        goal = to_goal_keys({"observation.images.top": hwc}, features)
    image = goal["observation.goal.images.top"]
    assert image.shape == (3, 32, 32) and 0.0 <= image.min() and image.max() <= 1.0
    assert abs(float(image.mean()) - float(hwc.float().mean() / 255)) < 0.02
    assert sum("resized" in r.message for r in caplog.records) == 1


def test_goal_cli_shows_the_goal_in_rerun(video_dataset_root, tmp_path):
    rrd = tmp_path / "goal.rrd"
    goal_cli(
        [
            f"--dataset.root={video_dataset_root}",
            f"--dataset.repo_id={REPO_ID}",
            "--dataset.frame=5",
            f"--output={tmp_path / 'goal.safetensors'}",
            "--display=true",
            f"--rrd={rrd}",
        ]
    )
    assert rrd.is_file() and rrd.stat().st_size > 32 * 32 * 3  # the goal image is in it


def test_a_sequence_of_goals_advances_when_the_critic_says_reached(state_dataset, tmp_path):
    """goal_path=a,b: goal a is inserted until the critic's distance to it falls under goal_advance_distance,
    then goal b (a multi-step task); one step of the last chunk is executed before replanning."""
    from lerobot_efm.goal_source import deploy_goal_index

    path = checkpoint(state_dataset, tmp_path)
    first, second = tmp_path / "a.safetensors", tmp_path / "b.safetensors"
    save_file({"observation.state": torch.tensor([0.2, 0.2])}, str(first))
    save_file({"observation.state": torch.tensor([-0.3, 0.1])}, str(second))
    policy, pre, _ = deploy(path, f"--goal_path={first},{second}", "--goal_advance_distance=5")
    policy.config.goal_advance_distance = (
        -1e6
    )  # an untrained critic's distance may be anything: never reached
    robot = {"observation.state": torch.tensor([[0.0, 0.0]])}
    goal_a = pre(dict(robot))["observation.goal.state"]
    for _ in range(3 * policy.config.n_action_steps):  # stays on goal a
        policy.select_action(pre(dict(robot)))
    assert deploy_goal_index() == 0 and len(policy._action_queue) < policy.config.n_action_steps

    policy.config.goal_advance_distance = 1e6  # any distance counts as reached now
    policy.reset()
    policy.select_action(pre(dict(robot)))
    assert deploy_goal_index() == 1 and len(policy._action_queue) == 0  # replans at the next step
    goal_b = pre(dict(robot))["observation.goal.state"]
    assert not torch.allclose(goal_a, goal_b)
    policy.reset()
    policy.select_action(pre(dict(robot)))
    assert deploy_goal_index() == 1  # the last goal stays


def test_a_goal_sequence_needs_a_critic(state_dataset, tmp_path):
    cfg = tiny_config("efm_gc")
    wrapped = HindsightGoalDataset(state_dataset, cfg)
    policy = make_policy(cfg, ds_meta=wrapped.meta)
    policy.save_pretrained(tmp_path / "gc")
    goal = tmp_path / "g.safetensors"
    save_file({"observation.state": torch.tensor([0.2, 0.2])}, str(goal))
    cfg = PreTrainedConfig.from_pretrained(tmp_path / "gc", cli_overrides=[f"--goal_path={goal},{goal}"])
    with pytest.raises(ValueError, match="sequence of 2 goals.*efm_gc has no critic"):
        get_policy_class("efm_gc").from_pretrained(tmp_path / "gc", config=cfg)


def test_a_key_press_moves_a_goal_sequence_on_even_without_critic(state_dataset, tmp_path, monkeypatch):
    """--policy.goal_advance_key=g: LeRobot's keyboard listener reports key names; 'g' moves on to the next goal at
    the next action (the chunk towards the old goal is dropped), other keys do nothing; FM-GC may then follow a
    sequence although it has no critic."""
    import lerobot_efm.goal_source as goal_source

    listeners = []

    class FakeListener:  # what lerobot.utils.keyboard_input.create_key_listener returns (a thread with stop())
        def __init__(self, dispatch, controls_help=""):
            self.dispatch, self.help, self.stopped = dispatch, controls_help, False
            listeners.append(self)

        def stop(self):
            self.stopped = True

    monkeypatch.setattr(goal_source, "create_key_listener", FakeListener)
    path = checkpoint(state_dataset, tmp_path, "efm_gc")
    first, second = tmp_path / "a.safetensors", tmp_path / "b.safetensors"
    save_file({"observation.state": torch.tensor([0.2, 0.2])}, str(first))
    save_file({"observation.state": torch.tensor([-0.3, 0.1])}, str(second))
    policy, pre, _ = deploy(path, f"--goal_path={first},{second}", "--goal_advance_key=g")
    assert len(listeners) == 1 and "'g' = next goal" in listeners[0].help
    robot = {"observation.state": torch.tensor([[0.0, 0.0]])}
    policy.select_action(pre(dict(robot)))
    queued = len(policy._action_queue)
    listeners[0].dispatch("x")
    policy.select_action(pre(dict(robot)))
    assert deploy_goal_index() == 0 and len(policy._action_queue) == queued - 1
    listeners[0].dispatch("g")
    policy.select_action(pre(dict(robot)))  # replanned towards goal b
    assert deploy_goal_index() == 1 and len(policy._action_queue) == policy.config.n_action_steps - 1
    assert torch.allclose(deploy_goal()["observation.goal.state"], torch.tensor([-0.3, 0.1]))
    listeners[0].dispatch("g")  # the last goal stays
    policy.select_action(pre(dict(robot)))
    assert deploy_goal_index() == 1
    set_deploy_goal(None)
    assert listeners[0].stopped  # a new deployment (or none) stops the old listener


def test_live_camera_frames_of_another_resolution_are_resized_once_warned(video_dataset, tmp_path, caplog):
    """A camera at another resolution than the recording's is resized to the checkpoint's, and so is a goal image
    that comes with the observation at that resolution (lerobot-eval on an env rendering at --env.image_size)."""
    path = checkpoint(video_dataset, tmp_path)
    policy, pre, _ = deploy(path)
    with caplog.at_level(logging.WARNING):
        for _ in range(2):
            processed = pre(
                {
                    "observation.state": torch.zeros(1, 2),
                    "observation.images.top": torch.rand(1, 3, 48, 64),
                    "observation.goal.images.top": torch.rand(1, 3, 48, 64),
                    "observation.goal.state": torch.zeros(1, 2),
                }
            )
    assert processed["observation.images.top"].shape == (1, 3, 32, 32)
    assert processed["observation.goal.images.top"].shape == (1, 3, 32, 32)
    assert sum("sends (3, 48, 64) frames" in r.message for r in caplog.records) == 2  # once per key
    assert policy.select_action(processed).shape == (1, 2)


def test_a_dimension_constant_in_the_recording_is_centred_not_divided_by_eps(state_dataset, caplog):
    """A deployed robot nudges what never moved in the play recording: its normalised value must stay of the
    order of the nudge (LeRobot divides a zero range by 1e-8), for the observation and for the goal."""
    import copy

    cfg = tiny_config("efm_ac")
    wrapped = HindsightGoalDataset(state_dataset, cfg)
    make_policy(cfg, ds_meta=wrapped.meta)
    stats = copy.deepcopy(wrapped.meta.stats)
    for key in [k for k in stats if k.startswith("observation.") and k.endswith("state")]:  # and the goal's
        stats[key]["min"][1] = stats[key]["max"][1] = 0.25  # never changed
    with caplog.at_level(logging.WARNING):
        pre, _ = make_pre_post_processors(cfg, dataset_stats=stats)
    assert "observation.state: dimension(s) [1] never change" in caplog.text
    nudged = torch.tensor([[0.0, 0.254]])
    out = pre({"observation.state": nudged, "observation.goal.state": nudged})
    for key in ("observation.state", "observation.goal.state"):
        assert abs(float(out[key][0, 1]) - 0.004) < 1e-5, out[key]
