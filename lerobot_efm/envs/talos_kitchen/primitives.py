"""Scripted motion primitives for the Talos kitchen (10-D absolute left-hand commands at 25 Hz).

Every primitive is a **generator** of 10-D commands (``pos 3 + rot6d 6 + gripper 1``, the
:class:`~.control.CartesianController` layout). Generators read the object state from ``data``
lazily, i.e. when they are advanced, so they can be composed with ``yield from`` and adapt to the
current door angle / tray slide / pot pose. :func:`execute` runs one on a controller.

Grasp conventions (``R`` = TCP rotation; the fingers point along the TCP's -z axis and close
across its y axis):

* door handle (vertical bar): fingers horizontal into the door, closing axis horizontal
  (:func:`rot_forward` with the door's yaw);
* tray handle (horizontal bar along y): fingers forward, closing axis vertical (:func:`rot_tray`);
* pot handle (horizontal bar along x): fingers down, closing axis along y (:func:`rot_down`).

Known limits (measured): the door opens to about -1.2 rad (the IK cannot follow the arc much past
-1.3, the handle then comes too close to the chest); with the door open, the straight approach to
the tray handle sweeps the arm through the door panel and pushes the door shut, so operate the
tray with the door closed (or add a via point); turning the pot while carrying it
(``place_yaw != 0``) is not reliable (IK error, the pot tilts ~25 deg).

The grasps rely on the weld-on-contact simplification of :class:`~.control.GraspWeld` (gripper
command > 0.5 and both finger sides touching the handle).
"""

from __future__ import annotations

from collections.abc import Iterator
from functools import lru_cache

import numpy as np

from . import scene
from .control import hand_pose10, matrix_to_rot6d, rot6d_to_matrix

OPEN, CLOSED, PRE = 0.0, 1.0, 0.3  # gripper commands (PRE: half-open pre-grasp, easier clearance)
SPEED = 0.20  # m/s, default Cartesian speed
CTRL_HZ = 25.0
DOOR_YAW_GAIN = 0.5  # hand yaw = gain * door yaw (the connect grasp lets the handle turn in the hand)


def _rz(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def _rx(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])


# fingers along +x (TCP z = -x), closing axis (TCP y) = +y, TCP x = up
_FORWARD = np.column_stack([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])


def rot_forward(yaw: float = 0.0) -> np.ndarray:
    """Fingers horizontal pointing along ``(cos yaw, sin yaw, 0)``, closing axis horizontal."""
    return _rz(yaw) @ _FORWARD


def rot_tray(pitch: float = 0.8) -> np.ndarray:
    """Tray handle grasp (vertical bar, z ~ 0.80 m): fingers forward, tilted ``pitch`` rad downwards.

    Horizontal fingers cannot reach that low (IK error ~0.15 m); at 0.8 rad the whole pull is exact.
    """
    c, s = np.cos(pitch), np.sin(pitch)
    return np.array([[c, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, c]]) @ _FORWARD


def rot_down(yaw: float = 0.0) -> np.ndarray:
    """Fingers pointing down, closing axis along ``(-sin yaw, cos yaw, 0)`` (bar along yaw)."""
    return _rz(yaw)


def cmd(pos, mat, grip: float) -> np.ndarray:
    return np.concatenate([np.asarray(pos, float), matrix_to_rot6d(np.asarray(mat, float)), [float(grip)]])


@lru_cache(maxsize=1)
def _home10() -> tuple:
    _, data, h = scene.build_kitchen()
    return tuple(hand_pose10(data, h))


def home_command() -> np.ndarray:
    """Home hand pose (TCP near (0.31, 0.20, 0.99), fingers forward) with the gripper open."""
    c = np.array(_home10())
    c[9] = OPEN
    return c


def _slerp_mats(r0: np.ndarray, r1: np.ndarray, t: float) -> np.ndarray:
    rel = r0.T @ r1
    ang = np.arccos(np.clip((np.trace(rel) - 1) / 2, -1, 1))
    if ang < 1e-6:
        return r1.copy()
    w = np.array([rel[2, 1] - rel[1, 2], rel[0, 2] - rel[2, 0], rel[1, 0] - rel[0, 1]])
    n = np.linalg.norm(w)
    if n < 1e-9:  # 180 deg: pick any axis orthogonal solution via eigenvector
        vals, vecs = np.linalg.eigh(rel + rel.T)
        w = vecs[:, -1]
    else:
        w = w / n
    k = np.array([[0, -w[2], w[1]], [w[2], 0, -w[0]], [-w[1], w[0], 0]])
    a = ang * t
    return r0 @ (np.eye(3) + np.sin(a) * k + (1 - np.cos(a)) * k @ k)


def move(
    start: np.ndarray, goal: np.ndarray, speed: float = SPEED, ang_speed: float = 1.2, min_steps: int = 2
) -> Iterator[np.ndarray]:
    """Straight-line (position) + slerp (rotation) interpolation from ``start`` to ``goal``.

    The gripper entry is interpolated too. The last command is ``goal`` itself.
    """
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    r0, r1 = rot6d_to_matrix(start[3:9]), rot6d_to_matrix(goal[3:9])
    dist = np.linalg.norm(goal[:3] - start[:3])
    ang = np.arccos(np.clip((np.trace(r0.T @ r1) - 1) / 2, -1, 1))
    n = max(min_steps, int(np.ceil(max(dist / speed, ang / ang_speed) * CTRL_HZ)))
    for i in range(1, n + 1):
        t = i / n
        s = 0.5 - 0.5 * np.cos(np.pi * t)  # smooth start / stop
        pos = start[:3] + s * (goal[:3] - start[:3])
        yield cmd(pos, _slerp_mats(r0, r1, s), start[9] + s * (goal[9] - start[9]))


def hold(command: np.ndarray, steps: int) -> Iterator[np.ndarray]:
    for _ in range(int(steps)):
        yield np.asarray(command, float).copy()


def set_gripper(command: np.ndarray, grip: float, steps: int = 12) -> Iterator[np.ndarray]:
    """Keep the pose, switch the gripper command (close = grasp, open = release), then wait."""
    c = np.asarray(command, float).copy()
    c[9] = grip
    yield from hold(c, steps)


def welded(data, handles) -> str | None:
    """Name of the object currently held by the weld-on-contact grasp (or None)."""
    for name in ("pot", "door", "tray"):
        eq = getattr(handles, f"{name}_weld")
        if eq >= 0 and data.eq_active[eq]:
            return name
    return None


def grasp(
    command: np.ndarray, steps: int = 15, data=None, handles=None, max_steps: int = 40
) -> Iterator[np.ndarray]:
    """Close the gripper in place; with ``data``/``handles`` also wait (up to ``max_steps``) for the weld."""
    yield from set_gripper(command, CLOSED, steps)
    if data is not None:
        c = np.asarray(command, float).copy()
        c[9] = CLOSED
        for _ in range(max_steps):
            if welded(data, handles):
                break
            yield c.copy()
        yield from hold(c, 3)


def release(command: np.ndarray, steps: int = 12, data=None, handles=None, max_steps: int = 40):
    """Open the gripper in place; with ``data``/``handles`` also wait until it is measured open.

    Returns (``yield from``) the open command, the one to retreat from: retreating from the closed
    command would close the gripper again and re-grasp the object.
    """
    yield from set_gripper(command, OPEN, steps)
    c = np.asarray(command, float).copy()
    c[9] = OPEN
    if data is not None:
        for _ in range(max_steps):
            if scene.gripper_opening(data, handles) < 0.1:
                break
            yield c.copy()
    return c


def approach(
    start: np.ndarray, pos, mat, direction, standoff: float = 0.10, grip: float = PRE, speed: float = SPEED
) -> Iterator[np.ndarray]:
    """Go to ``standoff`` before ``pos`` along ``-direction`` (the approach direction), then onto it."""
    direction = np.asarray(direction, float) / np.linalg.norm(direction)
    pre = cmd(np.asarray(pos) - standoff * direction, mat, grip)
    yield from move(start, pre, speed)
    yield from hold(pre, 5)
    yield from move(pre, cmd(pos, mat, grip), speed * 0.5)


def retreat(start: np.ndarray, direction, dist: float = 0.10, speed: float = SPEED) -> Iterator[np.ndarray]:
    """Move back by ``dist`` along ``-direction`` keeping orientation and gripper."""
    start = np.asarray(start, float)
    goal = start.copy()
    goal[:3] -= dist * np.asarray(direction, float) / np.linalg.norm(direction)
    yield from move(start, goal, speed)


# ------------------------------------------------------------------------------------------ door


def door_yaw(angle: float) -> float:
    """World yaw of the door panel for hinge ``angle`` (the hinge axis is -z)."""
    return -float(angle)


def door_grasp_pose(data, handles, angle: float | None = None, yaw_gain: float = DOOR_YAW_GAIN):
    """(pos, mat, inward direction) of the door-handle grasp at the current or a given angle."""
    a = scene.door_angle(data, handles) if angle is None else float(angle)
    pos = scene.door_handle_pos(data, handles, a)
    yaw = yaw_gain * door_yaw(a)
    inward = np.array([np.cos(door_yaw(a)), np.sin(door_yaw(a)), 0.0])
    return pos, rot_forward(yaw), inward


def door_arc(
    data, handles, start: np.ndarray, target_angle: float, step: float = 0.03, yaw_gain: float = DOOR_YAW_GAIN
) -> Iterator[np.ndarray]:
    """Gripper closed, TCP along the handle's arc from the current door angle to ``target_angle``.

    Waypoints are computed from the hinge geometry every ``step`` rad (~0.75 rad/s at 25 Hz).
    """
    a0 = scene.door_angle(data, handles)
    n = max(2, int(np.ceil(abs(target_angle - a0) / step)))
    prev = np.asarray(start, float)
    for a in np.linspace(a0, target_angle, n + 1)[1:]:
        pos, mat, _ = door_grasp_pose(data, handles, a, yaw_gain)
        c = cmd(pos, mat, CLOSED)
        yield c
        prev = c
    yield from hold(prev, 8)


def _toward_home(pos) -> np.ndarray:
    """Unit vector from ``pos`` towards the home TCP position (a retreat direction that stays reachable)."""
    v = home_command()[:3] - np.asarray(pos, float)
    return v / max(np.linalg.norm(v), 1e-9)


def door_move(
    data, handles, start: np.ndarray, target_angle: float, standoff: float = 0.07
) -> Iterator[np.ndarray]:
    """Approach the door handle, grasp, move the door along the arc to ``target_angle``, release, retreat."""
    pos, mat, inward = door_grasp_pose(data, handles)
    yield from approach(start, pos, mat, inward, standoff=standoff)
    c = cmd(pos, mat, CLOSED)
    yield from grasp(c, data=data, handles=handles)
    last = c
    for last in door_arc(data, handles, c, target_angle):
        yield last
    opened = yield from release(last, steps=10, data=data, handles=handles)
    away = -_toward_home(last[:3])
    for last in retreat(opened, away, 0.08):
        yield last


def open_door(data, handles, start: np.ndarray, target_angle: float = -1.2) -> Iterator[np.ndarray]:
    """Grasp the handle of the closed door and pull it open along the arc to ``target_angle``."""
    yield from door_move(data, handles, start, target_angle)


def close_door(data, handles, start: np.ndarray, target_angle: float = 0.0) -> Iterator[np.ndarray]:
    """Grasp the handle of an open door and push it back along the arc to ``target_angle``."""
    yield from door_move(data, handles, start, target_angle)


# ------------------------------------------------------------------------------------------ tray


def tray_move(data, handles, start: np.ndarray, target_slide: float) -> Iterator[np.ndarray]:
    """Approach the tray handle, grasp, slide to ``target_slide`` (m), release, retreat."""
    pos = scene.tray_handle_pos(data, handles)
    mat = rot_tray()
    fwd = np.array([1.0, 0.0, 0.0])
    yield from approach(start, pos, mat, fwd, standoff=0.10)
    c = cmd(pos, mat, CLOSED)
    yield from grasp(c, data=data, handles=handles)
    goal = cmd(scene.tray_handle_pos(data, handles, target_slide), mat, CLOSED)
    yield from move(c, goal, speed=0.10)
    yield from hold(goal, 10)
    released = yield from release(goal, data=data, handles=handles)
    yield from retreat(released, fwd, 0.08)


# ------------------------------------------------------------------------------------------- pot


def pot_pick_place(
    data,
    handles,
    start: np.ndarray,
    place_xy,
    place_z: float = scene.TABLE_TOP,
    lift: float = 0.12,
    side: str = "left",
    place_yaw: float = 0.0,
    along: float = 0.0,
) -> Iterator[np.ndarray]:
    """Grasp the pot by a handle from above, lift, carry, put its base centre at ``(place_xy, place_z)``.

    ``place_yaw`` (rad) turns the pot about the vertical while it is carried (the hand turns with
    it); e.g. ``pi / 2`` puts the grasped +y handle towards the robot (handles along x). ``along`` (m):
    the grasp point on the handle bar, from its centre (from the reset pose a held grasp 1-2.5 cm towards -x
    reads a closure of 0.6-1.0, at the centre 0.44: ``benchmarks/results/talos_pot_grasp_offsets.md``).
    """
    hpos = scene.pot_handle_pos(data, handles, side, along)
    ppos, _ = scene.pot_pose(data, handles)
    mat = rot_down(0.0)
    down = np.array([0.0, 0.0, -1.0])
    yield from approach(start, hpos, mat, down, standoff=0.12)
    c = cmd(hpos, mat, CLOSED)
    yield from grasp(c, steps=15, data=data, handles=handles)
    up = c.copy()
    up[2] += lift
    yield from move(c, up, speed=0.10)
    offset = _rz(place_yaw) @ (hpos - ppos)  # handle relative to the pot base (pot stays upright)
    mat_place = rot_down(place_yaw)
    dst = np.array([place_xy[0], place_xy[1], place_z]) + offset
    above = cmd(dst + [0, 0, lift], mat_place, CLOSED)
    yield from move(up, above, speed=0.15)
    put = cmd(dst + [0, 0, 0.005], mat_place, CLOSED)
    yield from move(above, put, speed=0.08)
    yield from hold(put, 8)
    released = yield from release(put, data=data, handles=handles)
    yield from retreat(released, down, 0.10)


# ------------------------------------------------------------------------------------------- run


def execute(controller, data, commands, callback=None) -> np.ndarray | None:
    """Run a command iterable on ``controller``; returns the last command sent."""
    last = None
    for c in commands:
        controller.step(data, c)
        last = c
        if callback is not None:
            callback(c)
    return last
