"""Named (initial state, goal state) tasks of the Talos kitchen env.

A :class:`KitchenState` is what a task pins down: door hinge angle, tray slide, pot placement and,
optionally, the left-hand pose (``None`` = the home posture). States are *set* directly (qpos; no
grasp needed), then physics settles for a few control steps (see ``TalosKitchenEnv``).

Pot placement: ``pot_on="table"`` uses ``pot_xy`` as a world-frame (dx, dy) offset from the scene's
``POT_HOME`` on the table top; ``pot_on="tray"`` uses ``pot_xy`` as (dx, dy) in the *tray's* frame
(on the tray floor), so a pot resting on the tray moves with the tray (its world position follows
the tray slide of the same state).

Every task is meant to be achievable by the scripted primitives of :mod:`.primitives` (checked
for several tasks in ``tests/test_talos_tasks_feasible.py``), which sets these constraints:

* Door: ``DOOR_OPEN = -1.08`` rad. ``primitives.open_door`` reaches about -1.2 rad (the IK cannot
  follow the handle arc much past -1.3), but from about -1.1 rad on the opened panel touches the
  left hand in its home posture (the goal states have the hand at home), so -1.08 is the widest
  contact-free opening. A door opened to -1.2 and the hand then sent home ends near -1.1, within
  the 0.15 rad tolerance either way.
* Tray: the tray is only operated with the door **closed** (with the door open the straight
  approach to the tray handle sweeps the arm through the door panel). ``TRAY_OUT = -0.32`` m, 1 cm
  inside the joint stop ``TRAY_STOP`` where the primitives leave it.
* Pot on the tray: placed as picked (handles along y, ``pot_yaw = 0``; turning the pot while it is
  carried is not reliable). Thus oriented, the pot does not fit through the drawer slot (the
  handles hit the slot walls), so a pot only rides on the *pulled-out* tray: there are no
  "push / pull the tray carrying the pot" tasks. Where it can stand is bounded by the tray's front
  wall (towards the robot) and by the closed door above the tray's back half, which a pot carried
  at the primitives' lift height hits. With the tray stop at -0.28 m scripted placements rested on
  the tray floor from tray-frame x -0.08 to -0.04 only, the edges chaotic (from the task's initial
  tray -0.27, at -0.07 and -0.075 the pot rests on the front wall's rim): the old goal -0.06 had
  1.5-2 cm either way, the play operator's U(-1.5, 0) cm jitter reached the rim (20 % of the play's
  frames with the pot resting on the tray are > 2 cm high) and so did most of a policy's store_pot
  misses. With the stop at -0.33 they rest on the floor from -0.07 to +0.01
  (``benchmarks/talos_tray_placement_window.py``); ``POT_TRAY_XY`` is 3 cm towards the robot, that
  window's centre.

Deviation from the paper's long-horizon task (Fig. 8: put the pot on the tray, push the tray in,
close the door): ``store_pot`` starts with the door open, the tray in and the pot on the table and
ends with the door closed, the tray pulled out and the pot on it, i.e. it chains three sub-tasks
(close the door, pull the tray out, put the pot on the tray).

This module does not import MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

DOOR_CLOSED = 0.0
DOOR_OPEN = -1.08  # rad; reachable by primitives.open_door, clear of the home hand (see module docstring)
TRAY_IN = 0.0
TRAY_STOP = -0.33  # m, the tray slide's joint limit (fully out)
TRAY_OUT = -0.32  # m, within TRAY_TOL of the stop
POT_TABLE_HOME = (0.0, 0.0)  # offset from scene.POT_HOME
POT_TABLE_MOVED = (0.10, -0.16)  # offset from scene.POT_HOME (stays on the table top)
POT_TRAY_XY = (-0.03, 0.0)  # in the tray frame: towards the robot, clear of the front wall and the door
POT_TRAY_CENTRE = POT_TRAY_XY  # backwards-compatible name
POT_TRAY_YAW = 0.0  # as picked and placed by primitives.pot_pick_place (handles along y)

# success tolerances (absolute differences to the goal state)
DOOR_TOL = 0.15  # rad
TRAY_TOL = 0.03  # m
POT_TOL = 0.05  # m, Euclidean distance of the pot base centre (orientation not checked)

ALL = "all"
LONG_TASK = "store_pot"


@dataclass(frozen=True)
class KitchenState:
    door: float = DOOR_CLOSED
    tray: float = TRAY_IN
    pot_on: str = "table"  # "table" (pot_xy: offset from POT_HOME) or "tray" (pot_xy in the tray frame)
    pot_xy: tuple[float, float] = POT_TABLE_HOME
    pot_yaw: float = 0.0
    hand: tuple[float, ...] | None = None  # 10-D hand command (pos, rot6d, gripper); None = home

    def __post_init__(self):
        if self.pot_on not in ("table", "tray"):
            raise ValueError(f"pot_on must be 'table' or 'tray', got {self.pot_on!r}")
        if not -2.0 <= self.door <= 0.0:
            raise ValueError(f"door angle {self.door} outside [-2, 0] rad")
        if not TRAY_STOP <= self.tray <= 0.0:
            raise ValueError(f"tray slide {self.tray} outside [{TRAY_STOP}, 0] m")
        if self.hand is not None and len(self.hand) != 10:
            raise ValueError("hand must be a 10-D command (pos 3, rot6d 6, gripper 1) or None")


@dataclass(frozen=True)
class KitchenTask:
    name: str
    initial: KitchenState
    goal: KitchenState
    description: str

    @property
    def num_objects(self) -> int:
        """Objects whose state differs between the initial and the goal state (door, tray, pot)."""
        a, b = self.initial, self.goal
        return (
            int(a.door != b.door) + int(a.tray != b.tray) + int((a.pot_on, a.pot_xy) != (b.pot_on, b.pot_xy))
        )


_closed = KitchenState()
_open = KitchenState(door=DOOR_OPEN)
_out = KitchenState(tray=TRAY_OUT)  # door closed: the tray is only operated with the door closed
_out_pot_tray = replace(_out, pot_on="tray", pot_xy=POT_TRAY_XY, pot_yaw=POT_TRAY_YAW)

_TASK_LIST = [
    KitchenTask("open_door", _closed, _open, "open the cabinet door"),
    KitchenTask("close_door", _open, _closed, "close the cabinet door"),
    KitchenTask("pull_tray", _closed, _out, "pull the tray out of the cabinet"),
    KitchenTask("push_tray", _out, _closed, "push the tray back into the cabinet"),
    KitchenTask(
        "move_pot_on_table",
        _closed,
        replace(_closed, pot_xy=POT_TABLE_MOVED),
        "slide the pot across the table, away from the cabinet",
    ),
    KitchenTask("pot_to_tray", _out, _out_pot_tray, "put the pot from the table onto the tray"),
    KitchenTask("pot_to_table", _out_pot_tray, _out, "put the pot from the tray back on the table"),
    KitchenTask("close_door_pull_tray", _open, _out, "close the door and pull the tray out"),
    KitchenTask("push_tray_open_door", _out, _open, "push the tray in and open the door"),
    KitchenTask("pull_tray_load_pot", _closed, _out_pot_tray, "pull the tray out and put the pot on it"),
    KitchenTask(
        "unload_pot", _out_pot_tray, _closed, "put the pot from the tray on the table and push the tray in"
    ),
    KitchenTask(
        "unload_pot_open_door",
        _out_pot_tray,
        _open,
        "put the pot on the table, push the tray in and open the door",
    ),
    # long-horizon task (the paper's Fig. 8, adapted: see the module docstring)
    KitchenTask(
        LONG_TASK, _open, _out_pot_tray, "close the door, pull the tray out and put the pot on the tray"
    ),
]
TASKS: dict[str, KitchenTask] = {t.name: t for t in _TASK_LIST}
TASK_NAMES: tuple[str, ...] = tuple(TASKS)  # suite order used by the "all" task
VALID_TASKS: tuple[str, ...] = TASK_NAMES + (ALL,)


def check_task(task: str | None) -> str:
    if task not in VALID_TASKS:
        raise ValueError(f"Unknown Talos kitchen task {task!r}; valid tasks: {list(VALID_TASKS)}")
    return task


def get_task(task: str) -> KitchenTask:
    check_task(task)
    if task == ALL:
        raise ValueError(f"{ALL!r} is a suite, not a single task; pick one of {list(TASK_NAMES)}")
    return TASKS[task]


def describe(task: str) -> str:
    if check_task(task) == ALL:
        return f"the whole Talos kitchen suite ({len(TASK_NAMES)} tasks)"
    return TASKS[task].description
