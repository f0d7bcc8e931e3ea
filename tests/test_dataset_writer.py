"""The one dataset writer (lerobot_efm.dataset_writer): episodes sealed at a bounded interval survive a hard kill,
a SIGTERM between frames keeps the saved episodes, and feature specs name what they hold."""

import os
import shutil
import signal

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_efm import dataset_writer
from lerobot_efm.crash_safe import repair_dataset
from lerobot_efm.dataset_writer import EpisodeWriter, RecordingInterrupted, state_action_features
from lerobot_efm.recording import dataset_features

FEATURES = state_action_features(["x", "y"], ["vx", "vy"])


def _frames(episode: int, length: int = 10):
    for t in range(length):
        value = np.full(2, episode + t / 100, np.float32)
        yield {"observation.state": value, "action": value, "task": "play"}


def test_generators_seal_their_files_at_a_bounded_interval(tmp_path, monkeypatch):
    """With seal_interval_s=30, episodes saved at t = 0, 12, 24, 36, 48 s are sealed at 36 s: a SIGKILL after the
    fifth save (the files as they are on disk, copied) keeps the first four episodes, and the finished dataset
    holds all five in two data files."""
    clock = [0.0]
    monkeypatch.setattr(dataset_writer, "_now", lambda: clock[0])
    root, snapshot = tmp_path / "ds", tmp_path / "killed"
    with EpisodeWriter.open(root, "local/w", 10, FEATURES, use_videos=False, seal_interval_s=30) as writer:
        for episode in range(5):
            clock[0] = 12.0 * episode
            assert writer.write_episode(_frames(episode)) == 10
        shutil.copytree(root, snapshot)  # what a hard kill leaves: the fifth episode's files are still open
    repair_dataset(snapshot)
    killed = LeRobotDataset("local/w", root=snapshot)
    assert killed.num_episodes == 4 and killed.num_frames == 40
    assert np.allclose(killed[39]["observation.state"], 3.09)
    done = LeRobotDataset("local/w", root=root)
    assert done.num_episodes == 5 and len(sorted(root.glob("data/**/*.parquet"))) == 2


def test_sigterm_between_frames_keeps_the_saved_episodes(tmp_path):
    """A converter or generator stopped by SIGTERM raises RecordingInterrupted at the next frame; the unfinished
    episode is dropped and the dataset is finalized with the saved ones."""

    def frames_with_signal(episode):
        for t, frame in enumerate(_frames(episode)):
            if episode == 2 and t == 5:
                os.kill(os.getpid(), signal.SIGTERM)
            yield frame

    root = tmp_path / "ds"
    with pytest.raises(RecordingInterrupted):
        with EpisodeWriter.open(
            root, "local/s", 10, FEATURES, use_videos=False, seal_interval_s=1e9
        ) as writer:
            for episode in range(4):
                writer.write_episode(frames_with_signal(episode))
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL
    ds = LeRobotDataset("local/s", root=root)
    assert ds.num_episodes == 2 and ds.num_frames == 20


def test_feature_specs_name_their_entries_and_refuse_a_mismatch():
    spec = state_action_features(["a", "b", "c"], ["u"], {"top": 16})
    assert spec["observation.state"] == {"dtype": "float32", "shape": (3,), "names": ["a", "b", "c"]}
    assert (
        spec["observation.images.top"]["shape"] == (16, 16, 3)
        and spec["observation.images.top"]["dtype"] == "video"
    )
    frame = {"observation.state": np.zeros(3, np.float32)}
    assert dataset_features(frame, 2)["action"]["names"] == ["action_0", "action_1"]
    with pytest.raises(ValueError, match="'observation.state'.*value has 3"):
        dataset_features(frame, 2, {"observation.state": ["x", "y"]})


def test_an_existing_root_is_refused_by_name(tmp_path):
    (tmp_path / "ds").mkdir()
    with pytest.raises(FileExistsError, match="ds already exists"):
        EpisodeWriter.open(tmp_path / "ds", "local/x", 10, FEATURES)


def test_a_kill_while_lerobot_rewrites_info_json_keeps_the_sealed_episodes(tmp_path):
    """LeRobot rewrites meta/info.json and stats.json in place at every saved episode: a SIGKILL in that window
    leaves them empty. The repair restores them from the copy kept at the last seal; a finished dataset keeps
    no copy, and without one the unreadable file is named."""
    root, snapshot = tmp_path / "ds", tmp_path / "killed"
    with EpisodeWriter.open(root, "local/k", 10, FEATURES, use_videos=False) as writer:
        for episode in range(3):
            writer.write_episode(_frames(episode))
        shutil.copytree(root, snapshot)
    for name in ("info.json", "stats.json", "tasks.parquet"):  # truncated, then the kill before the write
        (snapshot / "meta" / name).write_text("")
    repair_dataset(snapshot)
    killed = LeRobotDataset("local/k", root=snapshot)
    assert killed.num_episodes == 3 and killed.num_frames == 30 and killed[29]["task"] == "play"
    assert np.allclose(killed.meta.stats["observation.state"]["max"], 2.09)
    assert not (root / "meta" / "last_sealed").exists()  # a normal finish leaves a plain LeRobot dataset
    (root / "meta" / "info.json").write_text("")
    with pytest.raises(ValueError, match="info.json is unreadable"):
        repair_dataset(root)
