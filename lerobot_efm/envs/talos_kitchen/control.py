"""Cartesian left-hand control of the Talos kitchen, like the real robot's hand-pose interface.

Action / command (10-D, world frame): TCP position (3) + 6-D rotation (first two columns of the
rotation matrix, column-major: ``R[:, 0], R[:, 1]``) (6) + gripper (1; 0 open .. 1 closed).

:class:`CartesianController` tracks an absolute pose at the control rate: each control step solves a
damped-least-squares differential IK (left arm 7 joints + torso 2, torso motion penalised) on a
private kinematic ``MjData``, warm-started from the previous solution, with joint limits respected
and a weak null-space pull to the home posture, then writes the joint targets to the position
actuators and runs ``n_substeps`` physics steps. Unreachable poses converge to the DLS
least-squares compromise. Positions outside :data:`WORKSPACE_LOW` .. :data:`WORKSPACE_HIGH` are
clipped; NaN/inf entries raise ``ValueError``. The 180-degree symmetry of the gripper is *not*
exploited: the commanded orientation is tracked as given.

Grasp simplification (:class:`GraspWeld`, alias :class:`PotWeld`): a one-hand pinch on a round bar
cannot hold the off-axis pot (it swings), so when the gripper command is > 0.5 and both finger
jaws (fingertips 1-2 and fingertip 3, each with its links) touch the pot, an (initially inactive) weld equality between
the left gripper and the pot is activated at the current relative pose. The same gating activates
a ball-joint (connect) equality at the TCP for the door handle (and the tray handle): the door then
follows the hand's position along its arc while the handle may turn in the hand. Everything is
released as soon as the gripper command drops below 0.5. The jaws' inner links close on the tray's
box bar before the fingertips do, so the links count as jaws (the tray handle welds too); when the
jaws clamp two objects at once, the one clamped nearest the TCP is welded.
"""

from __future__ import annotations

import numpy as np

from ...extras import require
from .scene import GRIPPER_CLOSED, HOME, KitchenHandles

mujoco = require("mujoco", "talos", "the Talos kitchen")

WORKSPACE_LOW = np.array([0.05, -0.45, 0.75])  # TCP position box (m, world frame)
WORKSPACE_HIGH = np.array([0.80, 0.75, 1.60])
COMMAND_NAMES = ("x", "y", "z", "r00", "r10", "r20", "r01", "r11", "r21", "gripper")


# ---------------------------------------------------------------------------------------- rot6d


def rot6d_to_matrix(r6: np.ndarray) -> np.ndarray:
    """6-D rotation (..., 6) = first two columns -> rotation matrix (..., 3, 3) via Gram-Schmidt.

    The third column is ``c0 x c1``, so the result is a proper rotation (det = +1).
    """
    r6 = np.asarray(r6, dtype=float)
    a, b = r6[..., 0:3], r6[..., 3:6]
    c0 = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), 1e-12)
    b = b - np.sum(c0 * b, axis=-1, keepdims=True) * c0
    c1 = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), 1e-12)
    c2 = np.cross(c0, c1)
    return np.stack([c0, c1, c2], axis=-1)


def matrix_to_rot6d(mat: np.ndarray) -> np.ndarray:
    """Rotation matrix (..., 3, 3) -> 6-D rotation (..., 6): ``[R[:, 0], R[:, 1]]``."""
    mat = np.asarray(mat, dtype=float)
    return np.concatenate([mat[..., :, 0], mat[..., :, 1]], axis=-1)


def matrix_to_quat(mat: np.ndarray) -> np.ndarray:
    """Rotation matrix (3, 3) -> unit quaternion ``w, x, y, z`` with ``w >= 0``."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(mat, dtype=float).reshape(-1))
    return q if q[0] >= 0 else -q


def rot6d_to_quat(r6: np.ndarray) -> np.ndarray:
    return matrix_to_quat(rot6d_to_matrix(r6))


def hand_pose(data: mujoco.MjData, handles: KitchenHandles) -> tuple[np.ndarray, np.ndarray]:
    """Measured left TCP position (3,) and rotation matrix (3, 3) in the world frame."""
    return data.site_xpos[handles.left_tcp].copy(), data.site_xmat[handles.left_tcp].reshape(3, 3).copy()


def hand_pose10(data: mujoco.MjData, handles: KitchenHandles) -> np.ndarray:
    """Measured hand state in the command layout: position, rot6d, gripper closure in [0, 1]."""
    pos, mat = hand_pose(data, handles)
    g = np.clip(data.qpos[handles.left_gripper_qpos] / GRIPPER_CLOSED, 0.0, 1.0)
    return np.concatenate([pos, matrix_to_rot6d(mat), [g]])


def validate_command(command: np.ndarray) -> np.ndarray:
    """Check shape and finiteness; returns a float copy. Raises ValueError naming bad entries."""
    cmd = np.asarray(command, dtype=float).reshape(-1)
    if cmd.shape != (10,):
        raise ValueError(
            f"command must have 10 entries (pos 3, rot6d 6, gripper 1), got shape {np.shape(command)}"
        )
    bad = np.flatnonzero(~np.isfinite(cmd))
    if bad.size:
        names = ", ".join(f"{COMMAND_NAMES[i]} (index {i}) = {cmd[i]}" for i in bad)
        raise ValueError(f"non-finite command entries: {names}")
    if np.linalg.norm(cmd[3:6]) < 1e-9 or np.linalg.norm(np.cross(cmd[3:6], cmd[6:9])) < 1e-9:
        raise ValueError("degenerate rot6d: the two columns (indices 3-8) must be non-zero and not parallel")
    return cmd.copy()


# ------------------------------------------------------------------------------------- controller


class GraspWeld:
    """Weld-on-contact grasps of the pot, the door handle and the tray handle.

    Gating (identical for every object): gripper command > 0.5 **and** both jaws (fingertips 1-2 with
    their links, fingertip 3 with its links) in contact with the object's grasp geoms (any pot geom; the door / tray
    handle geoms). Then the object's inactive weld equality is activated at the current relative
    pose; all welds are released as soon as the gripper command drops below 0.5. At most one weld is
    active at a time. The door and tray welds use a small ``torquescale`` (rotation about the bar is
    left almost free, like a real pinch grasp on a bar); the pot weld is rigid.
    """

    TORQUESCALE = {"pot": 1.0, "door": 0.02, "tray": 0.2}

    def __init__(self, model: mujoco.MjModel, handles: KitchenHandles):
        self.model, self.h = model, handles
        self.targets = [("pot", handles.pot_weld, handles.pot_body, handles.pot_geoms)]
        if handles.door_weld >= 0:
            self.targets.append(("door", handles.door_weld, handles.door_body, handles.door_handle_geoms))
        if handles.tray_weld >= 0:
            self.targets.append(("tray", handles.tray_weld, handles.tray_body, handles.tray_handle_geoms))

    def _clamp_distance(self, data: mujoco.MjData, geoms: frozenset) -> float | None:
        """Distance from the TCP to the nearest jaw contact on ``geoms`` if both jaws touch them, else None."""
        h = self.h
        side_a = side_b = False
        nearest = np.inf
        tcp = data.site_xpos[h.left_tcp]
        for i in range(data.ncon):
            c = data.contact[i]
            g1, g2 = int(c.geom1), int(c.geom2)
            if g1 in geoms:
                g1, g2 = g2, g1
            if g2 not in geoms:
                continue
            a, b = g1 in h.finger_geoms_a, g1 in h.finger_geoms_b
            side_a |= a
            side_b |= b
            if a or b:
                nearest = min(nearest, float(np.linalg.norm(c.pos - tcp)))
        return nearest if side_a and side_b else None

    def active(self, data: mujoco.MjData) -> str | None:
        """Name of the welded object ("pot", "door", "tray") or None."""
        for name, eq, _, _ in self.targets:
            if data.eq_active[eq]:
                return name
        return None

    def update(self, data: mujoco.MjData, gripper_cmd: float) -> None:
        h = self.h
        if gripper_cmd < 0.5:
            for _, eq, _, _ in self.targets:
                data.eq_active[eq] = 0
            return
        if self.active(data) is not None:
            return
        # the jaws may clamp two objects at once (the tray handle and the pot standing on the tray):
        # take the one clamped nearest the TCP, i.e. the one the hand was aimed at
        clamped = [(d, t) for t in self.targets if (d := self._clamp_distance(data, t[3])) is not None]
        if not clamped:
            return
        _, (name, eq, body, _) = min(clamped, key=lambda x: x[0])
        p1, p2 = data.xpos[h.left_gripper_body], data.xpos[body]
        q1, q2 = data.xquat[h.left_gripper_body], data.xquat[body]
        r1 = data.xmat[h.left_gripper_body].reshape(3, 3)
        rel_q = np.zeros(4)
        q1_inv = np.zeros(4)
        mujoco.mju_negQuat(q1_inv, q1)
        mujoco.mju_mulQuat(rel_q, q1_inv, q2)
        # weld data layout: anchor (3), relpose pos (3), relpose quat (4), torquescale (1)
        tcp = data.site_xpos[h.left_tcp]
        if self.model.eq_type[eq] == mujoco.mjtEq.mjEQ_CONNECT:
            # connect data layout: anchor in body1 (gripper) frame (3), anchor in body2 frame (3)
            d = np.zeros(6)
            d[0:3] = r1.T @ (tcp - p1)
            d[3:6] = data.xmat[body].reshape(3, 3).T @ (tcp - p2)
            _set_eq_data(self.model, data, eq, d)
            data.eq_active[eq] = 1
            return
        d = np.zeros(11)
        # weld point = TCP (between the fingertips): data[0:3] is it in the object (body2) frame
        # and data[3:6] in the gripper (body1) frame, so a low torquescale lets the object
        # pivot about the grasp point
        tcp = data.site_xpos[h.left_tcp]
        r2 = data.xmat[body].reshape(3, 3)
        d[0:3] = r2.T @ (tcp - p2)
        d[3:6] = r1.T @ (tcp - p1)
        d[6:10] = rel_q
        d[10] = self.TORQUESCALE[name]
        _set_eq_data(self.model, data, eq, d)
        data.eq_active[eq] = 1


PotWeld = GraspWeld  # backwards-compatible name


def _set_eq_data(model: mujoco.MjModel, data: mujoco.MjData, eq: int, values: np.ndarray) -> None:
    # MuJoCo 4.0 has no per-MjData eq_data: the relative pose is written into the (shared, cached)
    # model. Harmless while each process runs one kitchen at a time; use separate models otherwise.
    target = getattr(data, "eq_data", None)
    if target is None:
        target = model.eq_data
    target[eq, : values.size] = values


class CartesianController:
    """Absolute left-hand pose tracking: DLS IK (left arm + torso) -> position actuators.

    ``step(data, command10)`` validates/clips the command, solves IK, sets all actuator targets and
    runs ``n_substeps`` ``mj_step`` (default 20 x 2 ms = 25 Hz control).
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        handles: KitchenHandles,
        n_substeps: int = 20,
        ik_iters: int = 15,
        damping: float = 0.02,
        rot_weight: float = 0.5,
        torso_weight: float = 0.3,
        max_joint_step: float = 0.25,
        posture_gain: float = 0.02,
        pot_weld: bool = True,
    ):
        self.model, self.h = model, handles
        self.n_substeps, self.ik_iters = int(n_substeps), int(ik_iters)
        self.damping, self.rot_weight = float(damping), float(rot_weight)
        self.max_joint_step, self.posture_gain = float(max_joint_step), float(posture_gain)
        self._kin = mujoco.MjData(model)
        self.qadr = np.concatenate([handles.arm_qpos, handles.torso_qpos])
        self.dadr = np.concatenate([handles.arm_dof, handles.torso_dof])
        jnt = [int(np.flatnonzero(model.jnt_qposadr == a)[0]) for a in self.qadr]
        margin = 1e-3
        self.lo = model.jnt_range[jnt, 0] + margin
        self.hi = model.jnt_range[jnt, 1] - margin
        self.col_w = np.ones(self.qadr.size)
        self.col_w[7:] = torso_weight
        self.q_home = handles.home_qpos[self.qadr].copy()
        names = [n for n in HOME if n.startswith("arm_left")] + ["torso_1_joint", "torso_2_joint"]
        self.act = np.array([handles.actuator[n] for n in names])
        self.grip_act = handles.actuator["gripper_left_joint"]
        self.weld = GraspWeld(model, handles) if pot_weld else None
        self.q_target = self.q_home.copy()
        self.last_error = (np.inf, np.inf)
        self._jacp = np.zeros((3, model.nv))
        self._jacr = np.zeros((3, model.nv))

    @property
    def control_dt(self) -> float:
        return self.n_substeps * self.model.opt.timestep

    def reset(self, data: mujoco.MjData) -> None:
        """Start from the measured joint configuration (call after resetting ``data``)."""
        self._kin.qpos[:] = data.qpos
        self.q_target = np.clip(data.qpos[self.qadr], self.lo, self.hi)
        self.last_error = (np.inf, np.inf)

    def solve_ik(self, pos: np.ndarray, mat: np.ndarray, iters: int | None = None) -> np.ndarray:
        """Joint targets (arm 7 + torso 2) for a TCP pose; warm-started from the last solution."""
        m, kin, h = self.model, self._kin, self.h
        q = self.q_target.copy()
        target_quat = np.zeros(4)
        mujoco.mju_mat2Quat(target_quat, np.ascontiguousarray(mat).reshape(-1))
        err = np.zeros(6)
        cur_quat = np.zeros(4)
        dq_quat = np.zeros(4)
        cur_inv = np.zeros(4)
        lam2 = self.damping**2
        for _ in range(self.ik_iters if iters is None else iters):
            kin.qpos[self.qadr] = q
            mujoco.mj_kinematics(m, kin)
            mujoco.mj_comPos(m, kin)
            err[:3] = pos - kin.site_xpos[h.left_tcp]
            mujoco.mju_mat2Quat(cur_quat, kin.site_xmat[h.left_tcp])
            mujoco.mju_negQuat(cur_inv, cur_quat)
            mujoco.mju_mulQuat(dq_quat, target_quat, cur_inv)  # world-frame rotation error
            mujoco.mju_quat2Vel(err[3:], dq_quat, 1.0)
            self.last_error = (float(np.linalg.norm(err[:3])), float(np.linalg.norm(err[3:])))
            if self.last_error[0] < 2e-4 and self.last_error[1] < 2e-3:
                break
            err[3:] *= self.rot_weight
            mujoco.mj_jacSite(m, kin, self._jacp, self._jacr, h.left_tcp)
            jac = np.vstack([self._jacp[:, self.dadr], self.rot_weight * self._jacr[:, self.dadr]])
            jw = jac * self.col_w
            jjt = jw @ jac.T + lam2 * np.eye(6)
            dq = jw.T @ np.linalg.solve(jjt, err)
            # weak null-space pull towards the home posture
            pinv = jw.T @ np.linalg.solve(jjt, np.eye(6))
            dq += self.posture_gain * (np.eye(q.size) - pinv @ jac) @ (self.q_home - q)
            n = np.abs(dq).max()
            if n > self.max_joint_step:
                dq *= self.max_joint_step / n
            q = np.clip(q + dq, self.lo, self.hi)
        self.q_target = q
        return q

    def step(self, data: mujoco.MjData, command: np.ndarray) -> None:
        """Track one 10-D command for one control period (IK + ``n_substeps`` physics steps)."""
        cmd = validate_command(command)
        pos = np.clip(cmd[:3], WORKSPACE_LOW, WORKSPACE_HIGH)
        mat = rot6d_to_matrix(cmd[3:9])
        grip = float(np.clip(cmd[9], 0.0, 1.0))
        q = self.solve_ik(pos, mat)
        data.ctrl[self.act] = q
        data.ctrl[self.grip_act] = grip * GRIPPER_CLOSED
        for _ in range(self.n_substeps):
            mujoco.mj_step(self.model, data)
        if self.weld is not None:
            self.weld.update(data, grip)
