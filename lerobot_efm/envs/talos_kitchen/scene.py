"""Talos kitchen scene, built at run time with ``mujoco.MjSpec`` from example-robot-data.

Nothing is converted or copied into this repository: the ``talos_full_v2`` URDF is located inside
the installed ``example-robot-data`` wheel (``importlib.metadata``), its ``package://`` URIs are
rewritten to absolute paths in memory, and the kitchen is added with MjSpec.

Robot (PAL Talos, Apache-2.0 model by PAL Robotics, via example-robot-data 6.0.0):

* **Simplification: fixed base, no whole-body controller.** The real robot balances with a
  whole-body (SEIKO admittance QP) controller. Here the legs' joints are deleted (rigid legs), the
  base is welded to the world at z = 1.08305 m (soles on the floor) and every robot body has
  ``gravcomp = 1``; joint-space position servos stand in for the torque-level controller.
* 20 position actuators: torso 2 (kp 2000), head 2 (kp 100), arms 2 x 7 (kp 400), grippers 2
  (kp 20, +-3 N m; the 6 mimic joints per gripper follow through joint equalities). All critically
  damped (``dampratio = 1``). Armature 0.05 (grippers 0.005). Gripper joint friction lowered from
  the URDF's 1.0 to 0.01 on each of the 7 coupled gripper joints: the friction, not kp or the force
  limit, sets the closing speed (measured on air, 25 Hz frames to 95 % closure: 78 at 0.1, 26 at
  0.01, 24 at 0; kp 20 -> 1000 and +-3 -> 10 N m change nothing). At 0.1 a grasp needed a median
  26 frames (1 s) from the close command to the weld, longer than a policy's replanning period,
  and half-closed grippers were mistaken for aborted grasps (issue 14); at 0.01 it needs 7.
* Robot self-collision is disabled (adjacent URDF collision meshes overlap): robot geoms use
  ``contype = 2, conaffinity = 1`` and the kitchen ``contype = 1, conaffinity = 3``.
* URDF collision meshes are moved to geom group 3 (not rendered); visual meshes are group 1.
* Site ``talos/left_tcp`` (the controlled hand frame) sits between the fingertips, 0.14 m along
  -z of ``gripper_left_base_link``; the fingers point along the site's -z axis.
* Gripper joint ``gripper_left_joint``: 0 = open, -0.96 = closed.

Kitchen (world frame: x forward from the robot, y to its left, z up). Layout chosen so that every
grasp and every motion of the scripted primitives (:mod:`.primitives`) lies inside the left arm's
dexterous workspace (checked with the IK):

* table top at z = 0.85 m, centred at :data:`TABLE_CENTER` (0.50, -0.22) (x 0.30..0.70, y -0.50..0.06,
  clear of the hanging right hand);
* cabinet (front plane x = :data:`CAB_X0` = 0.60, y in [0.18, 0.52], 1.25 m tall). Its upper
  compartment (z 0.92..1.25) is closed by a **hinged door** (``door_hinge``, range [-2, 0] rad,
  0 = closed, negative = open towards the robot). The hinge is on the door's **-y edge** (towards
  the robot's midline) and the joint axis is -z, so the handle's arc ends in front of the left
  shoulder instead of far out to the left. Door handle: a vertical **box-section bar** (16 mm,
  14 cm long) 5 cm in front of the panel at (0.537, 0.475, 1.085) when closed
  (:func:`door_handle_pos` gives it for any angle). Door damping 1.5, frictionloss 0.1 (it stays
  where it is released). Reachable arc: 0 .. about -1.3 rad; the primitives open to -1.2.
* **pull-out tray = drawer below the door** (``tray_slide``, along x, range [-0.33, 0] m, 0 = in,
  negative = pulled out) in a slot z 0.74..0.90 under the compartment shelf, so it is reachable
  whatever the door angle (with the tray inside the door compartment the opened door panel lies
  across the arm's path). Vertical box-section bar handle at (0.61, 0.35, 0.80) when in
  (:func:`tray_handle_pos`); grasped with fingers pitched 0.8 rad down (horizontal fingers cannot
  reach z 0.80). Tray floor top at z = 0.75 m.
* a **red pot** (free joint ``pot_free``, hollow, 0.17 m diameter, ~0.8 kg) with two 13 cm bar
  handles on +-y (:func:`pot_handle_pos`), standing on the table at :data:`POT_HOME` (0.42, -0.16);
* one fixed external RGB camera ``front`` framing the robot and the kitchen.

Grasps: the door and tray handles are pinched by friction; for the door (and as a fallback for the
tray) a **ball-joint (connect) equality at the TCP** is activated on contact, and the pot uses a
weld, both gated by gripper command > 0.5 **and** contact on both finger sides
(:class:`~.control.GraspWeld`). All three equalities are inactive after :func:`reset_kitchen`.

Bug fixed here: ``MjSpec`` hinge ranges are in **degrees** (compiler default): the old
``range=[-2, 0]`` compiled to [-0.035, 0] rad, which is why the door never opened past -0.035.

:func:`build_kitchen` returns ``(model, data, handles)``; the compiled model is cached per process
(per ``image_size``), every call gets a fresh ``MjData`` reset to the home keyframe.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np

from ...extras import require, require_distribution
from . import tasks

mujoco = require("mujoco", "talos", "the Talos kitchen")

BASE_HEIGHT = 1.08305
ROBOT_PREFIX = "talos/"
LEFT_ARM_JOINTS = tuple(f"arm_left_{i}_joint" for i in range(1, 8))
RIGHT_ARM_JOINTS = tuple(f"arm_right_{i}_joint" for i in range(1, 8))
TORSO_JOINTS = ("torso_1_joint", "torso_2_joint")
HEAD_JOINTS = ("head_1_joint", "head_2_joint")
GRIPPER_JOINTS = ("gripper_left_joint", "gripper_right_joint")
GRIPPER_CLOSED = -0.96  # gripper joint angle when fully closed (0 = open)
# the two jaws of the left gripper: fingertips with their proximal links (the four-bar linkage's
# inner and motor links). A bar can be clamped by the proximal links before the fingertips touch it
# (the tray handle always is): counting only the fingertips left those grasps unwelded (issue 14).
GRIPPER_SIDE_A = tuple(
    f"gripper_left_{n}_link" for n in ("fingertip_1", "fingertip_2", "inner_double", "motor_double")
)
GRIPPER_SIDE_B = tuple(f"gripper_left_{n}_link" for n in ("fingertip_3", "inner_single", "motor_single"))
GRIPPER_KP, GRIPPER_FORCE, GRIPPER_FRICTIONLOSS = 20.0, 3.0, 0.01  # N m / rad, N m, N m per gripper joint

# Home posture (rad): left TCP near (0.30, 0.22, 1.0), fingers forward; right arm hanging (unused).
HOME = {
    "torso_1_joint": 0.0,
    "torso_2_joint": 0.0,
    "head_1_joint": 0.0,
    "head_2_joint": 0.35,
    "arm_left_1_joint": 0.7,
    "arm_left_2_joint": 0.25,
    "arm_left_3_joint": -1.2,
    "arm_left_4_joint": -1.2,
    "arm_left_5_joint": 0.3,
    "arm_left_6_joint": 0.3,
    "arm_left_7_joint": -0.6,
    "arm_right_1_joint": 0.0,
    "arm_right_2_joint": -0.1,
    "arm_right_3_joint": 0.0,
    "arm_right_4_joint": -0.5,
    "arm_right_5_joint": 0.0,
    "arm_right_6_joint": 0.0,
    "arm_right_7_joint": 0.0,
    "gripper_left_joint": 0.0,
    "gripper_right_joint": 0.0,
}

POT_HOME = (0.42, -0.16)  # pot centre on the table (x, y)
TABLE_TOP = 0.85
TABLE_CENTER = (0.50, -0.22)
TABLE_HALF = (0.20, 0.28)  # table top half extents (x, y): x in [0.30, 0.70], y in [-0.50, 0.06]
CAB_X0, CAB_Y0, CAB_Y1 = 0.60, 0.18, 0.52  # cabinet front plane x and its y extent
DOOR_HINGE = (CAB_X0 - 0.013, CAB_Y0 + 0.005, 1.085)  # hinge axis position (world, door body origin)
DOOR_HANDLE_LOCAL = (-0.05, 0.29, 0.0)  # handle bar centre in the door frame
DRAWER_Z = 0.74  # bottom of the drawer slot under the door compartment
TRAY_HANDLE_LOCAL = (-0.20, 0.0, 0.06)  # tray handle bar centre in the tray frame
TRAY_POS0 = (
    CAB_X0 + 0.21,
    (CAB_Y0 + CAB_Y1) / 2,
    DRAWER_Z + 0.002,
)  # tray body origin when pushed in  # tray handle bar centre in the tray frame
POT_RADIUS = 0.085
POT_HEIGHT = 0.10
POT_HANDLE_HALF_LENGTH = 0.065  # m, half the length of each handle bar (along the pot's x axis)


def talos_data_dir() -> Path:
    """Directory ``talos_data`` inside the installed example-robot-data wheel (6.0.0 layout)."""
    dist = require_distribution("example-robot-data", "talos", "the Talos kitchen (robot meshes)")
    root = Path(dist.locate_file("cmeel.prefix/share/example-robot-data/robots/talos_data"))
    if not (root / "robots" / "talos_full_v2.urdf").is_file():
        raise FileNotFoundError(
            f"talos_full_v2.urdf not found under {root} (example-robot-data 6.0.0 expected)"
        )
    return root


def _robot_spec() -> mujoco.MjSpec:
    root = talos_data_dir()
    text = (root / "robots" / "talos_full_v2.urdf").read_text()
    text = re.sub(r"package:///?example-robot-data/robots/talos_data/", str(root) + "/", text)
    # compiler flags only take effect from inside the URDF (setting them on the spec is too late)
    text = re.sub(
        r"(<robot[^>]*>)",
        r'\1<mujoco><compiler discardvisual="false" fusestatic="false"/></mujoco>',
        text,
        count=1,
    )
    spec = mujoco.MjSpec.from_string(text)

    for joint in list(spec.joints):
        if joint.name.startswith("leg_"):
            spec.delete(joint)
    for body in spec.bodies:
        if body.name != "world":
            body.gravcomp = 1.0
    for geom in spec.geoms:
        if geom.contype or geom.conaffinity:  # collision geom
            geom.contype, geom.conaffinity, geom.group = 2, 1, 3
            geom.condim = 4 if "gripper" in geom.name or "finger" in (geom.name or "") else 3
        else:
            geom.group = 1
    for joint in spec.joints:
        is_gripper = joint.name.startswith("gripper_")
        joint.armature = 0.005 if is_gripper else 0.05
        if is_gripper:
            joint.frictionloss = GRIPPER_FRICTIONLOSS

    gains = {"torso": 2000.0, "head": 100.0, "arm": 400.0}
    for name in TORSO_JOINTS + HEAD_JOINTS + LEFT_ARM_JOINTS + RIGHT_ARM_JOINTS + GRIPPER_JOINTS:
        act = spec.add_actuator(name=name, target=name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
        if name.startswith("gripper"):
            act.set_to_position(kp=GRIPPER_KP, dampratio=1.0)
            act.forcelimited, act.forcerange = True, [-GRIPPER_FORCE, GRIPPER_FORCE]
            act.ctrllimited, act.ctrlrange = True, [GRIPPER_CLOSED, 0.0]
        else:
            act.set_to_position(kp=gains[name.split("_")[0]], dampratio=1.0)
            act.inheritrange = 1.0

    for side in ("left", "right"):
        body = spec.body(f"gripper_{side}_base_link")
        body.add_site(name=f"{side}_tcp", pos=[0, 0, -0.14], size=[0.005, 0, 0], group=4)
    return spec


def _look_at_quat(pos, target) -> np.ndarray:
    """Quaternion of a MuJoCo camera at ``pos`` looking at ``target`` (camera looks along -z)."""
    fwd = np.asarray(target, float) - np.asarray(pos, float)
    fwd /= np.linalg.norm(fwd)
    x = np.cross(fwd, [0.0, 0.0, 1.0])
    x /= np.linalg.norm(x)
    y = np.cross(x, fwd)
    mat = np.stack([x, y, -fwd], axis=1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1))
    return quat


def _box(body, name, pos, half, rgba, **kw):
    return body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=pos,
        size=half,
        rgba=rgba,
        contype=1,
        conaffinity=3,
        group=0,
        **kw,
    )


def _capsule(body, name, p0, p1, radius, rgba, **kw):
    return body.add_geom(
        name=name,
        type=mujoco.mjtGeom.mjGEOM_CAPSULE,
        fromto=list(p0) + list(p1),
        size=[radius, 0, 0],
        rgba=rgba,
        contype=1,
        conaffinity=3,
        group=0,
        **kw,
    )


WOOD = [0.62, 0.45, 0.30, 1]
WHITE = [0.85, 0.85, 0.82, 1]
METAL = [0.55, 0.55, 0.6, 1]
RED = [0.8, 0.1, 0.1, 1]


def _add_kitchen(spec: mujoco.MjSpec) -> None:
    world = spec.worldbody
    spec.option.timestep = 0.002
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    spec.option.impratio = 10.0
    spec.visual.quality.shadowsize = 0
    spec.visual.quality.offsamples = 0
    spec.visual.headlight.ambient = [0.35, 0.35, 0.35]
    spec.visual.headlight.diffuse = [0.5, 0.5, 0.5]

    world.add_geom(
        name="floor",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[3, 3, 0.05],
        rgba=[0.55, 0.55, 0.5, 1],
        contype=1,
        conaffinity=3,
    )
    world.add_geom(
        name="wall",
        type=mujoco.mjtGeom.mjGEOM_BOX,
        pos=[1.05, 0.2, 1.2],
        size=[0.02, 1.5, 1.2],
        rgba=[0.8, 0.82, 0.86, 1],
        contype=0,
        conaffinity=0,
    )
    world.add_light(
        name="top", pos=[0.4, 0.0, 2.8], dir=[0, 0, -1], castshadow=False, diffuse=[0.5, 0.5, 0.5]
    )

    # table (right of the robot's midline, clear of the cabinet)
    table = world.add_body(name="table", pos=[TABLE_CENTER[0], TABLE_CENTER[1], 0.0])
    thx_, thy_ = TABLE_HALF
    _box(table, "table_top", [0, 0, TABLE_TOP - 0.02], [thx_, thy_, 0.02], WOOD)
    for i, (sx, sy) in enumerate([(1, 1), (1, -1), (-1, 1), (-1, -1)]):
        _box(
            table,
            f"table_leg{i}",
            [sx * (thx_ - 0.03), sy * (thy_ - 0.03), (TABLE_TOP - 0.04) / 2],
            [0.02, 0.02, (TABLE_TOP - 0.04) / 2],
            WOOD,
        )

    # cabinet: front plane x = CAB_X0, y in [CAB_Y0, CAB_Y1], depth 0.40, height 1.25
    x0, y0, y1 = CAB_X0, CAB_Y0, CAB_Y1
    x1, h, t = x0 + 0.40, 1.25, 0.02
    cab = world.add_body(name="cabinet")
    xm, ym = (x0 + x1) / 2, (y0 + y1) / 2
    # solid base to z = DRAWER_Z, then an open drawer slot (DRAWER_Z .. 0.90) holding the pull-out tray
    _box(cab, "cab_lower", [xm, ym, DRAWER_Z / 2], [(x1 - x0) / 2, (y1 - y0) / 2, DRAWER_Z / 2], WHITE)
    _box(
        cab,
        "cab_slot_back",
        [x1 - t / 2, ym, (DRAWER_Z + 0.90) / 2],
        [t / 2, (y1 - y0) / 2, (0.90 - DRAWER_Z) / 2],
        WHITE,
    )
    for nm_, yy in (("r", y0 + t / 2), ("l", y1 - t / 2)):
        _box(
            cab,
            f"cab_slot_side_{nm_}",
            [xm, yy, (DRAWER_Z + 0.90) / 2],
            [(x1 - x0) / 2, t / 2, (0.90 - DRAWER_Z) / 2],
            WHITE,
        )
    _box(
        cab, "cab_shelf", [xm, ym, 0.91], [(x1 - x0) / 2, (y1 - y0) / 2, 0.01], WHITE
    )  # floor of compartment 0.92
    _box(cab, "cab_top", [xm, ym, h - t / 2], [(x1 - x0) / 2, (y1 - y0) / 2, t / 2], WHITE)
    _box(cab, "cab_back", [x1 - t / 2, ym, (0.92 + h) / 2], [t / 2, (y1 - y0) / 2, (h - 0.92) / 2], WHITE)
    _box(cab, "cab_side_r", [xm, y0 + t / 2, (0.92 + h) / 2], [(x1 - x0) / 2, t / 2, (h - 0.92) / 2], WHITE)
    _box(cab, "cab_side_l", [xm, y1 - t / 2, (0.92 + h) / 2], [(x1 - x0) / 2, t / 2, (h - 0.92) / 2], WHITE)

    # hinged door in front of the compartment. The hinge is on the -y edge (towards the robot's
    # midline) and the joint axis is -z, so that negative angles open the door towards the robot
    # and the handle's arc stays inside the left arm's workspace.
    door = cab.add_body(name="door", pos=list(DOOR_HINGE))
    door.add_joint(
        name="door_hinge",
        type=mujoco.mjtJoint.mjJNT_HINGE,
        axis=[0, 0, -1],
        range=[-np.degrees(2.0), 0.0],  # MjSpec hinge ranges are in degrees (compiler default)
        limited=True,
        damping=1.5,
        frictionloss=0.1,
        armature=0.01,
    )
    dw = y1 - y0 - 0.01
    _box(door, "door_panel", [0, dw / 2, 0], [0.01, dw / 2, 0.16], WOOD, mass=2.0)
    hx, hy = DOOR_HANDLE_LOCAL[0], DOOR_HANDLE_LOCAL[1]
    _box(
        door, "door_handle", [hx, hy, 0], [0.008, 0.008, 0.07], METAL, mass=0.05, friction=[1.5, 0.02, 0.002]
    )
    for i, z in enumerate((-0.065, 0.065)):
        _box(
            door,
            f"door_handle_arm{i}",
            [(hx - 0.01) / 2, hy, z],
            [(-hx - 0.01) / 2 + 0.002, 0.006, 0.006],
            METAL,
            mass=0.02,
        )

    # pull-out tray in the compartment (slides along x towards the robot)
    tray = cab.add_body(name="tray", pos=list(TRAY_POS0))
    tray.add_joint(
        name="tray_slide",
        type=mujoco.mjtJoint.mjJNT_SLIDE,
        axis=[1, 0, 0],
        range=[tasks.TRAY_STOP, 0.0],
        limited=True,
        damping=3.0,
        frictionloss=0.2,
        armature=0.01,
    )
    tw = (y1 - y0) / 2 - 0.025
    _box(tray, "tray_bottom", [0, 0, 0.004], [0.16, tw, 0.004], METAL, mass=0.6)
    _box(tray, "tray_front", [-0.155, 0, 0.03], [0.005, tw, 0.03], METAL, mass=0.1)
    _box(tray, "tray_rear", [0.155, 0, 0.03], [0.005, tw, 0.03], METAL, mass=0.1)
    for i, s in enumerate((-1, 1)):
        _box(tray, f"tray_side{i}", [0, s * (tw - 0.005), 0.03], [0.16, 0.005, 0.03], METAL, mass=0.1)
    thx, thz = TRAY_HANDLE_LOCAL[0], TRAY_HANDLE_LOCAL[2]  # vertical box-section handle bar (like the door's)
    _box(
        tray,
        "tray_handle",
        [thx, 0, thz],
        [0.008, 0.008, 0.045],
        METAL,
        mass=0.05,
        friction=[1.5, 0.02, 0.002],
    )
    for i, z in enumerate((thz - 0.04, thz + 0.04)):
        _box(
            tray,
            f"tray_handle_arm{i}",
            [(thx - 0.16) / 2, 0, z],
            [(-0.16 - thx) / 2, 0.006, 0.006],
            METAL,
            mass=0.02,
        )

    # red pot with two bar handles on +-y
    pot = world.add_body(name="pot", pos=[POT_HOME[0], POT_HOME[1], TABLE_TOP + 0.001])
    pot.add_freejoint(name="pot_free")
    pot.add_geom(
        name="pot_bottom",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        pos=[0, 0, 0.005],
        size=[POT_RADIUS, 0.005, 0],
        rgba=RED,
        mass=0.25,
        contype=1,
        conaffinity=3,
    )
    n_seg = 16
    seg_half = POT_RADIUS * np.tan(np.pi / n_seg) + 0.001
    for i in range(n_seg):
        a = 2 * np.pi * i / n_seg
        quat = [np.cos(a / 2), 0, 0, np.sin(a / 2)]
        pot.add_geom(
            name=f"pot_wall{i}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            pos=[POT_RADIUS * np.cos(a), POT_RADIUS * np.sin(a), 0.011 + POT_HEIGHT / 2],
            quat=quat,
            size=[0.003, seg_half, POT_HEIGHT / 2],
            rgba=RED,
            mass=0.025,
            contype=1,
            conaffinity=3,
        )
    for side, s in (("left", 1), ("right", -1)):
        yb = s * (POT_RADIUS + 0.065)
        z = POT_HEIGHT - 0.01
        pot.add_geom(
            name=f"pot_handle_{side}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[-POT_HANDLE_HALF_LENGTH, yb, z, POT_HANDLE_HALF_LENGTH, yb, z],
            size=[0.009, 0, 0],
            rgba=[0.15, 0.15, 0.15, 1],
            mass=0.05,
            contype=1,
            conaffinity=3,
        )
        for j, x in enumerate((-POT_HANDLE_HALF_LENGTH, POT_HANDLE_HALF_LENGTH)):
            pot.add_geom(
                name=f"pot_handle_{side}_arm{j}",
                type=mujoco.mjtGeom.mjGEOM_CAPSULE,
                fromto=[x, s * (POT_RADIUS * 0.7), z, x, yb, z],
                size=[0.006, 0, 0],
                rgba=[0.15, 0.15, 0.15, 1],
                mass=0.02,
                contype=1,
                conaffinity=3,
            )

    cam_pos = [-0.35, 1.30, 1.85]
    world.add_camera(name="front", pos=cam_pos, quat=_look_at_quat(cam_pos, [0.40, 0.05, 0.95]), fovy=55.0)


@dataclass(frozen=True)
class KitchenHandles:
    """Indices into the compiled model used by the controller and the env."""

    arm_qpos: np.ndarray  # qpos addresses of the 7 left-arm joints
    arm_dof: np.ndarray  # dof addresses of the same joints
    torso_qpos: np.ndarray
    torso_dof: np.ndarray
    actuator: dict  # joint name (unprefixed) -> actuator id
    home_qpos: np.ndarray  # full qpos of the home keyframe
    left_tcp: int  # site id of the controlled hand frame
    left_gripper_body: int
    left_gripper_qpos: int
    door_qpos: int
    tray_qpos: int
    pot_qpos: int  # start of the pot's 7 free-joint qpos (pos, quat)
    pot_body: int
    pot_weld: int  # id of the (initially inactive) hand-pot weld equality
    camera: int  # id of the "front" camera
    finger_geoms_a: frozenset  # collision geoms of one jaw (fingertips 1-2 and their links)
    finger_geoms_b: frozenset  # collision geoms of the opposite jaw (fingertip 3 and its links)
    pot_geoms: frozenset
    door_body: int = -1
    tray_body: int = -1
    door_weld: int = -1  # id of the (initially inactive) hand-door-handle weld equality
    tray_weld: int = -1  # id of the (initially inactive) hand-tray-handle weld equality
    door_handle_geoms: frozenset = frozenset()
    tray_handle_geoms: frozenset = frozenset()


def _compile(image_size: int) -> tuple[mujoco.MjModel, KitchenHandles]:
    spec = mujoco.MjSpec()
    spec.modelname = "talos_kitchen"
    _add_kitchen(spec)
    frame = spec.worldbody.add_frame(pos=[0, 0, BASE_HEIGHT])
    spec.attach(_robot_spec(), frame=frame, prefix=ROBOT_PREFIX)
    # weld-on-contact grasp simplification for the pot (see control.PotWeld); inactive by default
    spec.add_equality(
        name="pot_weld",
        type=mujoco.mjtEq.mjEQ_WELD,
        objtype=mujoco.mjtObj.mjOBJ_BODY,
        name1=ROBOT_PREFIX + "gripper_left_base_link",
        name2="pot",
        active=False,
    )
    # door / tray handle grasps: ball-joint (connect) constraints at the TCP, so the hand can rotate
    # about the handle like a real pinch on a bar while the object follows the hand's position
    for obj in ("door", "tray"):
        spec.add_equality(
            name=f"{obj}_weld",
            type=mujoco.mjtEq.mjEQ_CONNECT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=ROBOT_PREFIX + "gripper_left_base_link",
            name2=obj,
            active=False,
        )
    spec.visual.global_.offwidth = max(int(image_size), 640)
    spec.visual.global_.offheight = max(int(image_size), 480)
    model = spec.compile()

    def jid(n):
        return model.joint(ROBOT_PREFIX + n).id

    arm = [jid(n) for n in LEFT_ARM_JOINTS]
    torso = [jid(n) for n in TORSO_JOINTS]
    home = model.qpos0.copy()
    for n, v in HOME.items():
        home[model.jnt_qposadr[jid(n)]] = v
    actuator = {n: model.actuator(ROBOT_PREFIX + n).id for n in HOME}

    def geoms_of(prefixes):
        out = set()
        for g in range(model.ngeom):
            b = model.body(model.geom_bodyid[g]).name
            if model.geom_contype[g] and any(b == ROBOT_PREFIX + p for p in prefixes):
                out.add(g)
        return frozenset(out)

    pot_body = model.body("pot").id
    handles = KitchenHandles(
        arm_qpos=model.jnt_qposadr[arm].copy(),
        arm_dof=model.jnt_dofadr[arm].copy(),
        torso_qpos=model.jnt_qposadr[torso].copy(),
        torso_dof=model.jnt_dofadr[torso].copy(),
        actuator=actuator,
        home_qpos=home,
        left_tcp=model.site(ROBOT_PREFIX + "left_tcp").id,
        left_gripper_body=model.body(ROBOT_PREFIX + "gripper_left_base_link").id,
        left_gripper_qpos=int(model.jnt_qposadr[jid("gripper_left_joint")]),
        door_qpos=int(model.jnt_qposadr[model.joint("door_hinge").id]),
        tray_qpos=int(model.jnt_qposadr[model.joint("tray_slide").id]),
        pot_qpos=int(model.jnt_qposadr[model.joint("pot_free").id]),
        pot_body=pot_body,
        pot_weld=model.equality("pot_weld").id,
        camera=model.camera("front").id,
        finger_geoms_a=geoms_of(GRIPPER_SIDE_A),
        finger_geoms_b=geoms_of(GRIPPER_SIDE_B),
        pot_geoms=frozenset(g for g in range(model.ngeom) if model.geom_bodyid[g] == pot_body),
        door_body=model.body("door").id,
        tray_body=model.body("tray").id,
        door_weld=model.equality("door_weld").id,
        tray_weld=model.equality("tray_weld").id,
        door_handle_geoms=frozenset(
            g for g in range(model.ngeom) if (model.geom(g).name or "").startswith("door_handle")
        ),
        tray_handle_geoms=frozenset(
            g for g in range(model.ngeom) if (model.geom(g).name or "").startswith("tray_handle")
        ),
    )
    return model, handles


@lru_cache(maxsize=4)
def _cached(image_size: int):
    return _compile(image_size)


def reset_kitchen(model: mujoco.MjModel, data: mujoco.MjData, handles: KitchenHandles) -> None:
    """Home posture, door closed, tray in, pot on the table; actuator targets = home."""
    mujoco.mj_resetData(model, data)
    data.qpos[:] = handles.home_qpos
    for name, act in handles.actuator.items():
        data.ctrl[act] = HOME[name]
    for eq in (handles.pot_weld, handles.door_weld, handles.tray_weld):
        data.eq_active[eq] = 0
    mujoco.mj_forward(model, data)


def build_kitchen(image_size: int = 128) -> tuple[mujoco.MjModel, mujoco.MjData, KitchenHandles]:
    """Compiled kitchen model (cached per process and ``image_size``), a fresh reset ``MjData``, handles.

    The model is shared between calls: treat it as read-only.
    """
    model, handles = _cached(int(image_size))
    data = mujoco.MjData(model)
    reset_kitchen(model, data, handles)
    return model, data, handles


# ----------------------------------------------------------------------------------------- state


def door_angle(data: mujoco.MjData, handles: KitchenHandles) -> float:
    """Door hinge angle (rad): 0 closed, down to -2 fully open."""
    return float(data.qpos[handles.door_qpos])


def tray_slide(data: mujoco.MjData, handles: KitchenHandles) -> float:
    """Tray slide (m): 0 pushed in, down to ``tasks.TRAY_STOP`` pulled out."""
    return float(data.qpos[handles.tray_qpos])


def pot_pose(data: mujoco.MjData, handles: KitchenHandles) -> tuple[np.ndarray, np.ndarray]:
    """Pot position (3,) of its base centre and unit quaternion (4,) ``w, x, y, z`` in the world frame."""
    a = handles.pot_qpos
    return data.qpos[a : a + 3].copy(), data.qpos[a + 3 : a + 7].copy()


def door_handle_pos(data: mujoco.MjData, handles: KitchenHandles, angle: float | None = None) -> np.ndarray:
    """World position (3,) of the door handle bar centre, at the current or a given hinge ``angle``."""
    a = door_angle(data, handles) if angle is None else float(angle)
    c, s = np.cos(-a), np.sin(-a)  # joint axis is -z: world yaw of the door = -angle
    lx, ly, lz = DOOR_HANDLE_LOCAL
    return np.array([DOOR_HINGE[0] + c * lx - s * ly, DOOR_HINGE[1] + s * lx + c * ly, DOOR_HINGE[2] + lz])


def tray_handle_pos(data: mujoco.MjData, handles: KitchenHandles, slide: float | None = None) -> np.ndarray:
    """World position (3,) of the tray handle bar centre at the current or a given ``slide``."""
    sl = tray_slide(data, handles) if slide is None else float(slide)
    x0 = TRAY_POS0[0] + sl + TRAY_HANDLE_LOCAL[0]
    return np.array([x0, TRAY_POS0[1] + TRAY_HANDLE_LOCAL[1], TRAY_POS0[2] + TRAY_HANDLE_LOCAL[2]])


def pot_handle_pos(
    data: mujoco.MjData, handles: KitchenHandles, side: str = "left", along: float = 0.0
) -> np.ndarray:
    """World position (3,) of the pot's ``left`` (+y) or ``right`` (-y) handle bar, ``along`` m from its centre
    along the bar (the pot's x axis; the bar spans +-``POT_HANDLE_HALF_LENGTH``)."""
    if abs(along) > POT_HANDLE_HALF_LENGTH:
        raise ValueError(f"along={along} m is off the pot's handle bar (+-{POT_HANDLE_HALF_LENGTH} m)")
    pos, quat = pot_pose(data, handles)
    mat = np.zeros(9)
    mujoco.mju_quat2Mat(mat, quat)
    s = 1.0 if side == "left" else -1.0
    return pos + mat.reshape(3, 3) @ np.array([along, s * (POT_RADIUS + 0.065), POT_HEIGHT - 0.01])


def gripper_opening(data: mujoco.MjData, handles: KitchenHandles) -> float:
    """Measured left gripper closure in [0, 1] (0 open, 1 closed)."""
    return float(np.clip(data.qpos[handles.left_gripper_qpos] / GRIPPER_CLOSED, 0.0, 1.0))


# ----------------------------------------------------------------------------------------- render


class KitchenRenderer:
    """Reusable offscreen renderer of the ``front`` camera (EGL/OSMesa; set MUJOCO_GL before import).

    Fast settings: no shadows, no MSAA (``offsamples = 0``), no reflections; collision meshes hidden.
    """

    def __init__(
        self, model: mujoco.MjModel, height: int = 128, width: int | None = None, camera: str = "front"
    ):
        self.model = model
        self.camera = camera
        self._renderer = mujoco.Renderer(model, height=height, width=width or height)
        self._opt = mujoco.MjvOption()
        self._opt.geomgroup[:] = [1, 1, 1, 0, 0, 0]
        self._opt.sitegroup[:] = 0

    def render(self, data: mujoco.MjData) -> np.ndarray:
        """(H, W, 3) uint8 RGB image (a new array)."""
        self._renderer.update_scene(data, camera=self.camera, scene_option=self._opt)
        return self._renderer.render().copy()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def render(
    model: mujoco.MjModel, data: mujoco.MjData, renderer: KitchenRenderer | None = None, image_size: int = 128
) -> np.ndarray:
    """Render the ``front`` camera; pass a :class:`KitchenRenderer` to reuse its GL context."""
    if renderer is None:
        with KitchenRenderer(model, image_size) as r:
            return r.render(data)
    return renderer.render(data)
