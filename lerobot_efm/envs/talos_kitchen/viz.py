"""How rerun draws the Talos kitchen (``--env.type=talos_kitchen``): commanded and measured hand, door and tray
handles, the pot, and the static table / cabinet / workspace."""

from __future__ import annotations

import numpy as np
import rerun as rr

from ...viz.env_viz import ENV_STATE_KEY, STATE_KEY, EnvViz, hand_points


def _talos_layout() -> dict[str, int]:
    """Where the hand positions and object states sit in the talos_kitchen vectors (from the env's names)."""
    from lerobot_efm.envs.talos_kitchen.env import ENV_STATE_NAMES, STATE_NAMES

    return {
        "cmd": STATE_NAMES.index("cmd_x"),
        "measured": STATE_NAMES.index("x"),
        "door": ENV_STATE_NAMES.index("door"),
        "tray": ENV_STATE_NAMES.index("tray"),
        "pot": ENV_STATE_NAMES.index("pot_x"),
    }


def _talos_objects(env_state: np.ndarray) -> dict[str, np.ndarray]:
    """Door handle, tray handle (where the door angle / tray slide put them) and pot base centre, in 3-D."""
    from lerobot_efm.envs.talos_kitchen import scene

    i, e = _talos_layout(), np.asarray(env_state, np.float64).reshape(-1)
    # the handle helpers read only the constants of the scene when the angle / slide is given
    return {
        "door_handle": scene.door_handle_pos(None, None, angle=float(e[i["door"]])).astype(np.float32),
        "tray_handle": scene.tray_handle_pos(None, None, slide=float(e[i["tray"]])).astype(np.float32),
        "pot": e[i["pot"] : i["pot"] + 3].astype(np.float32),
    }


def _talos_series(env_state: np.ndarray) -> dict[str, float]:
    i, e = _talos_layout(), np.asarray(env_state, np.float64).reshape(-1)
    pot = e[i["pot"] : i["pot"] + 3]
    return {"door": e[i["door"]], "tray": e[i["tray"]], "pot_x": pot[0], "pot_y": pot[1], "pot_z": pot[2]}


def _box_outline(lo, hi) -> list[list[float]]:
    """The 12 edges of an axis-aligned box as 2-point strips."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    corners = np.array(
        [[(lo, hi)[a][0], (lo, hi)[b][1], (lo, hi)[c][2]] for a in (0, 1) for b in (0, 1) for c in (0, 1)]
    )
    edges = [(i, j) for i in range(8) for j in range(i + 1, 8) if bin(i ^ j).count("1") == 1]
    return [[corners[i].tolist(), corners[j].tolist()] for i, j in edges]


def _talos_scene(rec: rr.RecordingStream) -> None:
    """Table top, cabinet front and door hinge, and the hand workspace box (static, from the scene constants)."""
    from lerobot_efm.envs.talos_kitchen import control, scene

    (tx, ty), (hx, hy), z = scene.TABLE_CENTER, scene.TABLE_HALF, scene.TABLE_TOP
    table = [
        [tx - hx, ty - hy, z],
        [tx + hx, ty - hy, z],
        [tx + hx, ty + hy, z],
        [tx - hx, ty + hy, z],
        [tx - hx, ty - hy, z],
    ]
    x0, y0, y1 = scene.CAB_X0, scene.CAB_Y0, scene.CAB_Y1
    cabinet = [[x0, y0, 0.0], [x0, y1, 0.0], [x0, y1, 1.25], [x0, y0, 1.25], [x0, y0, 0.0]]
    hinge = [
        [scene.DOOR_HINGE[0], scene.DOOR_HINGE[1], 0.92],
        [scene.DOOR_HINGE[0], scene.DOOR_HINGE[1], 1.25],
    ]
    rec.log("scene/table", rr.LineStrips3D([table], colors=[(150, 110, 60)], radii=0.006), static=True)
    rec.log(
        "scene/cabinet", rr.LineStrips3D([cabinet, hinge], colors=[(110, 110, 110)], radii=0.005), static=True
    )
    rec.log(
        "scene/workspace",
        rr.LineStrips3D(
            _box_outline(control.WORKSPACE_LOW, control.WORKSPACE_HIGH), colors=[(200, 200, 200)], radii=0.002
        ),
        static=True,
    )
    rec.log(
        "scene/robot_base",
        rr.Points3D(
            [[0.0, 0.0, scene.BASE_HEIGHT]], colors=[(90, 90, 90)], radii=0.05, labels=["Talos base"]
        ),
        static=True,
    )


def _talos_kitchen_viz() -> EnvViz:
    from lerobot_efm.envs.talos_kitchen.env import ENV_STATE_NAMES, STATE_NAMES

    i = _talos_layout()
    viz = hand_points(
        commanded=slice(i["cmd"], i["cmd"] + 3),
        measured=slice(i["measured"], i["measured"] + 3),
        action=slice(0, 3),
    )  # actions: position (3) + rot6d (6) + gripper (1)
    viz.scene = _talos_scene
    viz.object_points = {ENV_STATE_KEY: _talos_objects}
    viz.object_series = {ENV_STATE_KEY: _talos_series}
    viz.object_series_title = "door (rad), tray, pot (m); thin: goal"
    viz.dim_names = {STATE_KEY: STATE_NAMES, ENV_STATE_KEY: ENV_STATE_NAMES}
    viz.eye = (
        (-0.55, -1.25, 1.75),
        (0.45, 0.1, 0.95),
    )  # behind the robot's right shoulder, facing the kitchen
    return viz


TALOS_KITCHEN_VIZ = _talos_kitchen_viz()
