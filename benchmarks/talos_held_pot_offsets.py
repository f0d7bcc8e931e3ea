"""Does a Talos policy hold the pot where the play held it? Grasp offsets of rollouts against the play's.

The image FM-AC reads the pot 2-4 cm off while it carries it, and about 1 cm off on the play's frames
(`benchmarks/results/talos_kitchen.md`). One explanation: the policy's own grasps put the pot at offsets from
the hand that the play never shows, so the camera sees an arm-and-pot picture it was not trained on. This
measures it: the pot's position minus the measured hand position (world frame) on every frame where the pot is
carried, in the play (the pot moving while the hand is within 25 cm of its centre: the play records no weld flag) and in
rollouts (``info/held`` of ``lerobot-efm-log-rollouts`` ``.rrd`` files); for each rollout frame, the distance to
the nearest play offset, next to the same distance for one half of the play's episodes against the other
(what a new grasp of the operator's own lands at); and the pot readout error by that distance.

    python benchmarks/talos_held_pot_offsets.py --play outputs/talos34/play48 \\
        --rrd outputs/talos34/eval_g1/*.rrd outputs/talos34/eval_g2/*.rrd
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

HAND = slice(10, 13)  # measured hand position in observation.state (Talos)
POT = slice(2, 5)  # pot position in observation.environment_state
NEAR_HAND = 0.25  # m: a moving pot this close to the hand is carried by it (pot centre to handle: ~15 cm)
MOVING = 0.003  # m over LAG frames
LAG = 3


def play_offsets(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """(offset of every carried frame, its episode index) from a LeRobot recording's parquet files."""
    import pyarrow.parquet as pq

    files = sorted((root / "data").glob("*/*.parquet"))
    if not files:
        raise FileNotFoundError(f"no parquet files under {root / 'data'}: not a LeRobot v3 recording")
    offsets, episodes = [], []
    for f in files:
        t = pq.read_table(f, columns=["observation.state", "observation.environment_state", "episode_index"])
        state = np.stack(t["observation.state"].to_numpy(zero_copy_only=False))
        env = np.stack(t["observation.environment_state"].to_numpy(zero_copy_only=False))
        ep = t["episode_index"].to_numpy()
        hand, pot = state[:, HAND], env[:, POT]
        moved = np.zeros(len(pot), bool)
        moved[LAG:] = (np.linalg.norm(pot[LAG:] - pot[:-LAG], axis=1) > MOVING) & (ep[LAG:] == ep[:-LAG])
        carried = moved & (np.linalg.norm(pot - hand, axis=1) < NEAR_HAND)
        offsets.append(pot[carried] - hand[carried])
        episodes.append(ep[carried])
    return np.concatenate(offsets), np.concatenate(episodes)


def rollout_offsets(rrd_files: list[Path]) -> tuple[np.ndarray, np.ndarray]:
    """(offset, 3-D pot readout error or nan) of every held frame of the rollouts' ``.rrd`` files."""
    from lerobot_efm.envs.talos_kitchen.grasps import HELD_CODE
    from lerobot_efm.viz import read_rrd

    names = ("/obs/state", "/world/pot", "/info/held", "/objects/pot_", "/objects/read_pot_")

    def wanted(entity: str) -> bool:  # not the camera frames
        return any(entity.endswith(n) or (n.endswith("_") and n in entity) for n in names)

    offsets, errors = [], []
    for path in rrd_files:
        data = read_rrd(path, keep=wanted)
        for ep in sorted({k.split("/")[0] for k in data if k.startswith("episode_")}):

            def rows(name, ep=ep, data=data):
                return {r["step"]: r for r in data.get(f"{ep}/{name}", []) if r.get("step") is not None}

            state, pot, held = rows("obs/state"), rows("world/pot"), rows("info/held")
            true = [rows(f"objects/pot_{c}") for c in "xyz"]
            read = [rows(f"objects/read_pot_{c}") for c in "xyz"]
            for step, h in held.items():
                if int(h["Scalars:scalars"][0]) != HELD_CODE["pot"] or step not in state or step not in pot:
                    continue
                hand = np.asarray(state[step]["Scalars:scalars"], float)[HAND]
                offsets.append(np.asarray(pot[step]["Points3D:positions"][0], float) - hand)
                if all(step in r for r in read) and all(step in t for t in true):
                    e = [
                        read[i][step]["Scalars:scalars"][0] - true[i][step]["Scalars:scalars"][0]
                        for i in range(3)
                    ]
                    errors.append(float(np.linalg.norm(e)))
                else:
                    errors.append(np.nan)
    return np.array(offsets).reshape(-1, 3), np.array(errors)


def nearest(queries: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance of each query to its nearest point (in chunks of 500 queries: ~200 MB against 16k points)."""
    out = []
    for chunk in np.array_split(queries, max(1, len(queries) // 500)):
        out.append(np.sqrt(((chunk[:, None, :] - points[None]) ** 2).sum(-1)).min(1))
    return np.concatenate(out) if out else np.zeros(0)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--play", type=Path, required=True, help="the policy's training recording")
    ap.add_argument("--rrd", type=Path, nargs="+", required=True, help="rollout .rrd files")
    args = ap.parse_args(argv)

    play, play_ep = play_offsets(args.play)
    roll, err = rollout_offsets(args.rrd)
    if not len(play) or not len(roll):
        raise SystemExit(f"carried frames: play {len(play)}, rollouts {len(roll)}: nothing to compare")
    half = play_ep < np.median(np.unique(play_ep))
    own = nearest(play[~half], play[half])  # the operator's new grasps against its other grasps
    new = nearest(roll, play)
    print(f"carried frames: play {len(play)} ({len(np.unique(play_ep))} episodes), rollouts {len(roll)}")
    print("\n| offset pot - hand (cm) | mean x / y / z | std x / y / z |\n|---|---:|---:|")
    for name, o in (("play", play), ("rollouts", roll)):
        m, s = o.mean(0) * 100, o.std(0) * 100
        print(f"| {name} | {m[0]:.1f} / {m[1]:.1f} / {m[2]:.1f} | {s[0]:.1f} / {s[1]:.1f} / {s[2]:.1f} |")
    print(
        "\n| distance to the nearest play offset | median | 90th pct | share > 1 cm |\n|---|---:|---:|---:|"
    )
    for name, d in (("play, one half against the other", own), ("rollouts against the play", new)):
        q50, q90 = np.percentile(d, [50, 90]) * 100
        print(f"| {name} | {q50:.2f} cm | {q90:.2f} cm | {(d > 0.01).mean() * 100:.0f} % |")
    ok = ~np.isnan(err)
    if ok.any():
        print(
            "\n| rollout frames (replans with a reading) | frames | pot readout error: median |\n|---|---:|---:|"
        )
        for label, sel in (("within 1 cm of a play offset", new <= 0.01), ("beyond 1 cm", new > 0.01)):
            e = err[ok & sel]
            cell = f"{np.median(e) * 100:.1f} cm" if len(e) else "–"
            print(f"| {label} | {len(e)} | {cell} |")


if __name__ == "__main__":
    main()
