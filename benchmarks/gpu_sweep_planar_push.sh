#!/usr/bin/env bash
# The partitioned planar-push stitching sweep (FM-AC no-RL and use-RL x seeds, paper-size networks) fitted into a
# fixed wall-clock budget on one GPU machine. It first measures the steps/s of the concurrent trainings (each
# process's data loading is CPU work, so the rate depends on how many share the cores), then trains every cell for
# the same number of steps that still leaves time for its two evaluations (50 episodes each), through
# benchmarks/paper_experiments.py (lerobot-train / lerobot-eval) as on the CPU.
#
#   DEADLINE_S=560 OUT=outputs/gpu_sweep bash benchmarks/gpu_sweep_planar_push.sh
#
# A machine without the dependencies installs the wheels in .whl/ first (no network needed). Results: the cells'
# result.json / eval_info.json / logs under $WORK, packed into $OUT/results.tgz (checkpoints are left behind).
set -uo pipefail
START=$(date +%s)
elapsed() { echo $(($(date +%s) - START)); }
PY=${PY:-python3}
DEVICE=${DEVICE:-cuda}
DEADLINE_S=${DEADLINE_S:-560}       # everything (evaluations included) ends by then
EVAL_RESERVE_S=${EVAL_RESERVE_S:-150} # two lerobot-eval runs per cell after its training
CAL_STEPS=${CAL_STEPS:-400}
STARTUP_S=${STARTUP_S:-70}           # lerobot-train start to its first batch (H200 machine: ~60 s)
STEP_UNIT=${STEP_UNIT:-2000}          # the cells' steps: a multiple of this
EVAL_EPISODES=${EVAL_EPISODES:-50}
SEEDS=${SEEDS:-1000 2000 3000}
WORKERS=${WORKERS:-2}                 # DataLoader workers per training: the hindsight batch is ~25 ms of CPU
SLACK=${SLACK:-0.2}                   # use-RL cells: rl_actor_slack (the best CPU setting)
OUT=${OUT:-outputs/gpu_sweep}
WORK=${WORK:-outputs/gpu_sweep_runs}
DATA=${DATA:-outputs/paper_experiments/data}
CONFIG=planar_push_efm_cpu_paper_nets.json
export MUJOCO_GL=egl HF_HUB_OFFLINE=1 OMP_NUM_THREADS=1 PYTHONUNBUFFERED=1
mkdir -p "$OUT" "$WORK"

if [ -d .whl ] && ls .whl/*.whl >/dev/null 2>&1; then
  # into the interpreter's own environment; where that is read-only, into a venv that sees its packages
  if ! "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir .whl/*.whl; then
    "$PY" -m venv --system-site-packages /tmp/efm-venv && PY=/tmp/efm-venv/bin/python &&
      "$PY" -m pip install -q --no-index --no-deps --no-compile --no-cache-dir .whl/*.whl || exit 1
  fi
fi
"$PY" -c "import lerobot.scripts.lerobot_train, lerobot.scripts.lerobot_eval, lerobot_policy_efm, mujoco" || exit 1
BIN=$("$PY" -c "import sys, pathlib; print(pathlib.Path(sys.executable).parent)")
command -v nvidia-smi >/dev/null && nvidia-smi --query-gpu=name,memory.total,driver_version --format=csv,noheader
echo "[$(elapsed)s] installed; $(nproc --all) cores"

# 1. steps/s of the real load: one training per cell, side by side (RL rows on from the first step)
CAL=$WORK/calibration
rm -rf "$CAL"; mkdir -p "$CAL"
cal_pids=()
for seed in $SEEDS; do
  for variant in ac ac_rl; do
    rl=false; [ $variant = ac_rl ] && rl=true
    "$BIN/lerobot-train" --config_path=train_configs/$CONFIG --policy.type=efm_ac --policy.use_rl=$rl \
      --policy.rl_warmup_steps=0 --policy.rl_ramp_steps=0 --dataset.repo_id=local/planar_push_partitioned \
      --dataset.root=$DATA/planar_push/partitioned --output_dir=$CAL/$variant-$seed --policy.device=$DEVICE \
      --steps=$CAL_STEPS --save_freq=$CAL_STEPS --log_freq=100 --batch_size=128 --num_workers=$WORKERS \
      --seed=$seed >"$CAL/$variant-$seed.log" 2>&1 &
    cal_pids+=($!)
  done
done
for p in "${cal_pids[@]}"; do wait "$p" || { echo "calibration training failed:"; tail -c 3000 "$CAL"/*.log; exit 1; }; done
TRAIN_S=$((DEADLINE_S - EVAL_RESERVE_S - $(elapsed) - STARTUP_S))
STEPS=$("$PY" - "$CAL" "$TRAIN_S" "$STEP_UNIT" <<'EOF'
import re, sys, pathlib
rates = {}
for log in sorted(pathlib.Path(sys.argv[1]).glob("*.log")):
    # steady state: the last logged interval's update + data seconds (tqdm's closing rate averages in the
    # start-up, a minute before the first batch with DataLoader workers on the H200 machine)
    logged = re.findall(r"updt_s:([0-9.]+) data_s:([0-9.]+)", log.read_text(errors="replace"))
    if logged:  # (not the evaluation's log)
        rates[log.stem] = round(1 / (float(logged[-1][0]) + float(logged[-1][1])), 2)
print("steps/s per calibration run:", rates, file=sys.stderr)
unit = int(sys.argv[3])
print(max(unit, int(min(rates.values()) * int(sys.argv[2]) / unit) * unit))
EOF
) || exit 1
echo "[$(elapsed)s] calibrated: $STEPS steps per cell in ~${TRAIN_S}s"

# 2. a two-episode lerobot-eval of a calibration checkpoint, beside the trainings: a broken evaluation stops all
"$BIN/lerobot-eval" --policy.path=$CAL/ac_rl-${SEEDS%% *}/checkpoints/last/pretrained_model --env.type=planar_push \
  --env.task=all --env.reward=progress --eval.n_episodes=2 --eval.batch_size=2 --eval.use_async_envs=false \
  --policy.device=$DEVICE --seed=1000 --output_dir=$CAL/eval_smoke >"$CAL/eval_smoke.log" 2>&1 &
smoke=$!

# 3. the cells: same steps for all, two checkpoints each evaluated on 50 episodes
left=$((DEADLINE_S - $(elapsed)))
run_pids=()
for seed in $SEEDS; do
  for variant in ac ac_rl; do
    extra=(--train-arg=--num_workers=$WORKERS)
    [ $variant = ac_rl ] && extra+=(--train-arg=--policy.rl_actor_slack=$SLACK)
    timeout $left "$PY" benchmarks/paper_experiments.py --suite planar_push --config $CONFIG --seed $seed \
      --datasets partitioned --variants $variant --device $DEVICE --steps $STEPS --batch-size 128 \
      --eval-episodes $EVAL_EPISODES --eval-batch-size $EVAL_EPISODES --curve-points 2 --work-dir $WORK --data-root $DATA "${extra[@]}" \
      --out $WORK/report-$variant-$seed.md >"$WORK/runner-$variant-$seed.log" 2>&1 &
    run_pids+=($!)
  done
done
if ! wait $smoke; then
  echo "evaluation smoke test failed: stopping the cells"; tail -c 3000 "$CAL/eval_smoke.log"
  kill "${run_pids[@]}" 2>/dev/null; pkill -f lerobot-train
fi
for p in "${run_pids[@]}"; do wait "$p"; done
echo "[$(elapsed)s] cells done"

find "$WORK" \( -name '*.json' -o -name '*.md' -o -name '*.log' -o -name '*.txt' \) -not -path '*/wandb/*' -print0 |
  tar czf "$OUT/results.tgz" --null -T -
"$PY" - "$WORK" <<'EOF'
import json, sys, pathlib
for res in sorted(pathlib.Path(sys.argv[1]).rglob("result.json")):
    r = json.loads(res.read_text())
    curve = " / ".join(f"{p['step']}:{p['pc_success']:.0f}" for p in r["curve"])
    print(f"seed {r['seed']} {r['agent']:<13} {r['steps']} steps {r['steps_per_s']} steps/s  success {curve}")
EOF
