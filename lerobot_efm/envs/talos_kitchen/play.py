"""Scripted *play* teleoperator of the Talos kitchen: long unstructured episodes for hindsight relabelling.

Goal-conditioned policies are trained on play by relabelling future frames as goals, then evaluated on
the tasks of :mod:`.tasks`. So play must reach the exact task states often (door at ``DOOR_OPEN`` /
closed, tray at ``TRAY_OUT`` / in, pot at its table home / ``POT_TABLE_MOVED`` / on the pulled-out
tray, hand at home) and travel between them in many orders, through in-between states.

:class:`TalosPlayOperator` is a closed-loop sub-task scheduler. At each sub-task boundary it reads the
real kitchen state (door angle, tray slide, pot on table / tray / lost) and draws one *feasible*
sub-task (weights :data:`WEIGHTS`, renormalised over the feasible ones):

* ``open_door`` (tray in) / ``close_door`` (any tray): 80 % to the task state (open: U(-1.20, -1.08)
  rad, the hand pushes it back to about -1.1 on its way home; close: 0), 20 % partial (U(-0.9, -0.3));
* ``pull_tray`` / ``push_tray`` (door closed, pot not on the tray): 80 % fully out (``TRAY_STOP``, the
  joint stop, within ``TRAY_TOL`` of ``TRAY_OUT``; the tray stays there) / in, 20 % partial (U(-0.20, -0.08) m);
* ``pot_to_tray`` (door closed, tray out, pot on the table): at ``POT_TRAY_XY`` +- 1 cm in x and y (inside
  the window where a placed pot rests on the tray floor, see :mod:`.tasks`);
* ``pot_to_table`` (door closed; from the tray or the table): 40 % home, 40 % moved (+- 1 cm), 20 % a
  random table point (table moves go to the other place than the current one);
* ``wander`` (1-3 random free-space points, a smaller box near home when the door is open, random wrist yaw/pitch +- 0.4/0.3 rad, gripper <= 0.4) and
  ``home`` (go to the home pose and stay 0.4-2.4 s: goal states have the hand at home).

Each sub-task is a :mod:`.primitives` generator stepped lazily (it reads ``env.data`` when advanced),
wrapped in human-like imperfections:

* detour: with p = 0.3 a free-space via point before an object sub-task;
* aborted grasp: with p = 0.15 approach the handle (+- 1.5 cm sideways, stopping 6-9 cm short),
  half of the times close the gripper there until the fingers meet (a miss seen as a fully closed gripper, never a half-closed
  one), open, back off 10 cm, then do the real sub-task (which re-approaches);
* speed: every sub-task is slowed by a factor U(1, 1.3) (linear interpolation between commands;
  never faster than the primitives, whose grasp waits assume physics advances);
* pauses: p = 0.006 per command of holding 0.2-1 s mid-motion;
* noise: temporally correlated (Ornstein-Uhlenbeck, tau 0.4 s) position noise, 3 mm per axis;
* pot grasps: at the handle bar's centre, or anywhere within +- ``pot_grasp_spread`` of it (default 0: off).

``pot_to_tray_weight`` (CLI: ``--operator.pot_to_tray_weight=9``) replaces ``pot_to_tray``'s weight: more play
with the pot carried to, resting on and taken from the tray, the states the pot tasks of the suite pass through.

A failed primitive (no weld, object not moved) is simply followed by a new choice from the real state.
Commands are clipped to ``env.action_space`` (float32, finite). Everything random comes from the given
``numpy.random.Generator``, so a run is deterministic for a seed. :func:`coverage` counts how often
the exact task states are visited (for tests and dataset cards).
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from . import primitives as P
from . import scene, tasks
from .control import matrix_to_rot6d, rot6d_to_matrix
from .tasks import DOOR_TOL, POT_TOL, TRAY_TOL, KitchenState

WEIGHTS = {
    "open_door": 3.0,
    "close_door": 3.0,
    "pull_tray": 3.0,
    "push_tray": 3.0,
    "pot_to_tray": 3.0,
    "pot_to_table": 3.0,
    "wander": 1.0,
    "home": 2.0,
}
NOISE_STD = 0.003  # m per axis
NOISE_TAU = 0.4  # s
P_DETOUR, P_ABORT, P_PAUSE_STEP, P_PARTIAL = 0.3, 0.15, 0.006, 0.2
STRETCH = (1.0, 1.3)
# m: pot grasps land U(-spread, spread) along the handle bar, as a human's would, not always at its centre. From
# the reset pose a grasp 1-2.5 cm towards -x holds at a closure of 0.6-1.0 (the centre: 0.44), the closure of the
# FM-AC policy's held grasps; in play (hand noise, varied approaches) 2 of 49 carries read above 0.6, and FM-AC
# trained on such play did worse over the 13 tasks (benchmarks/results/talos_kitchen.md): off by default
POT_GRASP_SPREAD = 0.0
MISSED_GRASP_CLOSURE = 0.9  # measured closure at which the operator sees that a grasp missed
MISSED_GRASP_MAX_STEPS = 60  # ... or gives up waiting (2.4 s)
MISSED_GRASP_SHORT = (0.06, 0.09)  # m short of the handle where aborted grasps stop
TRAY_TOP_Z = scene.TRAY_POS0[2] + 0.008  # pot base height when placed on the tray floor
_TRAY_FLOOR = 0.009  # pot base above the tray body origin once settled (env.TRAY_FLOOR)
_DOOR_CLOSED_MAX = -DOOR_TOL  # door angle above this counts as closed (tray may be operated)
_TRAY_IN_MIN = -0.02
_TRAY_OUT_RANGE = (tasks.TRAY_OUT - 0.005, tasks.TRAY_OUT + 0.005)  # start states with the tray out


# ------------------------------------------------------------------------------------ state helpers


def pot_location(env_state: np.ndarray) -> str:
    """``"table"``, ``"tray"`` or ``"lost"`` (tilted / elsewhere) from a 9-D environment state."""
    z, (qx, qy) = float(env_state[4]), env_state[6:8]
    if 1.0 - 2.0 * (qx * qx + qy * qy) < np.cos(np.radians(20)):
        return "lost"
    if abs(z - scene.TABLE_TOP) < 0.03:
        return "table"
    if abs(z - (scene.TRAY_POS0[2] + _TRAY_FLOOR)) < 0.03:
        return "tray"
    return "lost"


def table_xyz(offset) -> np.ndarray:
    """World pot base centre for a table offset from ``scene.POT_HOME``."""
    return np.array([scene.POT_HOME[0] + offset[0], scene.POT_HOME[1] + offset[1], scene.TABLE_TOP + 0.001])


def tray_xyz(slide: float, xy=tasks.POT_TRAY_XY) -> np.ndarray:
    """World pot base centre for a tray-frame ``xy`` at tray ``slide``."""
    x0, y0, z0 = scene.TRAY_POS0
    return np.array([x0 + slide + xy[0], y0 + xy[1], z0 + _TRAY_FLOOR])


def state_name(s: KitchenState) -> str:
    door = "open" if abs(s.door - tasks.DOOR_OPEN) < DOOR_TOL else "closed" if s.door == 0 else f"{s.door:g}"
    tray = "out" if abs(s.tray - tasks.TRAY_OUT) < TRAY_TOL else "in" if s.tray == 0 else f"{s.tray:g}"
    pot = (
        "tray"
        if s.pot_on == "tray"
        else (
            "home"
            if tuple(s.pot_xy) == tasks.POT_TABLE_HOME
            else "moved"
            if tuple(s.pot_xy) == tasks.POT_TABLE_MOVED
            else "table"
        )
    )
    return f"door_{door}/tray_{tray}/pot_{pot}"


def _task_states() -> dict[str, KitchenState]:
    out = {}
    for t in tasks.TASKS.values():
        for s in (t.initial, t.goal):
            out.setdefault(state_name(s), s)
    return out


TASK_STATES: dict[str, KitchenState] = _task_states()  # the distinct initial / goal states of the suite


def state_env_vec(s: KitchenState) -> np.ndarray:
    """Expected (door, tray, pot_x, pot_y, pot_z) of a task state."""
    pot = tray_xyz(s.tray, s.pot_xy) if s.pot_on == "tray" else table_xyz(s.pot_xy)
    return np.concatenate([[s.door, s.tray], pot])


def _visits(mask: np.ndarray) -> int:
    return int(mask[0]) + int(np.count_nonzero(mask[1:] & ~mask[:-1])) if mask.size else 0


def coverage(env_states) -> dict:
    """How often each exact task component / task state is met (env success tolerances).

    ``env_states``: (N, 9) environment states (``ENV_STATE_NAMES`` layout) of consecutive frames.
    Returns ``{name: {"frames": n, "visits": entries}}`` for the components ``door_open``,
    ``door_closed``, ``tray_out``, ``tray_in``, ``pot_home``, ``pot_moved``, ``pot_on_tray`` and
    every state of :data:`TASK_STATES` (``state/<name>``).
    """
    e = np.asarray(env_states, dtype=float).reshape(-1, 9)
    door, tray, pot = e[:, 0], e[:, 1], e[:, 2:5]
    near = lambda target: np.linalg.norm(pot - target, axis=1) < POT_TOL  # noqa: E731
    on_tray = (
        np.linalg.norm(pot - (tray_xyz(0.0)[None] + np.c_[tray, np.zeros((len(e), 2))]), axis=1) < POT_TOL
    )
    masks = {
        "door_open": np.abs(door - tasks.DOOR_OPEN) < DOOR_TOL,
        "door_closed": np.abs(door - tasks.DOOR_CLOSED) < DOOR_TOL,
        "tray_out": np.abs(tray - tasks.TRAY_OUT) < TRAY_TOL,
        "tray_in": np.abs(tray - tasks.TRAY_IN) < TRAY_TOL,
        "pot_home": near(table_xyz(tasks.POT_TABLE_HOME)),
        "pot_moved": near(table_xyz(tasks.POT_TABLE_MOVED)),
        "pot_on_tray": on_tray,
    }
    for name, s in TASK_STATES.items():
        v = state_env_vec(s)
        masks[f"state/{name}"] = (
            (np.abs(door - v[0]) < DOOR_TOL)
            & (np.abs(tray - v[1]) < TRAY_TOL)
            & (np.linalg.norm(pot - v[2:5], axis=1) < POT_TOL)
        )
    return {k: {"frames": int(m.sum()), "visits": _visits(m)} for k, m in masks.items()}


# ------------------------------------------------------------------------------------------ operator


def _rot_y(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]])


class TalosPlayOperator:
    """Random feasible sub-tasks with human-like imperfections (see the module docstring)."""

    def __init__(
        self,
        env,
        rng: np.random.Generator,
        noise_std: float = NOISE_STD,
        weights: dict | None = None,
        pot_grasp_spread: float = POT_GRASP_SPREAD,
        pot_to_tray_weight: float | None = None,
    ):
        self.env, self.rng = env, rng
        self.noise_std = float(noise_std)
        if not 0.0 <= pot_grasp_spread <= scene.POT_HANDLE_HALF_LENGTH - 0.02:
            raise ValueError(
                f"pot_grasp_spread={pot_grasp_spread} m: the grasp must stay on the handle bar, "
                f"within 0 .. {scene.POT_HANDLE_HALF_LENGTH - 0.02:.3f} m of its centre"
            )
        self.pot_grasp_spread = float(pot_grasp_spread)
        # its own stream (spawned: the parent's draws are unchanged), so the grasp points leave the sub-task
        # sequence of a seed as it was
        self._grasp_rng = rng.spawn(1)[0]
        self.weights = dict(WEIGHTS if weights is None else weights)
        unknown = set(self.weights) - set(WEIGHTS)
        if unknown:
            raise ValueError(f"unknown sub-task weights {sorted(unknown)}; valid: {sorted(WEIGHTS)}")
        if pot_to_tray_weight is not None:
            # the CLI's handle on the pot-on-tray share of play: pot_to_tray is drawn only in the one state that
            # allows it (door closed, tray out, pot on the table), so its weight sets how often the pot is loaded
            if not (np.isfinite(pot_to_tray_weight) and pot_to_tray_weight >= 0):
                raise ValueError(f"pot_to_tray_weight={pot_to_tray_weight}: must be a finite weight >= 0")
            self.weights["pot_to_tray"] = float(pot_to_tray_weight)
        self._home = P.home_command()
        self._ou_a = float(np.exp(-1.0 / (P.CTRL_HZ * NOISE_TAU)))
        self.stats: dict[str, dict[str, int]] = {}
        self.current: str | None = None
        self.missing_grasp = False  # inside a deliberate missed grasp (see _missed_grasp)
        self._stream: Iterator[np.ndarray] | None = None
        self._check = None
        self._last = self._home.copy()
        self._noise = np.zeros(3)
        low, high = env.action_space.low.astype(float), env.action_space.high.astype(float)
        self._low, self._high = low, high

    @property
    def done(self) -> bool:
        return False

    # -------------------------------------------------------------------------------- episode
    def random_state(self) -> KitchenState:
        """A random feasible start state: one of the task states (door/tray/pot), sometimes a partial one."""
        r = self.rng
        pot_xy = [tasks.POT_TABLE_HOME, tasks.POT_TABLE_MOVED][r.integers(2)]
        kind = r.integers(6)
        s = KitchenState(pot_xy=pot_xy)
        if kind == 1:
            s = replace(s, door=float(r.uniform(-1.10, -1.05)))
        elif kind == 2:
            s = replace(s, tray=float(r.uniform(*_TRAY_OUT_RANGE)))
        elif kind == 3:
            s = KitchenState(tray=float(r.uniform(*_TRAY_OUT_RANGE)), pot_on="tray", pot_xy=tasks.POT_TRAY_XY)
        elif kind == 4:  # partial door or tray
            s = (
                replace(s, door=float(r.uniform(-0.9, -0.25)))
                if r.random() < 0.5
                else replace(s, tray=float(r.uniform(-0.2, -0.05)))
            )
        jitter = r.uniform(-0.01, 0.01, 2) if s.pot_on == "table" else np.zeros(2)
        return replace(
            s,
            pot_xy=(s.pot_xy[0] + jitter[0], s.pot_xy[1] + jitter[1]),
            pot_yaw=float(r.uniform(-0.05, 0.05)),
        )

    def reset(self) -> dict:
        self.env.set_state(self.random_state())
        obs = self.env.observe()
        self._last = obs["agent_pos"][:10].astype(float)
        self._last[9] = P.OPEN
        self._noise = np.zeros(3)
        self._stream, self._check, self.current = None, None, None
        self.missing_grasp = False
        return obs

    def act(self, obs: dict | None = None) -> np.ndarray:
        c = self._next_nominal()
        self._last = c
        a = self._ou_a
        self._noise = a * self._noise + np.sqrt(1 - a * a) * self.noise_std * self.rng.standard_normal(3)
        out = c.copy()
        out[:3] += self._noise
        return np.clip(out, self._low, self._high).astype(np.float32)

    # -------------------------------------------------------------------------------- scheduling
    def _next_nominal(self) -> np.ndarray:
        for _ in range(100):
            if self._stream is None:
                self._stream = self._start_subtask()
            try:
                return np.asarray(next(self._stream), dtype=float)
            except StopIteration:
                self._end_subtask()
        return self._last.copy()  # unreachable in practice: sub-tasks always yield

    def read_state(self) -> tuple[float, float, str, np.ndarray]:
        """(door angle, tray slide, pot location, 9-D environment state) read from ``env.data``."""
        d, h = self.env.data, self.env.h  # read directly: observe() would render an image
        pos, quat = scene.pot_pose(d, h)
        e = np.concatenate([[scene.door_angle(d, h), scene.tray_slide(d, h)], pos, quat])
        return float(e[0]), float(e[1]), pot_location(e), e

    def _end_subtask(self) -> None:
        ok = bool(self._check()) if self._check is not None else True
        self.stats[self.current]["succeeded"] += int(ok)
        self._stream, self._check = None, None

    def feasible(self) -> dict[str, float]:
        """Weights of the sub-tasks feasible in the current kitchen state."""
        door, tray, pot, _ = self.read_state()
        closed, tray_in = door > _DOOR_CLOSED_MAX, tray > _TRAY_IN_MIN
        ok = {
            "open_door": tray_in and door > -0.95,
            "close_door": door < -0.05,
            "pull_tray": closed and pot != "tray" and tray > tasks.TRAY_OUT + 0.03,
            "push_tray": closed and pot != "tray" and tray < -0.03,
            "pot_to_tray": closed and pot == "table" and tray < tasks.TRAY_OUT + 0.02,
            "pot_to_table": closed and pot in ("table", "tray"),
            "wander": True,
            "home": True,
        }
        return {k: w for k, w in self.weights.items() if ok[k] and w > 0}

    def _start_subtask(self) -> Iterator[np.ndarray]:
        d, h = self.env.data, self.env.h
        if P.welded(d, h) is not None:  # never start holding something (e.g. a disturbed release)
            kind, gen = "release", self._release()
        else:
            cand = self.feasible()
            names = list(cand)
            p = np.array([cand[n] for n in names])
            if not names or p.sum() <= 0:
                door, tray, pot, _ = self.read_state()
                raise ValueError(
                    f"no sub-task with a positive weight is feasible in the state door={door:.2f} "
                    f"tray={tray:.3f} pot on {pot}: weights {self.weights}; give 'home' or 'wander' a weight"
                )
            kind = names[int(self.rng.choice(len(names), p=p / p.sum()))]
            kind, gen = getattr(self, f"_plan_{kind}")()
        self.current = kind
        self.stats.setdefault(kind, {"attempted": 0, "succeeded": 0})["attempted"] += 1
        return self._humanize(gen, float(self.rng.uniform(*STRETCH)))

    def _humanize(self, gen: Iterator[np.ndarray], stretch: float) -> Iterator[np.ndarray]:
        """Slow down by ``stretch`` (interpolated commands) and pause now and then."""
        prev, acc = self._last.copy(), 0.0
        for c in gen:
            c = np.asarray(c, float)
            acc += stretch
            n = max(1, int(acc))
            acc -= n
            for i in range(1, n + 1):
                yield prev + (c - prev) * (i / n)
            prev = c
            if self.rng.random() < P_PAUSE_STEP:
                for _ in range(int(self.rng.integers(5, 26))):
                    yield c.copy()

    # -------------------------------------------------------------------------------- pieces
    def _free_point(self) -> np.ndarray:
        """A random free-space hand command (clear of the pot, tray and, when open, the door panel)."""
        r = self.rng
        door = self.read_state()[0]
        if door > _DOOR_CLOSED_MAX:
            pos = np.array([r.uniform(0.25, 0.48), r.uniform(-0.22, 0.30), r.uniform(0.97, 1.20)])
        else:  # keep the elbow off the opened panel
            pos = np.array([r.uniform(0.25, 0.40), r.uniform(-0.22, 0.05), r.uniform(0.97, 1.15)])
        mat = P._rz(r.uniform(-0.4, 0.4)) @ _rot_y(r.uniform(-0.3, 0.3)) @ rot6d_to_matrix(self._home[3:9])
        return np.concatenate(
            [pos, matrix_to_rot6d(mat), [r.uniform(0.0, 0.4) if r.random() < 0.3 else P.OPEN]]
        )

    def _go(self, goal: np.ndarray, grip_open: bool = True) -> Iterator[np.ndarray]:
        goal = np.asarray(goal, float).copy()
        if grip_open:
            goal[9] = min(goal[9], 0.4)
        yield from P.move(self._last, goal, speed=float(self.rng.uniform(0.12, 0.25)))

    def _release(self):
        opened = yield from P.release(self._last, data=self.env.data, handles=self.env.h)
        yield from P.retreat(opened, -P._toward_home(opened[:3]), 0.08)

    def _prelude(self, pos, mat, direction) -> Iterator[np.ndarray]:
        """Optional detour and aborted / missed grasp before an object sub-task."""
        r = self.rng
        if r.random() < P_DETOUR:
            yield from self._go(self._free_point())
        if r.random() < P_ABORT:
            direction = np.asarray(direction, float) / np.linalg.norm(direction)
            off = r.normal(0.0, 0.015, 3)
            off -= (off @ direction) * direction  # sideways only: the stop distance alone says "short"
            pre = P.cmd(np.asarray(pos) - 0.12 * direction + off, mat, P.PRE)
            # stop 6-9 cm short: the fingertips (2.6 cm past the TCP) stay clear of the bar, so a
            # missed grasp never touches, let alone holds, what the real grasp then takes
            near = P.cmd(np.asarray(pos) - r.uniform(*MISSED_GRASP_SHORT) * direction + off, mat, P.PRE)
            yield from P.move(self._last, pre, speed=float(r.uniform(0.12, 0.22)))
            yield from P.move(pre, near, speed=0.08)
            if r.random() < 0.5:  # missed grasp: close short of the handle
                near = yield from self._missed_grasp(near)
            yield from P.hold(near, int(r.integers(3, 15)))
            yield from P.retreat(near, direction, 0.10, speed=0.12)

    def _missed_grasp(self, near: np.ndarray):
        """Close on air until the fingers meet, notice the miss, open (returns the open command).

        The re-opening must be predictable from what a policy observes: it only ever follows a
        gripper measured fully closed on nothing, never a half-closed one. An abort that opened
        the gripper mid-closure (as before) looks exactly like the start of a real grasp and
        taught policies to re-open grasps that were about to hold (issue 14).
        """
        closed = near.copy()
        closed[9] = P.CLOSED
        self.missing_grasp = True  # read by benchmarks/talos_grasps.py to tell misses from grasps
        for _ in range(MISSED_GRASP_MAX_STEPS):
            yield closed.copy()
            if scene.gripper_opening(self.env.data, self.env.h) >= MISSED_GRASP_CLOSURE:
                break
        yield from P.hold(closed, int(self.rng.integers(2, 8)))
        opened = yield from P.release(closed, steps=6, data=self.env.data, handles=self.env.h)
        self.missing_grasp = False
        return opened

    def _target(self, lo_hi_full, lo_hi_partial) -> tuple[float, bool]:
        partial = self.rng.random() < P_PARTIAL
        return float(self.rng.uniform(*(lo_hi_partial if partial else lo_hi_full))), partial

    def _door_plan(self, target: float):
        env = self.env
        pos, mat, inward = P.door_grasp_pose(env.data, env.h)
        yield from self._prelude(pos, mat, inward)
        yield from P.door_move(env.data, env.h, self._last, target)

    def _plan_open_door(self):
        target, partial = self._target((-1.20, -1.08), (-0.9, -0.3))
        goal = tasks.DOOR_OPEN if not partial else target
        self._check = lambda: abs(self.read_state()[0] - goal) < DOOR_TOL
        return "open_door" + "_partial" * partial, self._door_plan(target)

    def _plan_close_door(self):
        door = self.read_state()[0]
        partial = door < -0.7 and self.rng.random() < P_PARTIAL
        target = float(self.rng.uniform(-0.6, -0.25)) if partial else tasks.DOOR_CLOSED
        self._check = lambda: abs(self.read_state()[0] - target) < DOOR_TOL
        return "close_door" + "_partial" * partial, self._door_plan(target)

    def _tray_plan(self, target: float):
        env = self.env
        yield from self._prelude(scene.tray_handle_pos(env.data, env.h), P.rot_tray(), [1.0, 0.0, 0.0])
        yield from P.tray_move(env.data, env.h, self._last, target)

    def _plan_pull_tray(self):
        stop = tasks.TRAY_STOP  # at the joint stop: it stays
        target, partial = self._target((stop, stop), (-0.20, -0.08))
        goal = tasks.TRAY_OUT if not partial else target
        self._check = lambda: abs(self.read_state()[1] - goal) < TRAY_TOL
        return "pull_tray" + "_partial" * partial, self._tray_plan(target)

    def _plan_push_tray(self):
        tray = self.read_state()[1]
        partial = tray < -0.15 and self.rng.random() < P_PARTIAL
        target = float(self.rng.uniform(-0.12, -0.05)) if partial else tasks.TRAY_IN
        self._check = lambda: abs(self.read_state()[1] - target) < TRAY_TOL
        return "push_tray" + "_partial" * partial, self._tray_plan(target)

    def _pot_plan(self, dest: np.ndarray, place_z: float):
        env = self.env
        along = float(self._grasp_rng.uniform(-self.pot_grasp_spread, self.pot_grasp_spread))
        yield from self._prelude(
            scene.pot_handle_pos(env.data, env.h, "left", along), P.rot_down(0.0), [0.0, 0.0, -1.0]
        )
        yield from P.pot_pick_place(env.data, env.h, self._last, dest[:2], place_z=place_z, along=along)

    def _plan_pot_to_tray(self):
        tray = self.read_state()[1]
        xy = np.asarray(tasks.POT_TRAY_XY) + self.rng.uniform(-0.01, 0.01, 2)
        dest = tray_xyz(tray, xy)
        self._check = (
            lambda: np.linalg.norm(self.read_state()[3][2:5] - tray_xyz(self.read_state()[1])) < POT_TOL
        )
        return "pot_to_tray", self._pot_plan(dest, TRAY_TOP_Z)

    def _plan_pot_to_table(self):
        r = self.rng
        pot = self.read_state()[3][2:5]
        home, moved = table_xyz(tasks.POT_TABLE_HOME), table_xyz(tasks.POT_TABLE_MOVED)
        u = r.random()
        if u < 1 - P_PARTIAL:
            options = [("home", home), ("moved", moved)]
            options = [o for o in options if np.linalg.norm(pot - o[1]) > POT_TOL] or options
            name, target = options[int(r.integers(len(options)))]
            dest = target + np.r_[r.uniform(-0.01, 0.01, 2), 0.0]
        else:
            name = "random"
            dest = np.array([r.uniform(0.36, 0.56), r.uniform(-0.36, -0.10), scene.TABLE_TOP])
            target = dest
        self._check = lambda: np.linalg.norm(self.read_state()[3][2:5] - target) < POT_TOL
        return f"pot_to_table_{name}", self._pot_plan(dest, scene.TABLE_TOP)

    def _plan_wander(self):
        def gen():
            for _ in range(int(self.rng.integers(1, 4))):
                yield from self._go(self._free_point())
                yield from P.hold(self._last, int(self.rng.integers(0, 10)))

        return "wander", gen()

    def _plan_home(self):
        def gen():
            yield from self._go(self._home)
            yield from P.hold(self._home, int(self.rng.integers(10, 60)))

        return "home", gen()
