#!/usr/bin/env bash
# Training steps/s of FM-AC use-RL with the paper's Euler-20 bootstrap queries vs Heun (results/rl_bootstrap_solver_speed.md).
# Run from the repository root; about 5 min on one core.
set -ef  # -f: no globbing of the [..] list values
mkdir -p "${OUT:-outputs/bench_heun}"
B=".venv/bin/python benchmarks/bench_agents.py --configs state --agents efm_ac --threads 1 --skip-latency --repeats 3 --train-steps 30"
CPU="--set mlp_hidden_dims=[256,256,256] --set unet_down_dims=[32,64,128]"
$B --rl both --set rl_actor_slack=0.2 --out ${OUT:-outputs/bench_heun}/paper_euler.md
$B --rl use --set rl_actor_slack=0.2 --set rl_target_solver=heun --set rl_target_inference_steps=5 --out ${OUT:-outputs/bench_heun}/paper_heun5.md
$B --rl use --set rl_actor_slack=0.2 --set rl_target_solver=heun --set rl_target_inference_steps=3 --out ${OUT:-outputs/bench_heun}/paper_heun3.md
$B --rl both --set rl_actor_slack=0.2 $CPU --out ${OUT:-outputs/bench_heun}/cpu_euler.md
$B --rl use --set rl_actor_slack=0.2 --set rl_target_solver=heun --set rl_target_inference_steps=5 $CPU --out ${OUT:-outputs/bench_heun}/cpu_heun5.md
