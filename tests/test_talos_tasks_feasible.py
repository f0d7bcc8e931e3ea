"""Talos kitchen tasks are achievable: the scripted primitives, fed as env actions from a task's
initial state, reach its goal (``info["is_success"]``)."""

import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np  # noqa: E402
import pytest  # noqa: E402

pytest.importorskip("mujoco")

from lerobot_efm.envs.talos_kitchen import primitives, scene, tasks  # noqa: E402
from lerobot_efm.envs.talos_kitchen.env import TalosKitchenEnv  # noqa: E402


@pytest.fixture(scope="module")
def env():
    e = TalosKitchenEnv(task="open_door", image_size=32, randomize=False, terminate_on_success=False)
    yield e
    e.close()


def _tray_top_xy(env, slide):
    """World (x, y) of the tray-frame point ``tasks.POT_TRAY_XY`` at tray slide ``slide``."""
    x0, y0, _ = scene.TRAY_POS0
    return (x0 + slide + tasks.POT_TRAY_XY[0], y0 + tasks.POT_TRAY_XY[1])


def _plans(env):
    """Per task: primitive generator factories (each called with the last command), one per sub-task."""
    d, h = env.data, env.h
    door = {
        "open": lambda c: primitives.open_door(d, h, c, tasks.DOOR_OPEN),
        "close": lambda c: primitives.close_door(d, h, c, tasks.DOOR_CLOSED),
    }
    tray = {
        "pull": lambda c: primitives.tray_move(d, h, c, tasks.TRAY_OUT),
        "push": lambda c: primitives.tray_move(d, h, c, tasks.TRAY_IN),
    }
    top = scene.TRAY_POS0[2] + 0.008
    home = scene.POT_HOME
    pot = {
        "to_tray": lambda c: primitives.pot_pick_place(
            d, h, c, _tray_top_xy(env, tasks.TRAY_OUT), place_z=top
        ),
        "to_table": lambda c: primitives.pot_pick_place(
            d, h, c, (home[0] + tasks.POT_TABLE_HOME[0], home[1] + tasks.POT_TABLE_HOME[1])
        ),
        "moved": lambda c: primitives.pot_pick_place(
            d, h, c, (home[0] + tasks.POT_TABLE_MOVED[0], home[1] + tasks.POT_TABLE_MOVED[1])
        ),
    }
    return {
        "open_door": [door["open"]],
        "close_door": [door["close"]],
        "pull_tray": [tray["pull"]],
        "push_tray": [tray["push"]],
        "pot_to_tray": [pot["to_tray"]],
        "pot_to_table": [pot["to_table"]],
        "move_pot_on_table": [pot["moved"]],
        "close_door_pull_tray": [door["close"], tray["pull"]],
        "push_tray_open_door": [tray["push"], door["open"]],
        "pull_tray_load_pot": [tray["pull"], pot["to_tray"]],
        "unload_pot": [pot["to_table"], tray["push"]],
        "unload_pot_open_door": [pot["to_table"], tray["push"], door["open"]],
        "store_pot": [door["close"], tray["pull"], pot["to_tray"]],
    }


def run_task(env, name, settle=25):
    """Reset to ``name``, run its primitives, go home; returns (final info, steps). Every command goes through
    ``env.advance`` (exactly ``env.step``'s physics, without rendering an observation, which dominates a step);
    the last settling command is a real ``env.step``, whose info says whether the goal is reached."""
    obs, info = env.reset(seed=0, options={"task": name})
    assert not info["is_success"]
    last = obs["agent_pos"][:10].astype(float)
    n = 0
    for make in _plans(env)[name]:
        for c in make(last):
            env.advance(c)
            last, n = np.asarray(c, float), n + 1
    home = primitives.home_command()
    for c in primitives.move(last, home):  # back to the home posture of the goal states, then settle
        env.advance(c)
        n += 1
    for _ in range(settle - 1):
        env.advance(home)
    obs, _, _, _, info = env.step(home)
    return info, n + settle


def test_every_task_has_a_primitive_plan(env):
    # all of them reach their goal (checked by hand: ~4-16 s each); the slow ones are not run here
    assert set(_plans(env)) == set(tasks.TASK_NAMES)


@pytest.mark.parametrize("name", ["open_door", "close_door", "pull_tray", "pot_to_tray"])
def test_short_task_feasible(env, name):
    info, n = run_task(env, name)
    assert info["is_success"], (name, info)


def test_chain_close_door_pull_tray_feasible(env):
    info, n = run_task(env, "close_door_pull_tray")
    assert info["is_success"], info


FAST_TASKS = {"open_door", "close_door", "pull_tray", "pot_to_tray", "close_door_pull_tray"}


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(set(tasks.TASK_NAMES) - FAST_TASKS))
def test_remaining_task_feasible(env, name):
    """The other task plans, the long ``store_pot`` among them (4-16 s each): ``make test-slow``, run by CI."""
    info, n = run_task(env, name)
    assert info["is_success"], (name, info)


def test_pot_goal_on_the_tray_has_room_either_way(env):
    """A pot set down 3 cm off the tray goal, towards the robot or the cabinet, still rests on the tray floor.

    With the tray stop at -0.28 the pot had 1.5-2 cm: 3 cm towards the cabinet the closed door knocked it
    onto a rim (``benchmarks/talos_tray_placement_window.py``)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from talos_tray_placement_window import place_at

    for dx in (tasks.POT_TRAY_XY[0] - 0.03, tasks.POT_TRAY_XY[0] + 0.03):
        placed = place_at(env, dx)
        assert placed["on_floor"], placed
