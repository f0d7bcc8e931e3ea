"""Where a Talos policy leaves the pot when a pot task fails: never grasped, dropped, or set down off the goal.

Rolls a policy out on a pot task (``lerobot-efm-log-rollouts``, the same episodes as ``lerobot-eval`` for a
seed), reads the ``.rrd`` back and reports, per episode, the pot's position at each release of a held pot and at
the end, against the goal's (success: within 5 cm, ``tasks.POT_TOL``). A failure is classed as
``never held`` (no closure welded the pot), ``fell`` (the pot ended under the table top), ``above the goal``
(within 10 cm of it in x-y but resting more than 2 cm higher: on a rim or wall, not on the tray floor) or
``off target``.

    MUJOCO_GL=egl python benchmarks/talos_pot_placements.py --policy CKPT --task pot_to_tray --episodes 20 \\
        --out benchmarks/results/talos_pot_placements_pot_to_tray
"""

from __future__ import annotations

import argparse
import json
from collections import Counter
from pathlib import Path

import numpy as np
from talos_door_releases import rollouts_rrd, scalars

HELD_POT = 1  # lerobot_efm.envs.talos_kitchen.grasps.HELD_CODE["pot"]
FELL_BELOW_Z = 0.5  # m: under the table top (0.7 m) the pot is on the floor
ABOVE_GOAL_DZ = 0.02  # m
NEAR_GOAL_XY = 0.10  # m: farther away the pot is on the table, not on a rim of the tray


def pot_xyz(rrd: dict, e: int, prefix: str = "") -> dict[int, np.ndarray]:
    axes = [dict(scalars(rrd[f"episode_{e}/objects/{prefix}pot_{a}"])) for a in "xyz"]
    return {s: np.array([ax[s] for ax in axes]) for s in axes[0]}


def episode_summary(rrd: dict, e: int) -> dict:
    pot, goal = pot_xyz(rrd, e), pot_xyz(rrd, e, "goal_")
    goal = goal[max(goal)]
    grip = scalars(rrd[f"episode_{e}/info/grip_command"])
    held = dict(scalars(rrd[f"episode_{e}/info/held"]))
    success = any(v > 0 for _, v in scalars(rrd[f"episode_{e}/success"]))
    releases = [
        s
        for (_, prev), (s, now) in zip(grip, grip[1:], strict=False)
        if prev >= 0.5 > now and held.get(s - 1) == HELD_POT
    ]
    last = max(pot)
    delta = pot[last] - goal
    if success:
        outcome = "success"
    elif not any(v == HELD_POT for v in held.values()):
        outcome = "never held"
    elif pot[last][2] < FELL_BELOW_Z:
        outcome = "fell"
    elif delta[2] > ABOVE_GOAL_DZ and np.linalg.norm(delta[:2]) < NEAR_GOAL_XY:
        outcome = "above the goal"
    else:
        outcome = "off target"
    door, tray = (scalars(rrd[f"episode_{e}/objects/{name}"]) for name in ("door", "tray"))
    goal_door, goal_tray = (scalars(rrd[f"episode_{e}/objects/goal_{name}"]) for name in ("door", "tray"))
    return {
        "episode": e,
        "success": success,
        "outcome": outcome,
        "steps": last,
        # the other objects at the end (unload_pot also pushes the tray in, with the door left closed)
        "final_door_error": round(door[-1][1] - goal_door[-1][1], 3),
        "final_tray_error": round(tray[-1][1] - goal_tray[-1][1], 3),
        "pot_error_at_releases": [
            round(float(np.linalg.norm(pot[s] - goal)), 3) for s in releases if s in pot
        ],
        "final_xy_error": round(float(np.linalg.norm(delta[:2])), 3),
        "final_dz": round(float(delta[2]), 3),
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", required=True, help="checkpoint dir (pretrained_model)")
    ap.add_argument(
        "--task",
        default="pot_to_tray",
        choices=["pot_to_tray", "pot_to_table", "move_pot_on_table", "store_pot", "unload_pot"],
    )
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=None, help="writes OUT.json and OUT.md")
    args = ap.parse_args()

    from lerobot_efm.envs.talos_kitchen.tasks import POT_TOL

    rrd = rollouts_rrd(args.policy, args.task, args.episodes, args.seed)
    episodes = [episode_summary(rrd, e) for e in range(args.episodes)]
    counts = dict(Counter(ep["outcome"] for ep in episodes))
    lines = [
        f"# Pot placements: {args.task}, {args.episodes} episodes (seeds {args.seed}-{args.seed + args.episodes - 1})",
        "",
        f"Policy `{args.policy}`; success: pot within {POT_TOL} m of the goal pot (door and tray within theirs).",
        "",
        "| episode | outcome | steps | pot error at each release (m) | final xy error (m) | final dz (m) "
        "| final door error (rad) | final tray error (m) |",
        "|---:|---|---:|---|---:|---:|---:|---:|",
        *(
            f"| {ep['episode']} | {ep['outcome']} | {ep['steps']} | {ep['pot_error_at_releases']} | "
            f"{ep['final_xy_error']} | {ep['final_dz']} | {ep['final_door_error']} | {ep['final_tray_error']} |"
            for ep in episodes
        ),
        "",
        "Outcomes: " + ", ".join(f"{k} {v}" for k, v in counts.items()) + f" (of {len(episodes)}).",
    ]
    print("\n".join(lines))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        args.out.with_suffix(".json").write_text(
            json.dumps(
                {"policy": args.policy, "task": args.task, "counts": counts, "episodes": episodes}, indent=1
            )
        )
        args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
