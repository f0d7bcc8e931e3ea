"""Named (initial state, goal state) tasks of the Talos kitchen env.

A :class:`KitchenState` is what a task pins down: door hinge angle, tray slide, pot placement and,
optionally, the left-hand pose (``None`` = the home posture). States are *set* directly (qpos; no
grasp needed), then physics settles for a few control steps (see ``TalosKitchenEnv``).

Pot placement: ``pot_on="table"`` uses ``pot_xy`` as a world-frame (dx, dy) offset from the scene's
``POT_HOME`` on the table top; ``pot_on="tray"`` uses ``pot_xy`` as (dx, dy) in the *tray's* frame
(on the tray floor), so a pot resting on the tray moves with the tray (its world position follows
the tray slide of the same state). On the tray the pot is turned 90 degrees (``POT_TRAY_YAW``):
with its handles along y it would not fit between the cabinet's side walls.

Door: ``DOOR_OPEN = -1.7`` rad. With the hand at home, angles from about -1.0 to -1.6 make the
opened panel touch the left hand, and around -1.5 it also grazes a pulled-out tray.

This module does not import MuJoCo.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

DOOR_CLOSED = 0.0
DOOR_OPEN = -1.7  # rad; clear of the home hand and of a pulled-out tray (see module docstring)
TRAY_IN = 0.0
TRAY_OUT = -0.25  # m (joint range is [-0.28, 0])
POT_TABLE_HOME = (0.0, 0.0)  # offset from scene.POT_HOME
POT_TABLE_MOVED = (0.10, -0.16)  # offset from scene.POT_HOME (stays on the table top)
POT_TRAY_CENTRE = (0.0, 0.0)  # in the tray frame
POT_TRAY_YAW = 1.5707963267948966  # handles along x on the tray

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
        if not -0.28 <= self.tray <= 0.0:
            raise ValueError(f"tray slide {self.tray} outside [-0.28, 0] m")
        if self.hand is not None and len(self.hand) != 10:
            raise ValueError("hand must be a 10-D command (pos 3, rot6d 6, gripper 1) or None")


@dataclass(frozen=True)
class KitchenTask:
    name: str
    initial: KitchenState
    goal: KitchenState
    description: str


_closed = KitchenState()
_open = KitchenState(door=DOOR_OPEN)
_open_out = KitchenState(door=DOOR_OPEN, tray=TRAY_OUT)
_open_out_pot_tray = replace(_open_out, pot_on="tray", pot_xy=POT_TRAY_CENTRE, pot_yaw=POT_TRAY_YAW)
_open_in_pot_tray = replace(_open_out_pot_tray, tray=TRAY_IN)
_closed_pot_tray = replace(_open_in_pot_tray, door=DOOR_CLOSED)

_TASK_LIST = [
    KitchenTask("open_door", _closed, _open, "open the cabinet door"),
    KitchenTask("close_door", _open, _closed, "close the cabinet door"),
    KitchenTask("pull_tray", _open, _open_out, "pull the tray out of the open cabinet"),
    KitchenTask("push_tray", _open_out, _open, "push the tray back into the cabinet"),
    KitchenTask("move_pot_on_table", _closed, replace(_closed, pot_xy=POT_TABLE_MOVED),
                "slide the pot across the table, away from the cabinet"),
    KitchenTask("pot_to_tray", _open_out, _open_out_pot_tray, "put the pot from the table onto the tray"),
    KitchenTask("pot_to_table", _open_out_pot_tray, _open_out, "put the pot from the tray back on the table"),
    KitchenTask("push_tray_with_pot", _open_out_pot_tray, _open_in_pot_tray,
                "push the tray carrying the pot into the cabinet"),
    KitchenTask("pull_tray_with_pot", _open_in_pot_tray, _open_out_pot_tray,
                "pull the tray carrying the pot out of the cabinet"),
    KitchenTask("open_door_pull_tray", _closed, _open_out, "open the door and pull the tray out"),
    KitchenTask("push_tray_close_door", _open_out, _closed, "push the tray in and close the door"),
    KitchenTask("unload_pot", _closed_pot_tray, _open_out,
                "open the door, pull the tray out and put the pot on the table"),
    # Fig. 8 of the paper: the long-horizon task
    KitchenTask(LONG_TASK, _open_out, _closed_pot_tray,
                "put the pot on the tray, push the tray in and close the door"),
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
