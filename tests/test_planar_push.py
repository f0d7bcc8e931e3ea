"""Planar push: MuJoCo physics, success rule, eval pairs solved by the expert, demonstrators, datasets, LeRobot factory."""

import gymnasium as gym
import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset
from lerobot.envs.configs import EnvConfig
from lerobot.envs.factory import make_env
from lerobot.envs.utils import preprocess_observation

from lerobot_efm.envs import PlanarPushEnv, PlanarPushEnvConfig
from lerobot_efm.envs.planar_push.demonstrators import (
    BEHAVIOURS,
    CORNER_SLIDE,
    CORNERS,
    CURSOR_REACH,
    PLAY_REST,
    REGION_OVERLAP,
    STALL_FRAMES,
    VIA_TOL,
    WALL_SLIDE_TO,
    ExpertReachGoal,
    Leg,
    PlayFullSpace,
    PlayPartitioned,
    Pusher,
    disc_coverage,
    evaluate_expert,
    main,
    record_planar_push_dataset,
    run_episode,
)
from lerobot_efm.envs.planar_push.env import EVAL_PAIRS, FPS, GYM_ID, SUCCESS_TOL, TASK_NAMES
from lerobot_efm.envs.planar_push.maze import CELL, CORNER, inside_region, region_of, wall_distance


@pytest.fixture(scope="module")
def env():
    e = PlanarPushEnv(task="all")
    yield e
    e.close()


def _run(env, cmd, n):
    for _ in range(n):
        obs, *_ = env.step(np.asarray(cmd, np.float32))
    return obs["agent_pos"].astype(float)


def test_effector_tracks_command(env):
    env.reset(options={"initial": [0.3, -0.5, -0.5, 0.5]})
    s = _run(env, [0.6, -0.5], 30)
    np.testing.assert_allclose(s[:2], [0.6, -0.5], atol=0.01)
    np.testing.assert_allclose(s[2:], [-0.5, 0.5], atol=1e-6)  # disc untouched: friction holds it


def test_effector_pushes_disc(env):
    env.reset(options={"initial": [-0.8, -0.55, -0.45, -0.55]})
    s = _run(env, [0.3, -0.55], 40)
    assert s[2] > 0.4 and abs(s[3] + 0.55) < 0.02  # pushed right along its line
    assert s[2] - s[0] == pytest.approx(0.275, abs=0.02)  # in contact, behind it


@pytest.mark.parametrize("deg", [15, 30, 60])
def test_disc_friction_is_isotropic(env, deg):
    """Pushed along any direction the disc moves along it (the reference's pivot-joint friction); per-axis
    friction (MuJoCo frictionloss on each slide joint) moved it at 1-3 / 10 / 80 deg. Under the static friction
    (push force 1.5 < 2) it stays put."""
    u = np.array([np.cos(np.deg2rad(deg)), np.sin(np.deg2rad(deg))])
    obj = np.array([-0.5, -0.6])
    for lead, moved in ((0.1, 0.05), (0.03, None)):
        env.reset(options={"initial": [*(obj - u * 0.28), *obj], "goal": [*(obj - u * 0.28), *obj]})
        disc = _run(env, obj - u * 0.275 + u * lead, 15)[2:] - obj
        if moved is None:
            assert np.linalg.norm(disc) < 0.01, disc
        else:
            assert (
                np.linalg.norm(disc) > moved and abs(np.degrees(np.arctan2(disc[1], disc[0])) - deg) < 2.0
            ), disc


def test_walls_block_effector_and_disc(env):
    env.reset(options={"initial": [0.5, -0.5, -0.6, 0.5]})
    s = _run(env, [0.5, 0.5], 40)  # effector into the divider from below
    assert s[1] < -CELL / 2 - 0.06
    env.reset(options={"initial": [0.5, -0.7, 0.5, -0.4]})
    s = _run(env, [0.5, 0.5], 60)  # disc pushed up into the divider
    assert wall_distance(s[2:]) > 0.19 and s[3] < -CELL / 2 - 0.18
    env.reset(options={"initial": [0.6, 0.5, 0.0, 0.5]})
    s = _run(env, [1.0, 0.5], 40)  # arena border
    assert s[0] <= 1.0 - 0.075 + 0.005


def test_success_rule_and_termination():
    env = gym.make(GYM_ID, task="pair0", max_episode_steps=5)
    _, info = env.reset()
    assert not info["is_success"]
    goal = EVAL_PAIRS[0][2]
    near = goal + np.array([0.0, 0.0, 0.0, -SUCCESS_TOL * 0.5])
    _, info = env.reset(options={"initial": near})
    assert info["is_success"]
    _, reward, terminated, truncated, info = env.step(near[:2])
    assert info["is_success"] and terminated and reward == 1.0 and not truncated
    _, info = env.reset(options={"initial": goal + np.array([0.0, 0.0, 0.0, -SUCCESS_TOL * 1.5])})
    assert not info["is_success"]  # disc too far although the effector is on its goal
    _, info = env.reset(options={"initial": goal + np.array([0.0, SUCCESS_TOL * 1.5, 0.0, 0.0])})
    assert not info["is_success"]  # and the other way round
    env.close()


def test_invalid_inputs_raise(env):
    env.reset(options={"pair": 0})
    with pytest.raises(ValueError, match="action"):
        env.step(np.array([np.nan, 0.0]))
    with pytest.raises(ValueError, match="overlaps a wall"):
        env.reset(options={"initial": [0.5, 0.0, -0.5, 0.5]})
    with pytest.raises(ValueError, match="overlaps the disc"):
        env.reset(options={"initial": [0.0, 0.5, 0.1, 0.5]})
    with pytest.raises(ValueError, match="pair9"):
        PlanarPushEnvConfig(task="pair10")


def test_all_cycles_the_ten_pairs(env):
    assert len(EVAL_PAIRS) == 10 and TASK_NAMES[-1] == "pair9"
    env._reset_count = 0
    seen = [env.reset()[0]["goal.state"].copy() for _ in range(10)]
    for k, g in enumerate(seen):
        np.testing.assert_allclose(g, EVAL_PAIRS[k][2], atol=1e-6)
    for seed in (13, 0, 7):  # seeded resets (lerobot-eval's batched envs) pick pair seed % 10
        np.testing.assert_allclose(env.reset(seed=seed)[0]["goal.state"], EVAL_PAIRS[seed % 10][2], atol=1e-6)
    for name, start, goal in EVAL_PAIRS:  # far apart
        assert np.linalg.norm(start[2:] - goal[2:]) > 0.9, name


@pytest.mark.parametrize("pair", [0, 3, 9])
def test_expert_solves_eval_pairs(env, pair):
    obs, _ = env.reset(options={"pair": pair})
    expert = ExpertReachGoal(env, np.random.default_rng(pair), goal=env.goal)
    obs = expert.reset()
    for _ in range(600):
        obs, _, terminated, _, info = env.step(expert.act(obs))
        if terminated:
            break
    assert info["is_success"], (pair, info)


def test_progress_reward_sums_to_the_closed_share_of_the_goal_distance():
    env = PlanarPushEnv(task="pair3", reward="progress")
    obs, info = env.reset()
    d0 = info["object_distance"] + info["effector_distance"]
    expert, total = ExpertReachGoal(env, np.random.default_rng(0), goal=env.goal), 0.0
    obs = expert.reset()
    for t in range(600):
        obs, reward, terminated, _, info = env.step(expert.act(obs))
        total += reward
        if t == 20:  # partway: the sum so far is exactly the share closed so far
            d = info["object_distance"] + info["effector_distance"]
            assert total == pytest.approx(1 - d / d0, abs=1e-9)
        if terminated:
            break
    assert info["is_success"] and total > 1 - 2 * SUCCESS_TOL / d0
    env.reset(seed=3)
    idle = sum(env.step(env.state[:2].astype(np.float32))[1] for _ in range(20))
    assert abs(idle) < 0.01  # holding still closes nothing
    with pytest.raises(ValueError, match="progress"):
        PlanarPushEnvConfig(reward="dense")
    env.close()
    reference = evaluate_expert()  # the reference row of the agent tables
    assert reference["pc_success"] == 100.0 and 95.0 < reference["pc_closed"] < 100.0


@pytest.mark.parametrize("behaviour", sorted(BEHAVIOURS))
def test_demonstrators_valid_actions(env, behaviour):
    cls, _, _ = BEHAVIOURS[behaviour]
    op = cls(env, np.random.default_rng(0))
    states, actions, images, _ = run_episode(env, op, 300)
    assert actions.shape[1] == 2 and actions.dtype == np.float32 and images is None
    assert np.all(np.isfinite(actions)) and np.all(np.abs(actions) <= 1.0)
    disc_moved = np.linalg.norm(states[-1, 2:] - states[0, 2:])
    if behaviour == "hand":  # the hand goes around the disc, never pushes it
        assert disc_moved < 1e-3 and np.ptp(states[:, :2], axis=0).max() > 0.2
    elif behaviour != "expert":
        disc_path = np.linalg.norm(np.diff(states[:, 2:], axis=0), axis=1).sum()
        assert disc_path > 0.3  # play moves the disc (maybe back near its start: an open-space stop)
    assert disc_coverage(states) > 0.0


@pytest.mark.parametrize("behaviour", sorted(BEHAVIOURS))
def test_commands_trail_the_effector_like_a_cursor(env, behaviour):
    """Commands stay within CURSOR_REACH (+ noise) of the effector, as a human's cursor: a far command moves the
    hand exactly as its point at the force clip does, so it would be an action no state determines."""
    cls, _, _ = BEHAVIOURS[behaviour]
    states, actions, _, _ = run_episode(env, cls(env, np.random.default_rng(2)), 600)
    lead = np.linalg.norm(actions - states[:, :2], axis=1)
    assert lead.max() < CURSOR_REACH + 0.05, lead.max()  # noise: 0.01 per axis in play
    far = cls(env, np.random.default_rng(2), cursor_reach=None)
    states, actions, _, _ = run_episode(env, far, 600)
    assert (
        np.linalg.norm(actions - states[:, :2], axis=1).max() > CURSOR_REACH + 0.08
    )  # the option turns it off


def test_recorder_options_reach_the_operator(tmp_path, capsys):
    """The demonstrators' CLI takes LeRobot-style flags and the operators' draccus options (--operator.*)."""
    main(
        [
            "--operator.type=planar_push_partitioned",
            "--operator.region=1",
            f"--dataset.root={tmp_path / 'pp'}",
            "--num_frames=50",
        ]
    )
    states = np.stack(
        LeRobotDataset("local/planar_push_partitioned", root=tmp_path / "pp").hf_dataset["observation.state"]
    )
    assert inside_region(states[:, 2:], 1, -REGION_OVERLAP - 0.03).all()
    with pytest.raises(SystemExit):  # draccus: an option the operator does not have
        main(["--operator.type=planar_push_full", "--operator.nois=1", f"--dataset.root={tmp_path / 'x'}"])
    assert "nois" in capsys.readouterr().err
    with pytest.raises(Exception) as refused:  # draccus wraps the config's ValueError in its ParsingError
        main(["--operator.type=talos_kitchen_play", f"--dataset.root={tmp_path / 'y'}", "--num_frames=5"])
    reason = str(refused.value.__cause__ or refused.value)
    assert "records talos_kitchen, not planar push" in reason and "planar_push_partitioned" in reason


def test_expert_reaches_its_corner(env):
    op = ExpertReachGoal(env, np.random.default_rng(3))
    _, _, _, done = run_episode(env, op, 600)
    assert done and np.linalg.norm(env.state[2:] - op.target) < 0.04


def _frames_at_rest(states, tol=0.01):
    """Trailing frames whose disc and effector are within ``tol`` of the episode's last state."""
    near = np.all(np.linalg.norm((states - states[-1]).reshape(len(states), 2, 2), axis=-1) < tol, axis=-1)
    return len(near) - int(np.flatnonzero(~near)[-1]) - 1 if (~near).any() else len(near)


def test_expert_rests_on_its_goal_like_a_human(env):
    """Expert episodes end with a human-like rest on the goal, longer than the trajectory window (30 frames),
    so reached states and stopping are start frames of training tuples; the resting command is the hand."""
    rests = []
    for seed in range(4):
        op = ExpertReachGoal(env, np.random.default_rng(seed), rest=(40, 60))
        states, actions, _, done = run_episode(env, op, 600)
        assert done and np.linalg.norm(states[-1, 2:] - op.target) < 0.04
        rests.append(_frames_at_rest(states))
        assert np.linalg.norm(actions[-1] - states[-1, :2]) < 0.01  # "stay" = command on the hand
    assert min(rests) >= 35, rests


def test_expert_slides_into_its_corner_and_leaves_the_hand_behind_the_disc():
    """Expert episodes end the way the corner evaluation goals are: disc in the corner, hand behind it along a
    wall (a straight push at the corner leaves the hand on the diagonal, off every corner goal)."""
    env = PlanarPushEnv(task="all")
    op = ExpertReachGoal(env, np.random.default_rng(0), corner_share=1.0)
    hand_gap = (
        EVAL_PAIRS[0][2][3] - EVAL_PAIRS[0][2][0]
    )  # corner goal: hand this far from the disc, on a wall
    goals = np.array([[*(c - hand_gap * np.sign(c) * axis), *c] for c in CORNERS for axis in np.eye(2)])
    finals = [states[-1] for states, _, _, done in (run_episode(env, op, 600) for _ in range(8)) if done]
    env.close()
    on_goal = [
        bool((np.linalg.norm((goals - s).reshape(-1, 2, 2), axis=-1) < SUCCESS_TOL).all(axis=1).any())
        for s in finals
    ]
    assert len(finals) >= 3 and np.mean(on_goal) >= 0.75, on_goal


def test_expert_also_stops_in_open_space(env):
    """Two evaluation goals lie in open space; the expert's goals must include such stops (a braked push that
    rests away from every corner), else no expert frame shows one."""
    op = ExpertReachGoal(env, np.random.default_rng(1), corner_share=0.0, rest=(40, 41))
    for _ in range(2):
        states, _, _, done = run_episode(env, op, 600)
        assert done and np.linalg.norm(states[-1, 2:] - op.target) < SUCCESS_TOL
        assert np.linalg.norm(states[-1, :2] - op.effector_goal) < SUCCESS_TOL
        assert np.abs(op.target).min() < CORNER - 0.1, op.target  # not a corner
        assert _frames_at_rest(states) >= 35


def _farthest_past_goal(states: np.ndarray, goal: np.ndarray) -> float:
    """How far the disc went past ``goal`` along the direction it came from (from 0.3 out)."""
    d = np.linalg.norm(states[:, 2:] - goal, axis=1)
    i = int(np.argmax(d < 0.3))
    return float(((states[i:, 2:] - goal) @ ((goal - states[i, 2:]) / d[i])).max())


def test_expert_overshoots_open_space_goals_and_pushes_the_disc_back(env):
    """With overshoot_share the expert brakes the disc past an open-space goal, then brings it back from the
    other side: the data show the way back a policy needs when it overshoots (the plain expert never does)."""
    past = {}
    for share in (0.0, 1.0):
        past[share] = []
        for seed in range(2, 6):
            op = ExpertReachGoal(env, np.random.default_rng(seed), corner_share=0.0, overshoot_share=share)
            states, _, _, done = run_episode(env, op, 600)
            if done:
                assert np.linalg.norm(states[-1, 2:] - op.target) < SUCCESS_TOL
                past[share].append(_farthest_past_goal(states, op.target))
    assert len(past[0.0]) >= 3 and len(past[1.0]) >= 3, past
    assert max(past[0.0]) < 0.04, past  # the plain expert stops on the goal
    assert sum(p > 0.06 for p in past[1.0]) >= 2, past  # the overshooting one goes past it, and comes back
    with pytest.raises(ValueError, match="overshoot_share"):
        ExpertReachGoal(env, np.random.default_rng(0), overshoot_share=1.5)


def test_full_play_brakes_the_disc_in_open_space_past_its_target_and_back(env):
    """With open_stops / open_overshoot, free-space disc legs of full play brake the disc past their target,
    then push it back onto it: the open-space goal states and the way back to them."""
    stops, pauses = [], []

    class LoggedStops(PlayFullSpace):
        def _open_stop(self, target):
            stops.append((self._frame - 1, target.copy()))  # frame index of the state it was planned on
            return super()._open_stop(target)

        def act(self, obs):
            action = super().act(obs)
            if self._queue[0].kind == "pause" and (not pauses or pauses[-1][1] != id(self._queue[0])):
                pauses.append((self._frame - 1, id(self._queue[0])))
            return action

    shares = dict(corner_episodes=0.0, pause_share=0.0, effector_share=0.0)
    op = LoggedStops(env, np.random.default_rng(0), open_stops=1.0, open_overshoot=1.0, **shares)
    stopped = past_and_back = 0
    for _ in range(3):
        stops.clear(), pauses.clear()
        states = run_episode(env, op, 800)[0]
        for start, target in stops:
            rest = next((f for f, _ in pauses if f > start), None)
            leg = states[start:rest]
            d = np.linalg.norm(leg[:, 2:] - target, axis=1)
            if (
                rest is None or d[-1] > 0.04
            ):  # a leg dropped (the disc wedged against a wall) or cut by the end
                continue
            stopped += 1
            near = int(np.argmax(d < 0.3))
            farthest = near + int(np.argmax((leg[near:, 2:] - target) @ (target - leg[near, 2:]) / d[near]))
            past_and_back += _farthest_past_goal(leg, target) > 0.06 and d[farthest:].min() < 0.03
    assert stopped >= 5 and past_and_back >= 2, (stopped, past_and_back)
    stops.clear()
    run_episode(env, LoggedStops(env, np.random.default_rng(0), open_stops=0.0, **shares), 800)
    assert not stops  # the disc only coasts near free-space targets
    with pytest.raises(ValueError, match="open_overshoot"):
        PlayFullSpace(env, np.random.default_rng(0), open_overshoot=1.5)


def test_full_play_ends_its_episodes_in_every_corner_alike():
    """balanced_corners: each episode heads for the corner ended in least often so far (a failed corner leg is
    tried again), so a recording covers the four corner goals alike instead of as the dice fell (with
    balanced_corners=False these 8 episodes end in the corners 1 / 1 / 2 / 0 times)."""
    env = PlanarPushEnv(task="all")  # its own: the solver's warm start makes rollouts depend on earlier tests
    op = PlayFullSpace(env, np.random.default_rng(0), corner_episodes=1.0, corner_after=60)
    ends = np.zeros(len(CORNERS), int)
    for _ in range(8):
        last = run_episode(env, op, 800)[0][-1, 2:]
        d = np.linalg.norm(CORNERS - last, axis=1)
        ends[d.argmin()] += d.min() < 0.05
    env.close()
    assert ends.sum() >= 6 and ends.min() >= 1 and ends.max() - ends.min() <= 1, ends
    assert sorted(op._corner_endings.values()) == sorted(ends[ends > 0].tolist())


def test_full_play_ends_every_episode_in_a_corner_by_default():
    """Full play's default (the recorder's too) ends every episode by pushing the disc into a corner after a first
    disc leg past frame 100-250: eight of the ten evaluation goals are corners, and with 0.6 of the episodes
    after frame 160-400 each corner goal showed up in 4-6 of 52 episodes (13-14 of 76 now). Partitioned play keeps
    0.6 / 400 (no gain measured there)."""
    from lerobot_efm.operators import OperatorConfig, register_operators

    env = PlanarPushEnv(task="all")  # its own: the solver's warm start makes rollouts depend on earlier tests
    op = PlayFullSpace(env, np.random.default_rng(3))
    lengths, in_corner = [], 0
    for _ in range(4):
        states, _, _, done = run_episode(env, op, 800)
        lengths.append(len(states))
        in_corner += done and np.linalg.norm(CORNERS - states[-1, 2:], axis=1).min() < 0.05
    env.close()
    assert in_corner >= 3 and np.mean(lengths) < 700, (in_corner, lengths)
    register_operators()
    full = OperatorConfig.get_choice_class("planar_push_full")()
    partitioned = OperatorConfig.get_choice_class("planar_push_partitioned")()
    assert (full.corner_episodes, full.corner_after) == (1.0, 250)
    assert (partitioned.corner_episodes, partitioned.corner_after) == (0.6, 400)


def test_play_pauses_hold_still(env):
    """Play pauses last 20-100 frames and follow half of the disc legs: disc and hand stay put meanwhile."""
    op = PlayFullSpace(env, np.random.default_rng(0), corner_episodes=0.0)  # pauses of play that goes on
    states, actions, _, _ = run_episode(env, op, 800)
    speed = np.linalg.norm(np.diff(states, axis=0), axis=1)
    still = np.r_[speed < 2e-3, False]
    runs = np.diff(np.flatnonzero(np.diff(np.r_[0, still.astype(int), 0])))[::2]  # lengths of still runs
    assert (runs >= 15).sum() >= 2, runs


def test_play_pushes_fast_and_keeps_the_hand_near_the_disc(env):
    """Play pushes near the force clip (humans do; at lead 0.06 the disc moved at 0.27 /s against the expert's
    0.41) and moves the hand alone only around the disc, not to any point of the maze."""
    states = [run_episode(env, PlayFullSpace(env, np.random.default_rng(seed)), 800)[0] for seed in range(3)]
    speed = np.concatenate([np.linalg.norm(np.diff(s[:, 2:], axis=0), axis=1) * FPS for s in states])
    assert speed[speed > 0.02].mean() > 0.33, speed[speed > 0.02].mean()
    hand_to_disc = np.concatenate([np.linalg.norm(s[:, :2] - s[:, 2:], axis=1) for s in states])
    # 95th percentile, not the max: going around a wall to the staging point behind the disc may take the hand
    # further for a moment (3 x 800 frames: 0.59 at the 95th, 1.09 when effector moves may go anywhere)
    assert np.percentile(hand_to_disc, 95) < 0.8, np.percentile(hand_to_disc, 95)
    with pytest.raises(ValueError, match="min_lead"):
        PlayFullSpace(env, np.random.default_rng(0), min_lead=0.2)


def _longest_run(mask: np.ndarray) -> int:
    edges = np.diff(np.r_[0, mask.astype(int), 0])
    return int((np.flatnonzero(edges == -1) - np.flatnonzero(edges == 1)).max(initial=0))


def test_play_ends_in_a_corner_and_never_stalls(env):
    """No push gets a disc out of a corner (no room behind it): play that wedges one there rests and ends the
    episode (before, 30 % of the full-play frames flailed around a wedged disc). A leg in which nothing moves is
    dropped instead of pressing the hand into a wall (3.6 % of the frames before)."""
    op = PlayFullSpace(
        env, np.random.default_rng(0), open_stops=0.0
    )  # the random stream these counts hold on
    in_corner_at_end = 0
    for _ in range(6):
        states, actions, _, done = run_episode(env, op, 800)
        to_corner = np.linalg.norm(states[:, None, 2:] - CORNERS[None], axis=-1).min(axis=1)
        corner, wedged = to_corner < 0.05, to_corner < 0.02  # a slide may pause 0.05 short before it wedges
        if wedged.any():
            first = int(np.argmax(wedged))
            assert done and corner[first:].all() and len(states) - first <= PLAY_REST[1] + 40, (done, first)
            in_corner_at_end += 1
        still = np.r_[np.abs(np.diff(states, axis=0)).max(axis=1) < 0.002, False]
        pressing = still & (np.linalg.norm(actions - states[:, :2], axis=1) > 0.04)
        assert _longest_run(pressing) <= STALL_FRAMES + 2, _longest_run(pressing)
    assert in_corner_at_end >= 2


@pytest.mark.parametrize("cls, length", [(PlayFullSpace, 800), (PlayPartitioned, 630)])
def test_play_pushes_the_disc_into_corners(cls, length):
    """Play stops the disc on walls and in corners, where 8 of the 10 evaluation goals lie: without such legs
    no play frame is within the success tolerance of those goals."""
    env = PlanarPushEnv(task="all")  # its own: the solver's warm start makes rollouts depend on earlier tests
    rng = np.random.default_rng(1)
    ops = (
        [cls(env, rng, region=r) for r in range(3)]
        if cls is PlayPartitioned
        else [cls(env, rng, open_stops=0)] * 3
    )
    states = np.concatenate([run_episode(env, op, length)[0] for op in ops])  # partitioned: each region once
    env.close()
    goals = np.array([g[2:] for _, _, g in EVAL_PAIRS])
    near = np.linalg.norm(states[:, None, 2:] - goals[None], axis=-1) < SUCCESS_TOL  # (T, 10)
    assert near[:, [0, 1, 2, 3, 4, 5, 7, 8]].any(axis=0).sum() >= 1, "no frame has the disc on a corner goal"
    assert near.any(axis=1).sum() >= 30  # and it rests there for a while


@pytest.mark.parametrize("pair", [0, 1, 2, 3])
def test_play_slides_the_disc_into_a_corner_along_a_wall(env, pair):
    """A corner leg stops the disc on a wall's line (within VIA_TOL), then slides it along the wall on the line
    fixed where the slide starts, leaving the hand behind it where the corner evaluation goals have it. Re-aiming
    at the corner at every step (or pushing straight at it) leaves the hand off that line, out of tolerance."""
    _, _, goal = EVAL_PAIRS[pair]
    along_wall = (goal[:2] - goal[2:]) / np.linalg.norm(
        goal[:2] - goal[2:]
    )  # the goal's hand is behind the disc
    via = Pusher().corner_via(goal[2:], np.random.default_rng(0))
    assert via is not None and np.isclose(
        np.abs(via - goal[2:]).min(), 0.0
    )  # on one of the corner's walls' lines
    inward = -np.sign(goal[2:]) * (1.0 - np.abs(along_wall))  # away from the wall, towards the room
    disc = goal[2:] + along_wall * CORNER_SLIDE + inward * 0.75 * VIA_TOL  # where a via leg may stop it
    env.reset(options={"initial": [*(disc + along_wall * 0.32), *disc]})
    op = PlayFullSpace(env, np.random.default_rng(pair))
    op._budget, op._queue = (
        op.leg_budget,
        [Leg("disc_stop", goal[2:].copy(), slide=True), Leg("pause", frames=30)],
    )
    obs = env.observe()
    for _ in range(400):
        obs, *_ = env.step(op.act(obs))
        if op._queue[0].kind == "pause" and op._queue[0].frames < 20:
            break
    s = obs["agent_pos"]
    assert (
        np.linalg.norm(s[2:] - goal[2:]) < SUCCESS_TOL and np.linalg.norm(s[:2] - goal[:2]) < SUCCESS_TOL
    ), s


@pytest.mark.parametrize("region", [0, 1, 2])
def test_partitioned_stays_in_region(env, region):
    """The disc stays in its region, touching the border line at most (its centre within a radius beyond)."""
    op = PlayPartitioned(env, np.random.default_rng(region), region=region)
    states = np.concatenate([run_episode(env, op, 630)[0] for _ in range(3)])
    assert np.all(inside_region(states[:, 2:], region, -REGION_OVERLAP - 0.03))
    assert np.mean(region_of(states[:, 2:]) == region) > 0.5  # mostly on its side of the line


@pytest.mark.parametrize("a, b", [(0, 1), (1, 2)])
def test_neighbouring_regions_share_border_states(a, b):
    """Stitching (eq. 5) joins episodes only through states they share: the disc positions that the
    demonstrators of two neighbouring regions may plan through overlap along their border."""
    shared = Pusher(a).obj_free & Pusher(b).obj_free
    assert shared.sum() >= 20, shared.sum()


def test_full_play_leaves_its_start_region(env):
    op = PlayFullSpace(env, np.random.default_rng(0))
    states, _, _, _ = run_episode(env, op, 800)
    assert len(set(region_of(states[:, 2:]).tolist())) >= 2


def test_recorded_dataset_loads(tmp_path):
    ds = record_planar_push_dataset("full", tmp_path / "pp", num_frames=120, seed=0, max_episode_frames=60)
    again = LeRobotDataset("local/planar_push_full", root=tmp_path / "pp")
    assert again.num_frames == ds.num_frames == 120 and again.num_episodes == 2
    assert again.features["observation.state"]["shape"] == (4,)
    assert again.features["observation.state"]["names"] == ["eff_x", "eff_y", "obj_x", "obj_y"]
    assert again.features["action"]["shape"] == (2,) and "observation.images.top" not in again.features
    item = again[5]
    assert item["observation.state"].shape == (4,) and item["action"].shape == (2,)
    with pytest.raises(ValueError, match="behaviour"):
        record_planar_push_dataset("nope", tmp_path / "x", 10)


def test_lerobot_make_env_and_images():
    cfg = PlanarPushEnvConfig(task="pair0")
    assert EnvConfig.get_choice_class("planar_push") is PlanarPushEnvConfig
    vec = make_env(cfg, n_envs=1)[cfg.type][0]
    try:
        obs, _ = vec.reset(seed=[0])
        obs, _, _, _, info = vec.step(obs["agent_pos"][:, :2])
        batch = preprocess_observation(obs)
        assert batch["observation.state"].shape == (1, 4) and batch["observation.goal.state"].shape == (1, 4)
        assert "is_success" in info and vec.call("_max_episode_steps") == (600,)
    finally:
        vec.close()
    env = PlanarPushEnv(task="pair1", obs_type="pixels_state", image_size=32)
    obs, _ = env.reset()
    assert obs["pixels"]["top"].shape == (32, 32, 3) and obs["goal.images.top"].shape == (32, 32, 3)
    np.testing.assert_array_equal(env.render_state(env.goal), obs["goal.images.top"])
    assert not np.array_equal(obs["pixels"]["top"], obs["goal.images.top"])
    assert env.render().shape == (256, 256, 3)
    env.close()


def _slide_frames(states: np.ndarray) -> int:
    """Frames in which the disc moves along a wall line (one coordinate at a corner's) towards that corner, within
    0.7 of it: the final approach to the corner goals."""
    obj, step = states[:-1, 2:], np.diff(states[:, 2:], axis=0)
    count = 0
    for corner in CORNERS:
        for wall_axis in (0, 1):
            along = 1 - wall_axis
            gap = corner[along] - obj[:, along]
            count += int(
                (
                    (np.abs(obj[:, wall_axis] - corner[wall_axis]) < 0.03)
                    & (np.abs(gap) < 0.7)
                    & (step[:, along] * np.sign(gap) > 0.002)
                ).sum()
            )
    return count


def test_play_slides_along_walls_towards_corners_and_stops_short(env):
    """``wall_slides``: wall legs that slide the disc along a wall towards a corner (the final approach to the corner
    goals, otherwise shown once per episode at most) and stop where the hand still fits in front of the corner,
    so that play goes on: many more slide frames, the disc never wedged, and it leaves the corner again."""

    def play(wall_slides):
        slides, left, wedged = 0, 0, 0
        for seed in range(3):
            op = PlayFullSpace(env, np.random.default_rng(seed), wall_slides=wall_slides, corner_episodes=0.0)
            states = run_episode(env, op, 800)[0]
            slides += _slide_frames(states)
            to_corner = np.linalg.norm(states[:, None, 2:] - CORNERS[None], axis=-1).min(axis=1)
            wedged += int((to_corner < 0.05).sum())  # as far in as a corner goal
            stopped = np.flatnonzero(to_corner < WALL_SLIDE_TO[1] + 0.02)
            left += int(len(stopped) > 0 and (to_corner[stopped[-1] :] > 0.5).any())
        return slides, left, wedged

    base, _, _ = play(0.0)
    slides, left, wedged = play(1.0)
    assert slides > 40 and slides > 5 * base, (slides, base)
    assert wedged == 0 and left >= 1, (wedged, left)
    with pytest.raises(ValueError, match="wall_slides must be in"):
        PlayFullSpace(env, np.random.default_rng(0), wall_slides=1.5)
