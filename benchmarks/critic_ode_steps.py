"""How many ODE steps does the RL bootstrap's critic query need? Error and cost of Critic(eps | g, g') against
the solver (Euler, Heun) and its number of steps, on a trained checkpoint and (g, g') pairs of its recording.

Why: with use-RL every training row adds two integrations of the EMA critic ensemble (eq. 5's bridge
Critic(eps_g | g, g'), eps_g ~ U(0, r_g), and with ``rl_actor_slack`` the filter's Critic(0 | o, g')), each
``num_inference_steps`` (20) passes of the critic MLPs: with the paper's 3x1024 critics that made a use-RL step cost
3.3x a no-RL step on the CPU. The critic's flow is 1-D (U(0, 1) -> d); if it is nearly straight, a few steps give
the same target up to a fraction of a frame; if it is curved, a second-order solver (Heun) may need fewer critic
evaluations than Euler for the same error (``rl_target_solver``, ``rl_target_inference_steps``).

    python benchmarks/critic_ode_steps.py ac_rl=RUN/train/checkpoints/012000/pretrained_model \
        --dataset outputs/paper_experiments/data/planar_push/partitioned --out benchmarks/results/critic_ode_steps.md
"""

from __future__ import annotations

import argparse
import glob
import json
import time
from pathlib import Path

import numpy as np
import torch

REFERENCE_STEPS = 100  # Heun steps of the "exact" integration the others are compared with


def load_states(root: Path) -> np.ndarray:
    import pandas as pd

    files = sorted(glob.glob(str(root / "data" / "*" / "*.parquet")))
    if not files:
        raise FileNotFoundError(f"no parquet data files under {root / 'data'}")
    df = pd.concat([pd.read_parquet(f, columns=["observation.state"]) for f in files])
    return np.stack(df["observation.state"].to_numpy()).astype(np.float32)


def load_agent(checkpoint: Path):
    """The EMA agent (the bootstrap's target network) and the checkpoint's pre-processor, on the CPU."""
    from checkpoint_loading import load_policy

    policy, pre, _ = load_policy(checkpoint)
    return policy.ema_model, pre, policy.config


def measure(
    checkpoint: Path, states: np.ndarray, pairs: int, steps: list[int], batch: int, seed: int
) -> dict:
    from lerobot_efm.configuration_efm import GOAL_PREFIX, OBS_PREFIX

    agent, pre, cfg = load_agent(checkpoint)
    rng = np.random.default_rng(seed)
    g = torch.from_numpy(states[rng.integers(len(states), size=pairs)])
    g2 = torch.from_numpy(states[rng.integers(len(states), size=pairs)])
    normed = pre({"observation.state": g, "observation.goal.state": g2, "task": [""] * pairs})
    with torch.inference_mode():
        cond = torch.cat(agent.encode(normed, (OBS_PREFIX, GOAL_PREFIX)), -1)
        torch.manual_seed(seed)
        eps = torch.rand(cfg.num_critics, pairs) * cfg.rl_goal_ratio  # eq. 5's eps_g, one per member

        def bridge(n: int, e, solver: str = "heun") -> torch.Tensor:
            return agent.critic.query(cond, e, n, solver).amax(0) * cfg.max_goal_distance

        exact = {"bridge": bridge(REFERENCE_STEPS, eps), "minimum": bridge(REFERENCE_STEPS, 0.0)}
        rows = []
        for solver, n in steps:
            row = {"solver": solver, "steps": n, "evaluations": n * (2 if solver == "heun" else 1)}
            for name, e in (("bridge", eps), ("minimum", 0.0)):
                err = bridge(n, e, solver) - exact[name]
                row[f"{name}_mean_error"] = float(err.mean())
                row[f"{name}_mean_abs_error"] = float(err.abs().mean())
                row[f"{name}_p95_abs_error"] = float(err.abs().quantile(0.95))
            part = cond[:batch]
            t0, reps = time.perf_counter(), 20
            for _ in range(reps):
                agent.critic.query(part, eps[:, :batch], n, solver)
            row["ms_per_query"] = (time.perf_counter() - t0) / reps * 1e3
            rows.append(row)
    return {
        "checkpoint": str(checkpoint),
        "mlp_hidden_dims": list(cfg.mlp_hidden_dims),
        "num_critics": cfg.num_critics,
        "rl_goal_ratio": cfg.rl_goal_ratio,
        "mean_bridge_steps": float(exact["bridge"].mean()),
        "mean_minimum_steps": float(exact["minimum"].mean()),
        "rows": rows,
    }


def table(label: str, result: dict, batch: int) -> str:
    lines = [
        f"### {label}: critics {result['num_critics']} x MLP {result['mlp_hidden_dims']}, "
        f"mean bridge {result['mean_bridge_steps']:.0f} steps, mean minimum {result['mean_minimum_steps']:.0f} steps",
        "",
        "| solver | steps | critic evaluations | bridge: mean error, mean / p95 abs error (frames) | "
        f"minimum: mean error, mean / p95 abs error (frames) | ms per query ({batch} rows, 1 thread) |",
        "|---|---:|---:|---|---|---:|",
    ]
    for r in result["rows"]:
        lines.append(
            f"| {r['solver']} | {r['steps']} | {r['evaluations']} | "
            f"{r['bridge_mean_error']:+.2f}, {r['bridge_mean_abs_error']:.2f} / {r['bridge_p95_abs_error']:.2f} | "
            f"{r['minimum_mean_error']:+.2f}, {r['minimum_mean_abs_error']:.2f} / {r['minimum_p95_abs_error']:.2f} "
            f"| {r['ms_per_query']:.1f} |"
        )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("checkpoints", nargs="+", metavar="LABEL=CHECKPOINT")
    ap.add_argument("--dataset", type=Path, required=True, help="recording to draw (g, g') from")
    ap.add_argument("--pairs", type=int, default=1024)
    ap.add_argument("--euler-steps", type=int, nargs="+", default=[5, 10, 20, 40])
    ap.add_argument("--heun-steps", type=int, nargs="+", default=[2, 3, 5, 10])
    ap.add_argument("--batch", type=int, default=128, help="rows per timed query (a training batch)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path)
    args = ap.parse_args()
    torch.set_num_threads(1)
    states = load_states(args.dataset)
    results, sections = {}, []
    for item in args.checkpoints:
        label, _, path = item.partition("=")
        if not path:
            ap.error(f"{item!r}: give LABEL=CHECKPOINT")
        steps = [("euler", n) for n in args.euler_steps] + [("heun", n) for n in args.heun_steps]
        results[label] = measure(Path(path), states, args.pairs, steps, args.batch, args.seed)
        sections.append(table(label, results[label], args.batch))
    report = "\n\n".join(sections)
    print(report)
    if args.out:
        command = "python benchmarks/critic_ode_steps.py " + " ".join(args.checkpoints)
        command += f" --dataset {args.dataset} --pairs {args.pairs}"
        args.out.write_text(
            "# ODE steps of the bootstrap's critic query: error against "
            f"{REFERENCE_STEPS} Heun steps, and cost\n\nGenerated by `{command}`\n\n{report}\n"
        )
        args.out.with_suffix(".json").write_text(json.dumps(results, indent=1) + "\n")


if __name__ == "__main__":
    main()
