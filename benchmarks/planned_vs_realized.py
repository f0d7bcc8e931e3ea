"""Does the plan an FM-PC / FM-PS / FM-AS agent picks come true? Planar push, one rollout per pair.

The planner-based agents act on a planned observation trajectory tau^o (FM-PC, FM-PS: Planner; FM-AS: World
model over the chosen action chunk). FM-PS and FM-AS pick, among ``num_candidates`` samples, the one whose last
observation the critic finds nearest the goal. If the planner has not learnt that the disc only moves when the
hand pushes it, the candidate that teleports the disc towards the goal wins the critic's argmin, and no action
realises it. This measures, at every replan ``t``, the disc displacement that the chosen plan predicts over its
horizon ``(L_o - 1) * S_o`` frames against the one the rollout then realises, and (with candidates) how far
the candidates move the disc while the hand is not touching it.

    python benchmarks/planned_vs_realized.py ps=outputs/.../checkpoints/012000/pretrained_model \\
        --pairs 0 2 4 6 8 --steps 300 --out benchmarks/results/planned_vs_realized.md
"""

from __future__ import annotations

import argparse
import os
import shlex
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import numpy as np
import torch

STATE = "observation.state"  # planar push: eff_x, eff_y, obj_x, obj_y
CONTACT = 0.2 + 0.075 + 0.02  # disc radius + effector radius + slack: closer than this the hand can push


def load(checkpoint: str):
    """Policy config, policy and its processors, loaded once per checkpoint."""
    from lerobot.configs.policies import PreTrainedConfig
    from lerobot.policies import make_policy, make_pre_post_processors

    import lerobot_efm  # noqa: F401  (registers the policies and the env)
    from lerobot_efm.envs.planar_push.env import PlanarPushEnvConfig

    cfg = PreTrainedConfig.from_pretrained(checkpoint)
    cfg.pretrained_path, cfg.device = checkpoint, "cpu"
    policy = make_policy(cfg=cfg, env_cfg=PlanarPushEnvConfig()).eval()
    pre, post = make_pre_post_processors(policy_cfg=cfg, pretrained_path=checkpoint)
    return cfg, policy, pre, post


def rollout(loaded, pair: int, steps: int, seed: int) -> dict[str, np.ndarray]:
    """One episode; returns the realized states and, per replan step, the chosen (and candidate) plans."""
    from lerobot.envs.factory import make_env, make_env_pre_post_processors
    from lerobot.envs.utils import preprocess_observation

    from lerobot_efm.envs.planar_push.env import PlanarPushEnvConfig
    from lerobot_efm.viz.unnormalize import latent_to_states

    cfg, policy, pre, post = loaded
    env_cfg = PlanarPushEnvConfig(task=f"pair{pair}")
    envs = make_env(env_cfg, n_envs=1, use_async_envs=False)
    env = next(iter(next(iter(envs.values())).values()))
    env_pre, env_post = make_env_pre_post_processors(env_cfg=env_cfg, policy_cfg=cfg)

    def states_of(latent):
        out = latent_to_states(policy, pre, latent)
        if out is None:
            raise ValueError(
                f"{cfg.pretrained_path}: planned latents are not states (needs an identity state encoder)"
            )
        return out[STATE][0]

    observation, _ = env.reset(seed=[seed])
    policy.reset()
    realized, replans, chosen, candidates = [], [], [], []
    for t in range(steps):
        obs = env_pre(preprocess_observation(observation))
        obs["task"] = [""]
        realized.append(obs[STATE][0].numpy().copy())
        before = policy.last_prediction
        with torch.inference_mode():
            action = policy.select_action(pre(dict(obs)))
        prediction = policy.last_prediction
        if prediction is not before and "obs_plan" in prediction:
            replans.append(t)
            chosen.append(states_of(prediction["obs_plan"][:1]))
            if "candidate_obs_plans" in prediction:
                candidates.append(states_of(prediction["candidate_obs_plans"][:1]))
        action = env_post({"action": post(action)})["action"].numpy()
        observation, _, terminated, truncated, _ = env.step(action)
        if terminated[0] or truncated[0]:
            break
    env.close()
    return {
        "realized": np.array(realized),
        "replans": np.array(replans, dtype=int),
        "chosen": np.array(chosen),
        "candidates": np.array(candidates) if candidates else None,
        "horizon": (cfg.obs_traj_len - 1) * cfg.obs_traj_stride,
    }


def summarize(run: dict[str, np.ndarray]) -> dict[str, float]:
    realized, horizon = run["realized"], run["horizon"]
    keep = [i for i, t in enumerate(run["replans"]) if t + horizon < len(realized)]
    if not keep:
        raise ValueError(f"no replan with {horizon} realized frames after it: raise --steps")
    t = run["replans"][keep]
    now, later = realized[t], realized[t + horizon]
    plan_end = run["chosen"][keep, -1]
    free = np.linalg.norm(now[:, :2] - now[:, 2:], axis=-1) > CONTACT  # hand away from the disc
    planned_move = np.linalg.norm(plan_end[:, 2:] - now[:, 2:], axis=-1)
    realized_move = np.linalg.norm(later[:, 2:] - now[:, 2:], axis=-1)
    row = {
        "replans": len(t),
        "planned disc move": float(np.median(planned_move)),
        "realized disc move": float(np.median(realized_move)),
        "disc error at plan end": float(np.median(np.linalg.norm(plan_end[:, 2:] - later[:, 2:], axis=-1))),
        "hand error at plan end": float(np.median(np.linalg.norm(plan_end[:, :2] - later[:, :2], axis=-1))),
        "hand away from disc": float(free.mean()),
        "planned disc move, hand away": float(np.median(planned_move[free])) if free.any() else float("nan"),
    }
    if run["candidates"] is not None:
        cand = run["candidates"][keep]  # (R, N, L_o, 4)
        moves = np.linalg.norm(cand[:, :, -1, 2:] - now[:, None, 2:], axis=-1)
        row["candidates' disc move, hand away"] = (
            float(np.median(moves[free])) if free.any() else float("nan")
        )
    return row


def recorded_states(root: Path) -> tuple[np.ndarray, np.ndarray]:
    """``observation.state`` and ``episode_index`` of every frame of a LeRobot v3 recording."""
    import pyarrow.parquet as pq

    files = sorted((root / "data").glob("*/*.parquet"))
    if not files:
        raise SystemExit(f"--dataset {root}: no data/*/*.parquet (not a LeRobot v3 dataset)")
    tables = [pq.read_table(f, columns=[STATE, "episode_index"]) for f in files]
    states = np.concatenate([np.stack(t.column(STATE).to_numpy(zero_copy_only=False)) for t in tables])
    return states.astype(np.float32), np.concatenate([t.column("episode_index").to_numpy() for t in tables])


def data_reference(root: Path, horizon: int) -> dict[str, float]:
    """The same statistics on the recording itself: how far the disc moves in ``horizon`` frames."""
    states, episode = recorded_states(root)
    start = np.flatnonzero(episode[:-horizon] == episode[horizon:])  # both frames in one episode
    now, later = states[start], states[start + horizon]
    free = np.linalg.norm(now[:, :2] - now[:, 2:], axis=-1) > CONTACT
    move = np.linalg.norm(later[:, 2:] - now[:, 2:], axis=-1)
    return {
        "replans": len(start),
        "realized disc move": float(np.median(move)),
        "hand away from disc": float(free.mean()),
        "planned disc move, hand away": float(np.median(move[free])),
        "planner on recorded states: disc move, hand away": float(np.median(move[free])),
    }


def planner_on_recording(loaded, root: Path, n: int, seed: int) -> float | None:
    """FM-PS's goal-free Planner sampled on ``n`` recorded states with the hand away from the disc: the
    median disc displacement of its plans (the recording's own is ~0: nothing pushes the disc)."""
    from lerobot_efm.viz.unnormalize import latent_to_states, normalize

    cfg, policy, pre, _ = loaded
    if cfg.type != "efm_ps":
        return None
    states, _ = recorded_states(root)
    free = np.flatnonzero(np.linalg.norm(states[:, :2] - states[:, 2:], axis=-1) > CONTACT)
    pick = states[np.random.default_rng(seed).choice(free, n, replace=False)]
    obs = {STATE: normalize(pre, STATE, torch.from_numpy(pick))}
    torch.manual_seed(seed)
    with torch.no_grad():
        agent = policy.ema_model
        l_obs = agent.encoder(obs)
        plans = agent.plan_from(agent.planner.sample(l_obs, cfg.num_inference_steps), l_obs)
    planned = latent_to_states(policy, pre, plans)[STATE]
    return float(np.median(np.linalg.norm(planned[:, -1, 2:] - pick[:, 2:], axis=-1)))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("checkpoints", nargs="+", help="LABEL=CHECKPOINT (a pretrained_model folder)")
    ap.add_argument("--pairs", type=int, nargs="+", default=[0, 2, 4, 6, 8])
    ap.add_argument("--steps", type=int, default=300, help="control steps per rollout")
    ap.add_argument("--seed", type=int, default=1000)
    ap.add_argument("--dataset", type=Path, default=None, help="a recording: add its own disc moves as a row")
    ap.add_argument("--horizon", type=int, default=20, help="frames of the --dataset row ((L_o - 1) * S_o)")
    ap.add_argument("--out", type=Path, default=None, help="markdown table (printed either way)")
    args = ap.parse_args(argv)
    torch.set_num_threads(1)
    rows = {}
    for spec in args.checkpoints:
        label, sep, checkpoint = spec.partition("=")
        if not sep or not Path(checkpoint).is_dir():
            raise SystemExit(f"{spec!r}: expected LABEL=CHECKPOINT with an existing pretrained_model folder")
        loaded = load(checkpoint)
        runs = [rollout(loaded, p, args.steps, args.seed) for p in args.pairs]
        per_pair = [summarize(r) for r in runs]
        rows[label] = {k: float(np.nanmean([r[k] for r in per_pair])) for k in per_pair[0]}
        rows[label]["replans"] = sum(r["replans"] for r in per_pair)
        if args.dataset is not None:
            on_data = planner_on_recording(loaded, args.dataset, 500, args.seed)
            if on_data is not None:
                rows[label]["planner on recorded states: disc move, hand away"] = on_data
    if args.dataset is not None:  # frames, not replans; its 'planned' move is the recorded one
        rows[f"recording {args.dataset.name} (every frame)"] = data_reference(args.dataset, args.horizon)
    keys = list(dict.fromkeys(k for r in rows.values() for k in r))
    lines = [
        f"Pairs {args.pairs}, {args.steps} steps each, seed {args.seed}; disc/hand moves and errors in maze units "
        "(median per pair, mean over pairs); 'hand away' = hand farther than "
        f"{CONTACT:.3f} from the disc centre at the replan.",
        "",
        "| checkpoint | " + " | ".join(keys) + " |",
        "|---|" + "---:|" * len(keys),
    ]
    for label, row in rows.items():
        cells = [
            "–" if k not in row else str(int(row[k])) if k == "replans" else f"{row[k]:.3f}" for k in keys
        ]
        lines.append(f"| {label} | " + " | ".join(cells) + " |")
    text = "\n".join(lines)
    print(text)
    if args.out:
        args.out.write_text(
            f"# Planned vs realized disc motion (planar push)\n\nCommand: `python {shlex.join(sys.argv)}`\n\n{text}\n"
        )
    return 0


if __name__ == "__main__":
    sys.exit(main())
