"""The scripted play operator: valid deterministic commands, and play that really moves door, tray and pot."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("mujoco")

from lerobot_efm.envs.talos_kitchen import play, tasks  # noqa: E402
from lerobot_efm.envs.talos_kitchen.env import TalosKitchenEnv  # noqa: E402


@pytest.fixture(scope="module")
def env():
    e = TalosKitchenEnv(image_size=32, randomize=False, terminate_on_success=False)
    e.reset(seed=0)
    yield e
    e.close()


def _record(env, seed, steps):
    """Recorder loop of the operator protocol through the real ``env.step``; returns (actions, env states)."""
    env.reset(seed=0)
    op = play.TalosPlayOperator(env, np.random.default_rng(seed))
    obs = op.reset()
    actions, states = [], [obs["environment_state"]]
    for _ in range(steps):
        a = op.act(obs)
        obs, *_ = env.step(a)
        actions.append(a)
        states.append(obs["environment_state"])
    assert op.done is False
    return np.array(actions), np.array(states)


def test_commands_valid_and_deterministic(env):
    a1, s1 = _record(env, seed=3, steps=120)
    a2, s2 = _record(env, seed=3, steps=120)
    a3, _ = _record(env, seed=4, steps=120)
    assert a1.shape == (120, 10) and a1.dtype == np.float32
    assert np.isfinite(a1).all()
    assert all(env.action_space.contains(a) for a in a1)
    np.testing.assert_array_equal(a1, a2)
    np.testing.assert_array_equal(s1, s2)
    assert not np.array_equal(a1, a3)


def test_reset_states_are_feasible(env):
    op = play.TalosPlayOperator(env, np.random.default_rng(0))
    for _ in range(12):
        obs = op.reset()
        door, tray = obs["environment_state"][:2]
        assert set(obs) == set(env.observation_space.spaces)
        assert play.pot_location(obs["environment_state"]) in ("table", "tray")
        assert not (door < -tasks.DOOR_TOL and tray < -0.02), "door open with the tray out is never a start"


def test_coverage_counts_task_states():
    closed = play.state_env_vec(tasks.TASKS["open_door"].initial)
    on_tray = play.state_env_vec(tasks.TASKS["pot_to_tray"].goal)
    quat = np.array([1.0, 0, 0, 0])
    e = np.array(
        [
            np.r_[closed, quat],
            np.r_[on_tray, quat],
            np.r_[closed, quat],
            np.r_[closed + [0.5, 0, 0, 0, 0], quat],
        ]
    )
    cov = play.coverage(e)
    assert cov["state/door_closed/tray_in/pot_home"] == {"frames": 2, "visits": 2}
    assert cov["state/door_closed/tray_out/pot_tray"] == {"frames": 1, "visits": 1}
    assert cov["pot_on_tray"]["frames"] == 1 and cov["door_open"]["frames"] == 0
    assert len(play.TASK_STATES) == 5


def test_play_moves_door_tray_and_pot(env):
    """A few thousand steps (fast physics-only ``env.advance``) change every object, in both directions."""
    # Two operators (seeds 3 and 4), two 3000-step episodes each: whether one seed's 6000 steps put the pot on the
    # tray is a chance event that floating-point details of the CPU decide (seed 4 did on one machine, not on
    # another); together they cover every task state on both.
    visits, stats = {}, []
    for seed in (3, 4):
        env.reset(seed=0)
        op = play.TalosPlayOperator(env, np.random.default_rng(seed))
        states = []
        for _ in range(2):
            states.append(op.reset()["environment_state"])
            for _ in range(3000):
                env.advance(op.act(None))
                states.append(op.read_state()[3])
        s = np.array(states, dtype=float)
        assert s[:, 0].min() < -0.9 and s[:, 1].min() < -0.2
        assert np.linalg.norm(s[:, 2:5] - s[0, 2:5], axis=1).max() > 0.1
        for name, c in play.coverage(s).items():
            visits[name] = visits.get(name, 0) + c["visits"]
        stats.append(op.stats)
    for name in ("door_open", "door_closed", "tray_out", "tray_in", "pot_home", "pot_moved", "pot_on_tray"):
        assert visits[name] >= 1, (name, visits)
    for st in stats:
        assert sum(v["attempted"] for v in st.values()) >= 15, st
        assert sum(v["succeeded"] for k, v in st.items() if k not in ("home", "wander")) >= 8, st


def _pot_grasp_points(env, monkeypatch, n, **kwargs):
    """The ``along`` of the handle point each of ``n`` planned pot sub-tasks aims at (read when they start)."""
    seen = []
    real = play.scene.pot_handle_pos

    def spy(data, handles, side="left", along=0.0):
        seen.append(along)
        return real(data, handles, side, along)

    monkeypatch.setattr(play.scene, "pot_handle_pos", spy)
    env.reset(seed=0)
    op = play.TalosPlayOperator(env, np.random.default_rng(5), **kwargs)
    points = []
    for _ in range(n):
        seen.clear()
        next(op._pot_plan(play.table_xyz(tasks.POT_TABLE_MOVED), play.scene.TABLE_TOP))
        points.append(seen[0])
    return np.array(points)


def test_pot_grasps_spread_along_the_handle_bar(env, monkeypatch):
    along = _pot_grasp_points(env, monkeypatch, 40, pot_grasp_spread=0.025)
    assert len(along) == 40 and np.abs(along).max() <= 0.025
    assert along.std() > 0.01 and (along < -0.01).sum() >= 5  # the held grasps that read a high closure
    assert not _pot_grasp_points(env, monkeypatch, 5).any()  # default: at the bar's centre
    with pytest.raises(ValueError, match="pot_grasp_spread=0.06"):
        play.TalosPlayOperator(env, np.random.default_rng(0), pot_grasp_spread=0.06)


def test_pot_to_tray_weight_option_sets_how_often_the_pot_is_loaded(env):
    """``--operator.pot_to_tray_weight`` reaches the operator through the recorder's config and weighs the draw."""
    from lerobot_efm.operators import OperatorConfig, register_operators

    register_operators()
    config = OperatorConfig.get_choice_class("talos_kitchen_play")(pot_to_tray_weight=9.0)
    env.reset(seed=0)
    op = config.build(env, np.random.default_rng(0))
    assert op.weights["pot_to_tray"] == 9.0 and op.weights["pot_to_table"] == play.WEIGHTS["pot_to_table"]
    assert play.TalosPlayOperator(env, np.random.default_rng(0)).weights == play.WEIGHTS  # default unchanged
    # in the one state that allows a load (door closed, tray out, pot on the table) it is drawn
    # 9 / (9 + push_tray 3 + pot_to_table 3 + wander 1 + home 2) = 0.5 of the times (default weights: 0.25)
    env.set_state(tasks.TASKS["pot_to_tray"].initial)
    assert op.feasible()["pot_to_tray"] == 9.0
    draws = [op._start_subtask() and op.current for _ in range(200)]
    assert 0.4 < draws.count("pot_to_tray") / 200 < 0.6, draws
    with pytest.raises(ValueError, match="pot_to_tray_weight=-1"):
        play.TalosPlayOperator(env, np.random.default_rng(0), pot_to_tray_weight=-1.0)
