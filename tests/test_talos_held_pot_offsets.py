"""``benchmarks/talos_held_pot_offsets.py``: carried frames of a play recording and nearest-offset distances."""

import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import talos_held_pot_offsets as offsets  # noqa: E402


def _recording(root: Path) -> None:
    """Two episodes of 40 frames: in episode 1 the pot rides 17 cm below the hand for frames 10-29."""
    n = 40
    state = np.zeros((2 * n, 20), np.float32)
    env = np.zeros((2 * n, 9), np.float32)
    env[:, 2:5] = [0.5, 0.3, 0.75]  # the pot at rest
    env[:n, 2:5] = [0.6, 0.4, 0.75]  # elsewhere in episode 0: not a move across the episodes' boundary
    state[:, 10:13] = [0.2, 0.2, 1.0]  # the hand far from it
    state[n : n + 10, 10:13] = [0.5, 0.3, 0.92]  # episode 1 starts with the hand at the pot's handle
    for i in range(10, 30):  # episode 1 carries it along x at 1 cm per frame
        hand = np.array([0.5 + 0.01 * (i - 10), 0.3, 0.92])
        state[n + i, 10:13] = hand
        env[n + i, 2:5] = hand - [0.0, 0.0, 0.17]
    env[n + 30 :, 2:5] = env[n + 29, 2:5]
    state[n + 30 :, 10:13] = state[n + 29, 10:13] + [0.0, 0.0, 0.2]  # let go, hand lifts away
    table = pa.table(
        {
            "observation.state": list(state),
            "observation.environment_state": list(env),
            "episode_index": np.repeat([0, 1], n),
        }
    )
    (root / "data" / "chunk-000").mkdir(parents=True)
    pq.write_table(table, root / "data" / "chunk-000" / "file-000.parquet")


def test_play_offsets_are_the_frames_where_the_hand_carries_the_pot(tmp_path):
    _recording(tmp_path)
    found, episodes = offsets.play_offsets(tmp_path)
    # frames 11-29 of episode 1 (frame 10 holds it where it rested); not the resting pot of episode 0, and not
    # frames 30-32, where the pot still differs from 3 frames before but the hand has lifted away
    assert len(found) == 19 and set(episodes) == {1}
    np.testing.assert_allclose(found, [[0.0, 0.0, -0.17]] * 19, atol=1e-6)


def test_nearest_distance_to_a_point_cloud():
    points = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    queries = np.array([[0.1, 0.0, 0.0], [0.9, 0.2, 0.0], [0.5, 0.0, 0.0]] * 400)
    d = offsets.nearest(queries, points)
    np.testing.assert_allclose(d[:3], [0.1, np.hypot(0.1, 0.2), 0.5])
    assert len(d) == 1200
