"""How often a recorded Talos play visits the task states, and how often its pot rests on a tray rim.

Reads ``observation.environment_state`` of a LeRobot v3 recording (no video decoded) and prints the dataset
card's coverage table (``play.coverage`` per episode, summed: env success tolerances) plus the share of frames
with the pot at rest on the pulled-out tray but more than 2 cm above its floor, i.e. on a rim or a wall.

    python benchmarks/talos_play_coverage.py outputs/talos/play48
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
import pandas as pd

from lerobot_efm.envs.talos_kitchen import play

RIM_DZ = 0.02  # m above the settled pot base height on the tray floor
AT_REST = 1e-4  # m of pot motion per frame
CARD_ROWS = [
    ("door open / closed", ["door_open", "door_closed"]),
    ("tray out / in", ["tray_out", "tray_in"]),
    ("pot at table home / moved spot / on the tray", ["pot_home", "pot_moved", "pot_on_tray"]),
    ("door closed, tray in, pot home", ["state/door_closed/tray_in/pot_home"]),
    ("door open, tray in, pot home", ["state/door_open/tray_in/pot_home"]),
    ("door closed, tray out, pot home", ["state/door_closed/tray_out/pot_home"]),
    ("door closed, tray in, pot moved", ["state/door_closed/tray_in/pot_moved"]),
    ("door closed, tray out, pot on tray", ["state/door_closed/tray_out/pot_tray"]),
]


def env_states(root: Path) -> tuple[np.ndarray, np.ndarray]:
    files = sorted((root / "data").glob("chunk-*/file-*.parquet"))
    if not files:
        raise FileNotFoundError(f"no data/chunk-*/file-*.parquet under {root}")
    df = pd.concat(
        [pd.read_parquet(f, columns=["observation.environment_state", "episode_index"]) for f in files]
    )
    return np.stack(df["observation.environment_state"].to_numpy()), df["episode_index"].to_numpy()


def on_rim(e: np.ndarray, episode: np.ndarray) -> tuple[int, int]:
    """(frames with the pot at rest over the tray floor, of which > RIM_DZ high)."""
    tray, pot = e[:, 1], e[:, 2:5]
    local = pot - (play.tray_xyz(0.0, (0.0, 0.0))[None] + np.c_[tray, np.zeros((len(e), 2))])
    over_tray = (np.abs(local[:, 0]) < 0.16) & (np.abs(local[:, 1]) < 0.15) & (local[:, 2] < 0.10)
    moved = np.r_[np.inf, np.linalg.norm(np.diff(pot, axis=0), axis=1)]
    moved[np.r_[True, episode[1:] != episode[:-1]]] = np.inf  # first frame of an episode: unknown
    rest = over_tray & (moved < AT_REST) & (tray < -0.2)
    return int(rest.sum()), int((rest & (local[:, 2] > RIM_DZ)).sum())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("root", type=Path, help="LeRobot dataset root")
    args = p.parse_args()
    e, episode = env_states(args.root)
    total: dict[str, dict[str, int]] = {}
    for ep in np.unique(episode):
        for k, v in play.coverage(e[episode == ep]).items():
            t = total.setdefault(k, {"frames": 0, "visits": 0})
            t["frames"] += v["frames"]
            t["visits"] += v["visits"]
    n = len(e)
    print(f"{len(np.unique(episode))} episodes, {n} frames\n")
    print("| state | share of frames | separate visits |\n|---|---|---|")
    for label, keys in CARD_ROWS:
        shares = " / ".join(f"{100 * total[k]['frames'] / n:.1f} %" for k in keys)
        visits = " / ".join(str(total[k]["visits"]) for k in keys)
        print(f"| {label} | {shares} | {visits} |")
    rest, rim = on_rim(e, episode)
    print(
        f"\npot at rest on the pulled-out tray: {rest} frames, {rim} of them > {100 * RIM_DZ:.0f} cm high (on a rim)"
    )


if __name__ == "__main__":
    main()
