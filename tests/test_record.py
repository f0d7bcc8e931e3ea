"""``lerobot-efm-record``: scripted operators recorded as LeRobot datasets, safe to interrupt."""

import json
import os
import signal
import subprocess
import sys

import numpy as np
import pytest
from lerobot.datasets.lerobot_dataset import LeRobotDataset

from lerobot_efm.dataset_writer import EpisodeWriter
from lerobot_efm.envs.point_reach import PointReachEnvConfig
from lerobot_efm.recording import make_raw_env, operator_class, record_episodes
from lerobot_efm.synthetic import PointPlayOperator

RECORD = [sys.executable, "-m", "lerobot_efm.scripts.record"]
POINT_ARGS = [
    "--env.type=efm_point_reach",
    "--env.obs_type=pixels_state",
    "--env.image_size=32",
    "--dataset.repo_id=local/rec_test",
    "--dataset.push_to_hub=false",
]
ENV = {**os.environ, "HF_HUB_OFFLINE": "1", "OMP_NUM_THREADS": "1"}


def _record_ok(args: list[str]) -> None:
    """Run lerobot-efm-record in a subprocess; it must succeed."""
    subprocess.run(args, check=True, env=ENV, capture_output=True, timeout=300)


def test_cli_records_video_dataset_and_resumes(tmp_path):
    root = tmp_path / "ds"
    args = [*RECORD, *POINT_ARGS, f"--dataset.root={root}", "--dataset.episode_time_s=1.5"]
    _record_ok([*args, "--dataset.num_episodes=2", "--seed=3"])
    ds = LeRobotDataset("local/rec_test", root=root)
    assert ds.num_episodes == 2 and ds.num_frames == 60
    assert ds.meta.features["observation.images.top"]["dtype"] == "video"
    assert set(ds.meta.features) >= {"observation.state", "action", "observation.images.top"}
    assert not any("goal" in k for k in ds.meta.features)  # goals come from hindsight relabelling
    item = ds[35]
    assert item["observation.images.top"].shape == (3, 32, 32)
    # the recorded state is the point's position before the recorded action moved it
    states = np.stack([ds[i]["observation.state"].numpy() for i in range(30)])
    actions = np.stack([ds[i]["action"].numpy() for i in range(30)])
    assert np.all(np.abs(actions) <= 1) and np.linalg.norm(np.diff(states, axis=0), axis=1).max() < 0.1
    assert ds.meta.tasks.index.tolist() == ["play"]

    again = subprocess.run(
        [*args, "--dataset.num_episodes=1", "--seed=4"], env=ENV, capture_output=True, text=True
    )
    assert again.returncode != 0 and "--resume=true" in again.stderr  # never overwrites a dataset
    _record_ok([*args, "--dataset.num_episodes=1", "--resume=true"])
    ds = LeRobotDataset("local/rec_test", root=root)
    assert ds.num_episodes == 3 and ds.num_frames == 90
    assert ds[89]["observation.images.top"].shape == (3, 32, 32)


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_interrupt_keeps_saved_episodes(tmp_path, sig):
    root = tmp_path / "ds"
    proc = subprocess.Popen(
        [
            *RECORD,
            *POINT_ARGS,
            f"--dataset.root={root}",
            "--dataset.num_episodes=1000",
            "--dataset.episode_time_s=2",
        ],
        env=ENV,
        stderr=subprocess.PIPE,
        text=True,
    )
    seen = []
    for line in proc.stderr:  # wait until two episodes are saved, then interrupt mid-recording
        seen.append(line)
        if "episode 1:" in line:
            proc.send_signal(sig)
            break
    _, rest = proc.communicate(timeout=120)
    assert proc.returncode == 130, "".join(seen) + rest
    assert "interrupted" in rest
    ds = LeRobotDataset("local/rec_test", root=root)
    assert ds.num_episodes >= 2 and ds.num_frames == 40 * ds.num_episodes
    assert ds[ds.num_frames - 1]["observation.images.top"].shape == (3, 32, 32)


class _CrashOnce:
    """Wraps the real point operator and raises in the middle of episode 1 (a simulated bug)."""

    def __init__(self, env, rng):
        self.inner, self.episode, self.frame = PointPlayOperator(env, rng), -1, 0
        self.done = False

    def reset(self):
        self.episode, self.frame = self.episode + 1, 0
        return self.inner.reset()

    def act(self, obs):
        self.frame += 1
        if self.episode == 1 and self.frame == 10:
            raise RuntimeError("operator bug")
        return self.inner.act(obs)


POINT_FEATURES = {
    "observation.state": {"dtype": "float32", "shape": (2,), "names": ["x", "y"]},
    "action": {"dtype": "float32", "shape": (2,), "names": ["x", "y"]},
}


def _point_recording(root, operator_cls, repo_id):
    cfg = PointReachEnvConfig()
    env = make_raw_env(cfg)
    op = operator_cls(env, np.random.default_rng(0))
    env.reset(seed=0)
    writer = EpisodeWriter.open(root, repo_id, cfg.fps, POINT_FEATURES, use_videos=False)
    return cfg, env, op, writer


def test_crashing_episode_is_dropped_and_recording_goes_on(tmp_path):
    cfg, env, op, writer = _point_recording(tmp_path / "ds", _CrashOnce, "local/crash")
    with writer:
        stats = record_episodes(writer, env, op, cfg.features_map, episodes=3, episode_length=25, task="play")
    assert stats.saved == 2 and len(stats.failed) == 1 and "operator bug" in stats.failed[0]
    ds = LeRobotDataset("local/crash", root=tmp_path / "ds")
    assert ds.num_episodes == 2 and ds.num_frames == 50


def test_signal_while_saving_an_episode_keeps_it_and_stops(tmp_path, monkeypatch):
    """A SIGTERM that lands inside save_episode (CI hit this) waits for the episode to be written."""
    cfg, env, op, writer = _point_recording(tmp_path / "ds", PointPlayOperator, "local/sig")
    ds = writer.dataset
    real_save, calls = ds.save_episode, []

    def save_then_signal(*args, **kwargs):
        calls.append(1)
        if len(calls) == 2:
            os.kill(os.getpid(), signal.SIGTERM)  # delivered before the real save starts writing
        return real_save(*args, **kwargs)

    monkeypatch.setattr(ds, "save_episode", save_then_signal)
    with writer:
        stats = record_episodes(writer, env, op, cfg.features_map, episodes=5, episode_length=20, task="play")
    assert stats.interrupted and stats.saved == 2 and stats.frames == 40
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL  # the recorder's handler is gone
    ds = LeRobotDataset("local/sig", root=tmp_path / "ds")
    assert ds.num_episodes == 2 and ds.num_frames == 40


def test_unknown_operator_lists_the_registered_ones():
    with pytest.raises(ValueError, match="--env.type=talos_kitchen --operator=play"):
        operator_class("efm_point_reach", "expert")


def test_push_to_hub_sends_our_dataset_card(tmp_path, monkeypatch):
    """--push_to_hub=true: LeRobot's push gets the card of datasets_cards/ (tags, description, paper), which its
    own card template renders (the Hub itself is unreachable here: the push is captured)."""
    from lerobot.datasets.utils import create_lerobot_dataset_card

    from lerobot_efm.scripts.record import main as record

    pushed = {}
    monkeypatch.setattr(LeRobotDataset, "push_to_hub", lambda self, **kwargs: pushed.update(kwargs))
    record(
        [
            "--env.type=efm_point_reach",
            "--dataset.repo_id=local/push_test",
            f"--dataset.root={tmp_path / 'ds'}",
            "--dataset.num_episodes=1",
            "--dataset.episode_time_s=0.25",
            "--dataset.push_to_hub=true",
        ]
    )
    assert {"extremum-flow-matching", "play-data"} <= set(pushed["tags"]) and not pushed["private"]
    info = LeRobotDataset("local/push_test", root=tmp_path / "ds").meta.info  # what LeRobot's push adds
    card = str(create_lerobot_dataset_card(dataset_info=info, **pushed))
    assert (
        "PointReach" in card and "arxiv.org/abs/2505.19717" in card and "More Information Needed" not in card
    )


def _sealed_episode_files(root) -> int:
    from lerobot_efm.crash_safe import _readable

    return sum(_readable(p) for p in root.glob("meta/episodes/**/*.parquet"))


def test_a_recorder_killed_with_sigkill_keeps_every_saved_episode(tmp_path):
    """SIGKILL cannot be caught (OOM killer, power cut): the files on disk must be a complete dataset after each
    saved episode. Killed after >= 3 saved episodes, the dataset opens (after the repair --resume runs, which only
    removes the debris of a save cut short) with all of them, video frames decodable, and recording resumes."""
    import time

    from lerobot_efm.crash_safe import repair_dataset

    root = tmp_path / "ds"
    proc = subprocess.Popen(
        [
            *RECORD,
            *POINT_ARGS,
            f"--dataset.root={root}",
            "--dataset.episode_time_s=2",
            "--dataset.num_episodes=200",
        ],
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    try:
        deadline = time.monotonic() + 120
        while _sealed_episode_files(root) < 3 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        saved = _sealed_episode_files(root)
    finally:
        proc.kill()
        proc.wait()
    assert saved >= 3, f"only {saved} episodes saved before the deadline"
    repair_dataset(root)
    ds = LeRobotDataset("local/rec_test", root=root)
    assert ds.num_episodes >= saved and ds.num_frames == 40 * ds.num_episodes
    assert ds[ds.num_frames - 1]["observation.images.top"].shape == (3, 32, 32)  # the last video decodes
    kept = ds.num_episodes
    _record_ok(
        [
            *RECORD,
            *POINT_ARGS,
            f"--dataset.root={root}",
            "--dataset.episode_time_s=2",
            "--dataset.num_episodes=1",
            "--resume=true",
        ]
    )
    assert LeRobotDataset("local/rec_test", root=root).num_episodes == kept + 1


def test_repair_removes_the_debris_of_a_save_cut_short(tmp_path):
    """A kill inside save_episode: frames written without a footer, an episode-metadata file cut short and
    info.json already counting the episode. The repair keeps the saved episodes and makes the dataset open."""
    from lerobot_efm.crash_safe import repair_dataset

    root = tmp_path / "ds"
    _record_ok(
        [
            *RECORD,
            *POINT_ARGS,
            f"--dataset.root={root}",
            "--dataset.episode_time_s=1",
            "--dataset.num_episodes=3",
        ]
    )
    data = sorted(root.glob("data/**/*.parquet"))
    meta = sorted(root.glob("meta/episodes/**/*.parquet"))
    assert len(data) == len(meta) == 3  # one file of each per episode: every one closed when its episode was
    cut_data, cut_meta = data[-1].with_name("file-009.parquet"), meta[-1].with_name("file-009.parquet")
    cut_data.write_bytes(data[-1].read_bytes()[:-100])
    cut_meta.write_bytes(meta[-1].read_bytes()[: len(meta[-1].read_bytes()) // 2])
    info = json.loads((root / "meta/info.json").read_text())
    (root / "meta/info.json").write_text(json.dumps({**info, "total_episodes": 4, "total_frames": 80}))
    removed = repair_dataset(root)
    assert {p.name for p in removed} == {"file-009.parquet"} and len(removed) == 2
    ds = LeRobotDataset("local/rec_test", root=root)
    assert ds.num_episodes == 3 and ds.num_frames == 60 and len(ds) == 60
    assert json.loads((root / "meta/info.json").read_text())["total_episodes"] == 3


def test_lerobot_style_dataset_flags_are_checked():
    """The recorder takes LeRobot's --dataset.* flags (DatasetRecordConfig); missing ones are named."""
    proc = subprocess.run(
        [*RECORD, "--env.type=efm_point_reach", "--dataset.repo_id=local/x", "--dataset.push_to_hub=false"],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode != 0 and "--dataset.repo_id and --dataset.root are required" in proc.stderr


def test_operators_are_draccus_choices_with_their_own_options(tmp_path):
    """--operator.type picks a registered operator, --operator.<option> sets its keyword options (defaults from
    its signature); an operator of another env is refused with the env's list."""
    args = [
        *RECORD,
        "--env.type=planar_push",
        "--dataset.repo_id=local/op_test",
        f"--dataset.root={tmp_path / 'ds'}",
        "--dataset.num_episodes=1",
        "--dataset.episode_time_s=2",
        "--dataset.push_to_hub=false",
    ]
    _record_ok([*args, "--operator.type=planar_push_hand", "--operator.pause_share=0.0"])
    states = np.stack(LeRobotDataset("local/op_test", root=tmp_path / "ds").hf_dataset["observation.state"])
    assert (
        np.ptp(states[:, 2:], axis=0).max() < 1e-6 and np.ptp(states[:, :2], axis=0).max() > 0.05
    )  # the hand
    wrong = subprocess.run(
        [
            *[a for a in args if not a.startswith("--dataset.root")],
            f"--dataset.root={tmp_path / 'other'}",
            "--operator.type=talos_kitchen_play",
        ],
        env=ENV,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert (
        wrong.returncode != 0
        and "planar_push_full" in wrong.stderr
        and "not --env.type=planar_push" in wrong.stderr
    )
