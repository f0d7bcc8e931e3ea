"""Synthetic play datasets: LeRobot v3 round trip, action bounds, coverage, dynamics consistency."""

import numpy as np
import pytest
import torch
from lerobot.datasets.lerobot_dataset import LeRobotDataset

import lerobot_efm.synthetic as synthetic
from lerobot_efm.envs.point_reach import in_wall, move_point, render_scene
from lerobot_efm.synthetic import make_point_play_dataset

REPO = "local/test_play"


def _columns(ds):
    hf = ds.hf_dataset
    return (np.stack(hf["observation.state"]), np.stack(hf["action"]), np.asarray(hf["episode_index"]))


def test_state_only_dataset(tmp_path):
    root = tmp_path / "play"
    make_point_play_dataset(root, repo_id=REPO, num_episodes=3, episode_length=60, seed=1)
    ds = LeRobotDataset(REPO, root=root)
    assert ds.num_episodes == 3 and ds.num_frames == 180 and ds.fps == 20
    assert set(ds.meta.camera_keys) == set()
    assert ds.features["observation.state"]["names"] == ["x", "y"]
    assert ds.features["action"]["shape"] == (2,)
    assert not any("goal" in k for k in ds.features)  # goals come from hindsight relabelling
    item = ds[0]
    assert item["observation.state"].shape == (2,) and item["action"].dtype == torch.float32
    assert item["task"] == "play"

    states, actions, eps = _columns(ds)
    assert np.all(np.abs(actions) <= 1.0)
    assert not any(in_wall(s) for s in states)
    for e in range(3):  # every episode wanders: it spans a sizeable part of the arena
        s = states[eps == e]
        assert np.ptp(s, axis=0).max() > 0.3
        nxt = np.stack([move_point(p, a) for p, a in zip(s[:-1], actions[eps == e][:-1], strict=True)])
        np.testing.assert_allclose(nxt, s[1:], atol=1e-5)  # actions explain the transitions
    assert np.ptp(states, axis=0).min() > 0.5


def test_video_dataset(tmp_path):
    root = tmp_path / "play_video"
    make_point_play_dataset(
        root, repo_id=REPO, num_episodes=2, episode_length=40, with_images=True, image_size=32
    )
    ds = LeRobotDataset(REPO, root=root)
    assert ds.num_episodes == 2 and ds.num_frames == 80
    assert ds.meta.video_keys == ["observation.images.top"]
    assert ds.features["observation.images.top"]["shape"] == (32, 32, 3)
    for i in (0, 57):
        item = ds[i]
        img = item["observation.images.top"]
        assert img.shape == (3, 32, 32) and img.dtype == torch.float32
        assert 0.0 <= float(img.min()) and float(img.max()) <= 1.0
        ref = torch.from_numpy(render_scene(item["observation.state"].numpy(), 32)).permute(2, 0, 1) / 255.0
        assert float((img - ref).abs().mean()) < 0.05  # lossy codec, but the same picture


def test_cli(tmp_path, capsys):
    root = tmp_path / "cli"
    synthetic.main([f"--dataset.root={root}", "--num_episodes=2", "--episode_length=20"])
    out = capsys.readouterr().out
    assert str(root) in out and "40 frames" in out


def test_failure_keeps_saved_episodes(tmp_path, monkeypatch):
    calls = {"n": 0}
    orig = synthetic.play_episode

    def flaky(*args, **kwargs):
        calls["n"] += 1
        if calls["n"] == 3:
            raise RuntimeError("boom")
        return orig(*args, **kwargs)

    monkeypatch.setattr(synthetic, "play_episode", flaky)
    root = tmp_path / "partial"
    with pytest.raises(RuntimeError, match="boom"):
        make_point_play_dataset(root, repo_id=REPO, num_episodes=4, episode_length=30)
    ds = LeRobotDataset(REPO, root=root)
    assert ds.num_episodes == 2 and ds.num_frames == 60
