"""Talos kitchen scene + Cartesian controller (MuJoCo, built at run time from example-robot-data)."""

import os

os.environ.setdefault("MUJOCO_GL", "egl")

from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import pytest  # noqa: E402

mujoco = pytest.importorskip("mujoco")

from lerobot_efm.envs.talos_kitchen import control, scene  # noqa: E402

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def kitchen():
    return scene.build_kitchen(128)


@pytest.fixture(scope="module")
def renderer(kitchen):
    model, _, _ = kitchen
    r = scene.KitchenRenderer(model, 128)
    yield r
    r.close()


def _angle_deg(ra, rb):
    return float(np.degrees(np.arccos(np.clip((np.trace(ra.T @ rb) - 1) / 2, -1, 1))))


def test_model_builds_from_package_not_repo(kitchen):
    model, data, h = kitchen
    root = scene.talos_data_dir()
    assert "site-packages" in str(root) or "dist-packages" in str(root)
    assert not str(root).startswith(str(REPO) + "/lerobot_efm")
    assert not list(REPO.glob("lerobot_efm/**/*.urdf")) and not list(REPO.glob("lerobot_efm/**/*.STL"))
    for n in scene.LEFT_ARM_JOINTS + scene.TORSO_JOINTS + ("gripper_left_joint",):
        assert model.joint(scene.ROBOT_PREFIX + n).id >= 0
    assert model.joint("door_hinge").type == mujoco.mjtJoint.mjJNT_HINGE
    assert model.joint("tray_slide").type == mujoco.mjtJoint.mjJNT_SLIDE
    assert model.joint("pot_free").type == mujoco.mjtJoint.mjJNT_FREE
    assert not any(model.joint(i).name.startswith(scene.ROBOT_PREFIX + "leg_") for i in range(model.njnt))
    assert model.camera("front").id >= 0 and model.nu == 20
    # cached: a second build reuses the compiled model with fresh data
    model2, data2, _ = scene.build_kitchen(128)
    assert model2 is model and data2 is not data


def test_scene_is_stable_at_rest():
    model, data, h = scene.build_kitchen(128)
    pot0, _ = scene.pot_pose(data, h)
    for _ in range(250):
        mujoco.mj_step(model, data)
    pot1, quat = scene.pot_pose(data, h)
    assert np.all(np.isfinite(data.qpos))
    assert np.linalg.norm(pot1 - pot0) < 5e-3 and abs(quat[0]) > 0.999
    assert abs(scene.door_angle(data, h)) < 0.02 and abs(scene.tray_slide(data, h)) < 0.01
    assert np.abs(data.qpos[h.arm_qpos] - h.home_qpos[h.arm_qpos]).max() < 0.05


def test_render_front_changes_when_door_opens(renderer):
    model, data, h = scene.build_kitchen(128)
    img = renderer.render(data)
    assert img.shape == (128, 128, 3) and img.dtype == np.uint8
    assert img.std() > 10 and len(np.unique(img.reshape(-1, 3), axis=0)) > 50
    data.qpos[h.door_qpos] = -1.5
    mujoco.mj_forward(model, data)
    img_open = renderer.render(data)
    assert np.abs(img_open.astype(int) - img.astype(int)).mean() > 1.0
    assert scene.door_angle(data, h) == pytest.approx(-1.5)


def test_rot6d_round_trip():
    rng = np.random.default_rng(0)
    for _ in range(20):
        q = rng.normal(size=4)
        q /= np.linalg.norm(q)
        mat = np.zeros(9)
        mujoco.mju_quat2Mat(mat, q)
        mat = mat.reshape(3, 3)
        r6 = control.matrix_to_rot6d(mat)
        assert np.allclose(control.rot6d_to_matrix(r6), mat, atol=1e-9)
        q2 = control.rot6d_to_quat(r6)
        assert np.allclose(q2, q if q[0] >= 0 else -q, atol=1e-9)
    # non-orthonormal input -> proper rotation
    m = control.rot6d_to_matrix(np.array([2.0, 0.1, 0.0, 0.3, 1.5, 0.2]))
    assert np.allclose(m.T @ m, np.eye(3), atol=1e-9) and np.linalg.det(m) == pytest.approx(1.0)
    batch = control.rot6d_to_matrix(rng.normal(size=(5, 6)))
    assert batch.shape == (5, 3, 3) and np.allclose(np.linalg.det(batch), 1.0)


def test_controller_reaches_target():
    model, data, h = scene.build_kitchen(128)
    ctrl = control.CartesianController(model, h)
    ctrl.reset(data)
    target_pos = np.array([0.32, 0.08, 1.08])
    target_rot = control.rot6d_to_matrix([0.2, 0.0, 1.0, 0.0, 1.0, 0.0])  # fingers forward, tilted
    cmd = np.concatenate([target_pos, control.matrix_to_rot6d(target_rot), [0.0]])
    for _ in range(50):  # 2 s at 25 Hz
        ctrl.step(data, cmd)
    pos, mat = control.hand_pose(data, h)
    assert np.linalg.norm(pos - target_pos) < 0.02
    assert _angle_deg(mat, target_rot) < 10.0
    state = control.hand_pose10(data, h)
    assert state.shape == (10,) and np.allclose(state[:3], pos)


def test_controller_unreachable_target_stays_finite():
    model, data, h = scene.build_kitchen(128)
    ctrl = control.CartesianController(model, h)
    ctrl.reset(data)
    far = np.concatenate([[5.0, 3.0, 4.0], [1, 0, 0, 0, 1, 0], [1.0]])  # outside the box, clipped
    for _ in range(25):
        ctrl.step(data, far)
    assert np.all(np.isfinite(data.qpos)) and np.all(np.isfinite(data.qvel))
    lo = model.jnt_range[[model.joint(scene.ROBOT_PREFIX + n).id for n in scene.LEFT_ARM_JOINTS], 0]
    hi = model.jnt_range[[model.joint(scene.ROBOT_PREFIX + n).id for n in scene.LEFT_ARM_JOINTS], 1]
    assert np.all(ctrl.q_target[:7] >= lo) and np.all(ctrl.q_target[:7] <= hi)
    pos, _ = control.hand_pose(data, h)
    home_pos = scene.build_kitchen(128)[1].site_xpos[h.left_tcp]
    clipped = np.clip([5.0, 3.0, 4.0], control.WORKSPACE_LOW, control.WORKSPACE_HIGH)
    assert np.linalg.norm(pos - clipped) < np.linalg.norm(home_pos - clipped)  # moved towards it


def test_controller_rejects_nan_and_bad_shape():
    model, data, h = scene.build_kitchen(128)
    ctrl = control.CartesianController(model, h)
    ctrl.reset(data)
    cmd = np.concatenate([[0.3, 0.2, 1.0], [0, 0, 1, 0, 1, 0], [0.0]])
    bad = cmd.copy()
    bad[1] = np.nan
    bad[9] = np.inf
    with pytest.raises(ValueError, match=r"y \(index 1\).*gripper \(index 9\)"):
        ctrl.step(data, bad)
    with pytest.raises(ValueError, match="10 entries"):
        ctrl.step(data, cmd[:9])
    with pytest.raises(ValueError, match="degenerate"):
        ctrl.step(data, np.concatenate([[0.3, 0.2, 1.0], [0, 0, 1, 0, 0, 2], [0.0]]))
