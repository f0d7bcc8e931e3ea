#!/usr/bin/env python
"""Per-seed numbers and their mean ± std for paper-runner cells run with several training seeds.

The issue's stitching claim is a mean over seeds; each seed is its own ``benchmarks/paper_experiments.py`` run
(``--seed N``, one report each). This script groups the cells of those reports by (dataset, agent, setting:
config, ``--train-arg`` overrides, steps) and prints one markdown row per group: the final success of every
seed, its mean ± sample std, the best checkpoint of every seed (the curve's peak) and the goal distance closed.

    .venv/bin/python benchmarks/seed_means.py benchmarks/results/paper_experiments_planar_push_cpu-*.json \
        --datasets partitioned
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from plot_learning_curves import load_cells


def mean_std(values: list[float]) -> str:
    """``'24.0 ± 8.5'``; a single value has no spread (``'24.0'``)."""
    if len(values) == 1:
        return f"{values[0]:.1f}"
    return f"{statistics.mean(values):.1f} ± {statistics.stdev(values):.1f}"


def group_rows(cells: list[dict]) -> list[dict]:
    """One row per (dataset, agent, setting) with its cells sorted by seed; a seed seen twice is an error
    (two reports of the same run would count it twice in the mean)."""
    groups: dict[tuple[str, str, str], dict[int, dict]] = {}
    for cell in cells:
        key = (cell["dataset"], cell["agent"], cell["setting"])
        seeds = groups.setdefault(key, {})
        if cell["seed"] in seeds:
            raise ValueError(f"seed {cell['seed']} of {key} is in two reports; pass each run's report once")
        seeds[cell["seed"]] = cell
    rows = []
    for (dataset, agent, setting), by_seed in sorted(groups.items()):
        ordered = [by_seed[s] for s in sorted(by_seed)]
        rows.append(
            {
                "dataset": dataset,
                "agent": agent,
                "setting": setting,
                "seeds": [c["seed"] for c in ordered],
                "success": [c["pc_success"] for c in ordered],
                "peak": [
                    max([p["pc_success"] for p in c.get("curve") or []] + [c["pc_success"]]) for c in ordered
                ],
                "closed": [100 * c["mean_sum_reward"] for c in ordered],
            }
        )
    return rows


def markdown(rows: list[dict]) -> str:
    def listed(values: list[float]) -> str:
        return " / ".join(f"{v:.0f}" for v in values)

    lines = [
        "| dataset | agent | setting | seeds | success % per seed | mean ± std | best checkpoint per seed | mean "
        "| closed % per seed | mean |",
        "|---|---|---|---|---|---:|---|---:|---|---:|",
    ]
    for r in rows:
        lines.append(
            f"| {r['dataset']} | {r['agent']} | {r['setting']} | {' / '.join(map(str, r['seeds']))} "
            f"| {listed(r['success'])} | {mean_std(r['success'])} | {listed(r['peak'])} | {mean_std(r['peak'])} "
            f"| {listed(r['closed'])} | {mean_std(r['closed'])} |"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> str:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("reports", nargs="+", type=Path, help="JSON reports of benchmarks/paper_experiments.py")
    ap.add_argument("--datasets", nargs="*", default=None, help="keep only these datasets")
    args = ap.parse_args(argv)
    cells = load_cells(args.reports, require_curve=False)
    if args.datasets:
        cells = [c for c in cells if c["dataset"] in args.datasets]
    table = markdown(group_rows(cells))
    print(table)
    return table


if __name__ == "__main__":
    main()
