"""How far the critic reads the goal to be at the start of a Talos task, against how long the task takes.

FM-AC's actor is conditioned on ``actor_distance_scale`` x Critic(0 | o, g) (eq. 6: the minimum distance). A
critic that reads the goal as farther than the policy's own successful rollouts take asks the actor for a slow
route: the play's slow ones, with pauses and hesitations, which the episode limit then cuts off. This rolls a
policy out (``lerobot-efm-log-rollouts``, the same episodes as ``lerobot-eval`` for a seed), reads the ``.rrd``
back and reports per episode the critic's reading at the first replanning and the steps the episode took.

    MUJOCO_GL=egl python benchmarks/talos_critic_readings.py --policy image=CKPT --policy state=CKPT \\
        --task push_tray --episodes 10 --out benchmarks/results/talos_critic_readings_push_tray
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from statistics import median

from talos_door_releases import rollouts_rrd, scalars


def episode_readings(rrd: dict, e: int) -> dict:
    """Success, length and the critic's readings (steps to the goal) of episode ``e``."""
    critic = scalars(rrd[f"episode_{e}/distance/critic"])
    success = scalars(rrd[f"episode_{e}/success"])  # one row per env step
    return {
        "episode": e,
        "success": any(v > 0 for _, v in success),
        "steps": len(success),
        "critic_at_start": round(critic[0][1], 1),
        "critic_readings": [round(v, 1) for _, v in critic],
    }


def summary(label: str, episodes: list[dict]) -> dict:
    wins = [ep for ep in episodes if ep["success"]]
    return {
        "label": label,
        "successes": len(wins),
        "episodes": len(episodes),
        "median_critic_at_start": round(median(ep["critic_at_start"] for ep in episodes), 1),
        "median_steps_of_successes": median(ep["steps"] for ep in wins) if wins else None,
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--policy", action="append", required=True, help="LABEL=CHECKPOINT_DIR (repeatable)")
    ap.add_argument("--task", default="push_tray")
    ap.add_argument("--episodes", type=int, default=10)
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--out", type=Path, default=None, help="writes OUT.json and OUT.md")
    args = ap.parse_args()

    results = {}
    for spec in args.policy:
        label, _, checkpoint = spec.partition("=")
        rrd = rollouts_rrd(checkpoint, args.task, args.episodes, args.seed)
        results[label] = {
            "checkpoint": checkpoint,
            "episodes": [episode_readings(rrd, e) for e in range(args.episodes)],
        }
    rows = [summary(label, r["episodes"]) for label, r in results.items()]
    lines = [
        f"# Critic readings at the start of {args.task}, {args.episodes} episodes "
        f"(seeds {args.seed}-{args.seed + args.episodes - 1})",
        "",
        "| policy | successes | critic at the start (median, steps) | steps of a success (median) |",
        "|---|---:|---:|---:|",
        *(
            f"| {r['label']} | {r['successes']} / {r['episodes']} | {r['median_critic_at_start']} | "
            f"{r['median_steps_of_successes']} |"
            for r in rows
        ),
        "",
        "Per episode (critic at the start / steps, * = success):",
        "",
        *(
            f"- {label}: "
            + ", ".join(
                f"{ep['critic_at_start']} / {ep['steps']}{'*' if ep['success'] else ''}"
                for ep in r["episodes"]
            )
            for label, r in results.items()
        ),
    ]
    print("\n".join(lines))
    if args.out:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        payload = {"task": args.task, "seed": args.seed, "summary": rows, "policies": results}
        args.out.with_suffix(".json").write_text(json.dumps(payload, indent=1))
        args.out.with_suffix(".md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
