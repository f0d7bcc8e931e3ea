"""The paper-comparison runner (benchmarks/paper_experiments.py): eval parsing, tables, budgets, the fixed
hyper-parameter configs, and a tiny real run (generated OGBench data, lerobot-train, lerobot-eval, resume)."""

import argparse
import concurrent.futures as cf
import importlib.util
import json
import shutil
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
# the runner and the plots import their shared modules as scripts do
sys.path.insert(0, str(REPO / "benchmarks"))
spec = importlib.util.spec_from_file_location(
    "paper_experiments", REPO / "benchmarks" / "paper_experiments.py"
)
pe = importlib.util.module_from_spec(spec)
sys.modules["paper_experiments"] = pe  # dataclasses look their module up there
spec.loader.exec_module(pe)


def eval_info(successes, sum_rewards=None):
    n = len(successes)
    sum_rewards = [0.0] * n if sum_rewards is None else sum_rewards
    return {
        "per_task": [
            {
                "task_group": "ogbench",
                "task_id": 0,
                "metrics": {"successes": successes, "sum_rewards": sum_rewards},
            }
        ],
        "overall": {"pc_success": 100.0 * sum(successes) / n, "n_episodes": n},
    }


def test_parse_eval_info_splits_episodes_by_seed_task():
    # seeds 1000..1009: 1000 % 5 = 0 -> task1, 1001 -> task2, ..., 1005 -> task1 again
    ok = [True, False, True, False, False, True, True, False, False, False]
    out = pe.parse_eval_info(eval_info(ok), num_tasks=5, task_prefix="task", first_task=1)
    assert out["pc_success"] == 40.0 and out["n_episodes"] == 10 and out["n_success"] == 4
    assert {k: v["pc_success"] for k, v in out["per_task"].items()} == {
        "task1": 100.0,
        "task2": 50.0,
        "task3": 50.0,
        "task4": 0.0,
        "task5": 0.0,
    }
    closed = [1.0, 0.2, 0.9, -0.1, 0.0, 1.0, 0.95, 0.3, 0.1, 0.05]  # progress reward sums
    planar = pe.parse_eval_info(eval_info(ok, closed), num_tasks=10, task_prefix="pair", first_task=0, seed=7)
    assert (
        planar["per_task"]["pair7"]["pc_success"] == 100.0
        and planar["per_task"]["pair8"]["pc_success"] == 0.0
    )
    assert planar["mean_sum_reward"] == pytest.approx(0.44)
    assert planar["per_task"]["pair0"]["mean_sum_reward"] == pytest.approx(-0.1)  # seed 1010 -> pair0
    suite = pe.SUITES["planar_push"]
    assert "--env.reward=progress" in suite.env_args and suite.progress_note and suite.reference
    table = pe.progress_table(suite, ["gc"], ["partitioned"], {("gc", "partitioned"): planar})
    assert table.splitlines()[-1] == "| FM-GC | 44 |"


def test_parse_eval_info_rejects_malformed_files():
    with pytest.raises(ValueError, match="pc_success"):
        pe.parse_eval_info({"overall": {}, "per_task": []}, 5, "task", 1)
    with pytest.raises(ValueError, match="1 sum_rewards"):
        pe.parse_eval_info(eval_info([True, False], [0.5]), 5, "task", 1)
    bad = eval_info([True, False])
    bad["overall"]["n_episodes"] = 3
    with pytest.raises(ValueError, match="n_episodes=3"):
        pe.parse_eval_info(bad, 5, "task", 1)


def test_parse_list_and_paper_numbers():
    assert pe.parse_list(["all"], tuple(pe.VARIANTS), "variants") == list(pe.VARIANTS)
    assert pe.parse_list(["as_rl,gc", "ac"], tuple(pe.VARIANTS), "variants") == ["gc", "ac", "as_rl"]
    with pytest.raises(ValueError, match="'fm_gc'"):
        pe.parse_list(["fm_gc"], tuple(pe.VARIANTS), "variants")
    # spot checks against the paper (Fig. 5 and Fig. 7)
    assert pe.SUITES["ogbench"].paper["ac_rl"]["pointmaze-large-navigate-v0"] == "89"
    assert pe.SUITES["ogbench"].paper["as_rl"]["pointmaze-large-stitch-v0"] == "44"
    assert pe.SUITES["planar_push"].paper["pc_rl"]["partitioned"] == "90±3"
    assert pe.SUITES["planar_push"].paper["as"]["expert"] == "34±8"


def test_results_table_sets_ours_next_to_paper():
    suite = pe.SUITES["planar_push"]
    cells = {("gc", "expert"): {"pc_success": 70.0}, ("ac_rl", "expert"): {"error": "boom"}}
    table = pe.results_table(suite, ["gc", "ac_rl"], ["expert", "full"], cells)
    lines = table.splitlines()
    assert lines[0] == "| agent | Expert: ours | paper | Full: ours | paper |"
    assert lines[2] == "| FM-GC | 70 | 96±5 | – | 65±4 |"
    assert lines[3] == "| FM-AC use-RL | failed | 32±8 | – | 89±3 |"


def budget_args(**kw):
    base = dict(
        device="cpu",
        steps=None,
        batch_size=None,
        eval_episodes=None,
        eval_batch_size=10,
        eval_async=False,
        ema_cutoff=None,
        jobs=1,
        train_arg=[],
        eval_arg=[],
        config=None,
        seed=1000,
        curve_points=1,
    )
    return argparse.Namespace(**{**base, **kw})


def test_budgets_state_cpu_defaults_and_check_episodes():
    cpu = pe.resolve_budget(budget_args(), pe.SUITES["ogbench"])
    assert (cpu.steps, cpu.batch_size, cpu.eval_episodes, cpu.num_workers) == (
        pe.CPU_STEPS,
        pe.CPU_BATCH,
        10,
        0,
    )
    assert cpu.ema_cutoff == pe.CPU_STEPS / 10  # shorter than the paper's 5000 at 2000 steps
    gpu = pe.resolve_budget(budget_args(device="cuda"), pe.SUITES["planar_push"])
    assert (gpu.steps, gpu.batch_size, gpu.eval_episodes, gpu.ema_cutoff) == (200_000, 128, 60, None)
    with pytest.raises(ValueError, match="multiple of 10"):
        pe.resolve_budget(budget_args(eval_episodes=15), pe.SUITES["planar_push"])


def test_budget_config_seed_and_curve_name_the_runs():
    suite = pe.SUITES["planar_push"]
    budget = pe.resolve_budget(
        budget_args(steps=12000, batch_size=128, config="planar_push_efm_cpu.json", seed=3, curve_points=4),
        suite,
    )
    assert pe.budget_tag(budget) == "cpu-s12000-b128-planar_push_efm_cpu-seed3-c4"
    assert pe.budget_tag(pe.resolve_budget(budget_args(), suite)) == "cpu-s2000-b64"  # earlier reports' names
    assert [pe.curve_step(budget, k) for k in range(1, 5)] == [3000, 6000, 9000, 12000]
    cmd = pe.train_command(suite, "pc_rl", Path("data"), "local/x", Path("out"), budget)
    assert any(a.endswith("train_configs/planar_push_efm_cpu.json") for a in cmd)
    assert "--seed=3" in cmd and "--save_freq=3000" in cmd and "--policy.type=efm_pc" in cmd
    assert budget.ema_cutoff is None  # 12000 / 10 >= the config's 1000: its own cutoff
    assert not any(a.startswith("--policy.scheduler_decay_steps") for a in cmd)  # the config's 12000
    longer = pe.resolve_budget(budget_args(steps=24000, config="planar_push_efm_cpu.json"), suite)
    longer_cmd = pe.train_command(suite, "ac", Path("data"), "local/x", Path("out"), longer)
    assert "--policy.scheduler_decay_steps=24000" in longer_cmd  # LeRobot would hold lr = 0 after 12000
    with pytest.raises(ValueError, match="no such file"):
        pe.resolve_budget(budget_args(config="nope.json"), suite)
    with pytest.raises(ValueError, match="--curve-points"):
        pe.resolve_budget(budget_args(curve_points=0), suite)


def test_curve_table_lists_each_checkpoint_with_its_minutes():
    suite = pe.SUITES["planar_push"]
    curve = [
        {"step": 6000, "train_min": 15.2, "pc_success": 46.0},
        {"step": 12000, "train_min": 30.4, "pc_success": 64.0},
    ]
    cells = {("ac", "expert"): {"curve": curve, "steps_per_s": 6.75}, ("gc", "expert"): {"curve": curve[-1:]}}
    lines = pe.curve_table(suite, ["gc", "ac"], ["expert"], cells).splitlines()
    assert lines[0] == "| dataset | agent | step 6000 | step 12000 | steps/s |"
    assert lines[2:] == [
        "| Expert | FM-AC no-RL | 46 (15 min) | 64 (30 min) | 6.75 |"
    ]  # single points: no curve


@pytest.mark.parametrize(
    "config, expected",
    [
        (
            "ogbench_pointmaze_efm.json",
            dict(
                obs_traj_len=4,
                obs_traj_stride=16,
                action_traj_len=8,
                action_traj_stride=1,
                max_goal_distance=200,
                action_mode="velocity",
                ema_cutoff=5000,
            ),
        ),
        (
            "planar_push_efm.json",
            dict(
                obs_traj_len=3,
                obs_traj_stride=10,
                action_traj_len=8,
                action_traj_stride=1,
                max_goal_distance=600,
                action_mode="absolute",
                ema_cutoff=1000,
            ),
        ),
    ],
)
def test_configs_hold_the_paper_hyper_parameters(config, expected):
    cfg = json.loads((REPO / "train_configs" / config).read_text())
    policy = cfg["policy"]
    assert {k: policy[k] for k in expected} == expected
    assert (policy["optimizer_lr"], policy["optimizer_weight_decay"], policy["device"]) == (
        1e-4,
        1e-6,
        "cuda",
    )
    assert (cfg["steps"], cfg["batch_size"]) == (200_000, 128)


TINY_TRAIN = [
    "--policy.mlp_hidden_dims=[32,32]",
    "--policy.unet_down_dims=[8,16,16]",
    "--policy.unet_n_groups=4",
    "--policy.num_inference_steps=3",
]


def test_progress_bar_seconds_of_first_and_resumed_segments(tmp_path):
    log = tmp_path / "train.log"
    log.write_text(
        "Training: 0/90 [00:00<?, ?step/s]\rTraining: 30/90 [01:00<02:00]\rTraining: 60/90 [02:30<01:15]"
    )
    # a run resumed at step 10 of 100: its bar counts 90 steps; at step 40 it had run 30 of them in 60 s
    assert pe.progress_bar_seconds(log, 100, 40) == 60.0
    assert pe.progress_bar_seconds(log, 100, 55) == pytest.approx(60.0 * 45 / 30)  # extrapolated at its rate
    assert pe.clock_seconds("1:48:04") == 6484
    with pytest.raises(RuntimeError, match="no progress bar up to step 20"):
        pe.progress_bar_seconds(log, 100, 20)


def test_tiny_end_to_end_run_and_resume(tmp_path):
    """2 agents x 1 generated OGBench dataset, 20 training steps, 5 eval episodes (one per task) of 60 steps."""
    out = tmp_path / "report.md"
    argv = [
        "--suite",
        "ogbench",
        "--datasets",
        "pointmaze-large-navigate-v0",
        "--variants",
        "gc",
        "ac_rl",
        "--steps",
        "20",
        "--batch-size",
        "16",
        "--eval-episodes",
        "5",
        "--eval-batch-size",
        "5",
        "--ogbench-episodes",
        "10",
        "--ogbench-episode-steps",
        "101",
        "--jobs",
        "2",
        "--curve-points",
        "2",
        "--work-dir",
        str(tmp_path / "work"),
        "--data-root",
        str(tmp_path / "data"),
        "--out",
        str(out),
        *[f"--train-arg={a}" for a in TINY_TRAIN],
        "--eval-arg=--env.episode_length=60",
    ]
    assert pe.main(argv) == 0

    report = json.loads(out.with_suffix(".json").read_text())
    cells = {c["variant"]: c for c in report["cells"]}
    assert set(cells) == {"gc", "ac_rl"}
    for v, policy_type, rl in (("gc", "efm_gc", "false"), ("ac_rl", "efm_ac", "true")):
        cell = cells[v]
        assert cell["n_episodes"] == 5 and 0.0 <= cell["pc_success"] <= 100.0
        assert sorted(cell["per_task"]) == [f"task{k}" for k in range(1, 6)]
        assert f"--policy.type={policy_type}" in cell["train_command"]
        assert f"--policy.use_rl={rl}" in cell["train_command"]
        assert "--config_path=train_configs/ogbench_pointmaze_efm.json" in cell["train_command"]
        assert "--env.dataset=pointmaze-large-navigate-v0" in cell["eval_command"]
        assert cell["paper"] == pe.SUITES["ogbench"].paper[v]["pointmaze-large-navigate-v0"]
        saved = json.loads(next((tmp_path / "work").glob(f"ogbench/*/*/{v}/result.json")).read_text())
        # the checkpoint really is the trained agent, with the suite's hyper-parameters
        ckpt = json.loads(
            next(
                (tmp_path / "work").glob(
                    f"ogbench/*/*/{v}/train/checkpoints/last/pretrained_model/config.json"
                )
            ).read_text()
        )
        assert (ckpt["type"], ckpt["use_rl"], ckpt["obs_traj_stride"], ckpt["action_mode"]) == (
            policy_type,
            rl == "true",
            16,
            "velocity",
        )
        assert saved["pc_success"] == cell["pc_success"]
        # the report keeps the resolved hyper-parameters: config file plus --train-arg overrides
        assert cell["policy_config"]["type"] == policy_type and cell["policy_config"]["use_rl"] == (
            rl == "true"
        )
        assert cell["policy_config"]["mlp_hidden_dims"] == [32, 32]  # TINY_TRAIN's override
        # the learning curve: the step-10 checkpoint evaluated too, the last point is the cell's result
        assert [p["step"] for p in cell["curve"]] == [10, 20] and cell["curve"][-1]["pc_success"] == cell[
            "pc_success"
        ]
        assert 0 < cell["curve"][0]["train_min"] < cell["curve"][1]["train_min"] and cell["steps_per_s"] > 0
    md = out.read_text()
    assert "**Budget: 20 training steps at batch 16 on `cpu`**" in md
    assert "| FM-GC | " in md and "| 66 |" in md and "| 89 |" in md  # the paper's numbers next to ours
    assert "--device cuda --steps 200000" in md

    start = time.perf_counter()  # resume: every cell is cached, nothing is trained or evaluated again
    assert pe.main(argv) == 0
    assert time.perf_counter() - start < 5
    assert all(c.get("cached") for c in json.loads(out.with_suffix(".json").read_text())["cells"])
    assert (
        "generated by `python -m lerobot_efm.ogbench.generate --ogbench_dataset=pointmaze-large-navigate-v0"
        in out.read_text()
    )

    # a training killed after its step-10 checkpoint resumes there (not from scratch) and keeps its time
    cell_dir = next((tmp_path / "work").glob("ogbench/*/*/gc"))
    ckpts = cell_dir / "train" / "checkpoints"
    for stale in (cell_dir / "result.json", cell_dir / "train_seconds.txt"):
        stale.unlink()
    shutil.rmtree(ckpts / "000020")
    (ckpts / "last").unlink()
    (ckpts / "last").symlink_to("000010")
    (cell_dir / "train.log").write_text("Training:  50%|#####     | 10/20 [00:07<00:07,  1.43step/s]\n")
    gc_only = [a for a in argv if a != "ac_rl"]
    assert pe.main(gc_only) == 0
    segments = json.loads((cell_dir / "train_segments.json").read_text())
    assert [(s["from_step"], s["to_step"]) for s in segments] == [(0, 10), (10, 20)]
    assert segments[0]["seconds"] == 7.0 and segments[1]["seconds"] > 0
    assert json.loads((ckpts / "last" / "training_state" / "training_step.json").read_text())["step"] == 20
    assert "Resuming data order" in (cell_dir / "train.log").read_text()
    resumed = json.loads((cell_dir / "result.json").read_text())
    assert resumed["train_s"] == pytest.approx(7.0 + segments[1]["seconds"], abs=0.1)
    assert resumed["train_segments"] == segments  # the report says the training was resumed
    assert "- FM-GC on pointmaze-large-navigate-v0: 0-10: 7, 10-20: " in out.read_text()
    assert pe.main(argv) == 0  # the report again holds both cells

    # --cached-only reports the finished cells of a wider selection and runs nothing for the others
    wider = [a if a != "ac_rl" else "ac_rl pc" for a in argv] + ["--cached-only"]
    assert pe.main(wider) == 0
    assert {c["variant"] for c in json.loads(out.with_suffix(".json").read_text())["cells"]} == {
        "gc",
        "ac_rl",
    }
    assert "| FM-PC no-RL | – | 60 |" in out.read_text() and not list(
        (tmp_path / "work").glob("ogbench/*/*/pc")
    )

    # another checkout (no work dir, no datasets) reports those cells from the committed JSON with --import-report
    committed = tmp_path / "committed.json"
    shutil.copy(out.with_suffix(".json"), committed)
    elsewhere = [
        a.replace(str(tmp_path / "work"), str(tmp_path / "fresh_work")).replace(
            str(tmp_path / "data"), str(tmp_path / "fresh_data")
        )
        for a in argv
    ]
    assert pe.main([*elsewhere, "--cached-only", "--import-report", str(committed)]) == 0
    reported = json.loads(out.with_suffix(".json").read_text())
    assert {c["variant"]: c["pc_success"] for c in reported["cells"]} == {
        v: c["pc_success"] for v, c in cells.items()
    }
    assert (
        "generated by `python -m lerobot_efm.ogbench.generate" in out.read_text()
    )  # provenance from the report
    with pytest.raises(ValueError, match="committed.json.*budget"):  # another budget's cells never mix in
        pe.main([*[a if a != "20" else "40" for a in elsewhere], "--import-report", str(committed)])


def test_plot_learning_curves_draws_cells_with_curves(tmp_path):
    spec = importlib.util.spec_from_file_location(
        "plot_learning_curves", REPO / "benchmarks" / "plot_learning_curves.py"
    )
    plot = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(plot)
    curve = [
        {"step": 10, "train_min": 1.0, "pc_success": 20.0},
        {"step": 20, "train_min": 2.0, "pc_success": 40.0},
    ]
    report = tmp_path / "r.json"
    report.write_text(
        json.dumps(
            {
                "budget": {"seed": 3},
                "config": "train_configs/x_cpu.json",
                "cells": [
                    {"agent": "FM-AC no-RL", "dataset": "expert", "curve": curve},
                    {"agent": "FM-GC", "dataset": "full"},
                ],
            }
        )
    )
    cells = plot.load_cells([report])
    assert [(c["agent"], c["seed"], c["config_name"]) for c in cells] == [("FM-AC no-RL", 3, "x_cpu")]
    plot.main([str(report), "--out", str(tmp_path / "c.png")])
    assert (tmp_path / "c.png").read_bytes()[:4] == b"\x89PNG"
    # The same config with a --train-arg override is another setting: its own label, not the raw run's.
    fourier = tmp_path / "f.json"
    payload = json.loads(report.read_text())
    payload["budget"].update(train_args=["--policy.state_encoder=fourier"], steps=24000)
    fourier.write_text(json.dumps(payload))
    both = plot.load_cells([report, fourier])
    assert [c["setting"] for c in both] == ["x_cpu", "x_cpu state_encoder=fourier 24k steps"]
    assert (
        plot.label(both[1], several_settings=True)
        == "FM-AC no-RL (seed 3) [x_cpu state_encoder=fourier 24k steps]"
    )
    plot.main([str(report), str(fourier), "--out", str(tmp_path / "both.png")])
    # --datasets / --variants pick cells out of wide reports; a filter that keeps nothing says which
    both[0]["variant"], both[1]["variant"] = "ac", "pc_rl"
    assert plot.select(both, ["expert"], ["ac"]) == [both[0]] and plot.select(both, None, ["pc_rl"]) == [
        both[1]
    ]
    assert plot.select(both, ["expert"], None) == both == plot.select(both, None, None)
    with pytest.raises(ValueError, match=r"\['full'\] and variants \['ac'\]"):
        plot.select(both, ["full"], ["ac"])
    report.write_text(json.dumps({"cells": [{"agent": "FM-GC", "dataset": "full"}]}))
    with pytest.raises(ValueError, match="--curve-points"):
        plot.load_cells([report])


def test_seed_means_groups_seeds_of_one_setting(tmp_path):
    spec = importlib.util.spec_from_file_location("seed_means", REPO / "benchmarks" / "seed_means.py")
    means = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(means)

    def report(name, seed, success, curve, train_args=()):
        path = tmp_path / name
        cell = {
            "agent": "FM-AC use-RL",
            "dataset": "partitioned",
            "pc_success": success,
            "mean_sum_reward": 0.5,
        }
        cell["curve"] = [{"step": 10, "train_min": 1.0, "pc_success": p} for p in curve]
        budget = {"seed": seed, "steps": 12000, "train_args": list(train_args)}
        path.write_text(json.dumps({"budget": budget, "config": "c.json", "cells": [cell]}))
        return str(path)

    reports = [
        report("a.json", 2000, 30.0, [10.0, 40.0]),
        report("b.json", 1000, 20.0, [20.0]),
        report("c.json", 1000, 60.0, [60.0], ["--policy.rl_actor_slack=0.2"]),
    ]
    rows = means.group_rows(means.load_cells([tmp_path / r for r in reports], require_curve=False))
    assert [(r["setting"], r["seeds"], r["success"], r["peak"]) for r in rows] == [
        ("c 12k steps", [1000, 2000], [20.0, 30.0], [20.0, 40.0]),
        ("c rl_actor_slack=0.2 12k steps", [1000], [60.0], [60.0]),
    ]
    # a run on another recording (recorder options beyond the pinned standard ones) is another setting too
    other = json.loads((tmp_path / reports[1]).read_text())
    recorder = "python -m lerobot_efm.envs.planar_push.demonstrators --operator.type=planar_push_partitioned"
    other["datasets"] = {"partitioned": {"command": f"{recorder} --operator.corner_after=250 --num_frames=9"}}
    (tmp_path / "d.json").write_text(json.dumps(other))
    other["datasets"] = {"partitioned": {"command": f"{recorder} --operator.wall_slides=0 --num_frames=9"}}
    (tmp_path / "e.json").write_text(json.dumps(other))
    settings = [c["setting"] for c in means.load_cells([tmp_path / "d.json", tmp_path / "e.json"], False)]
    assert settings == ["c 12k steps recorded with corner_after=250", "c 12k steps"]

    # a config whose value changed after the older reports: a new cell that ran the new value without a flag
    # (its resolved policy_config) groups with the old cells that set it by flag, not with the old default
    def resolved_run(name, lr, train_args=()):
        payload = json.loads((tmp_path / report(name, 3000, 50.0, [50.0], train_args)).read_text())
        payload["config"] = "train_configs/planar_push_efm_cpu.json"
        payload["cells"][0]["policy_config"] = {"optimizer_lr": lr}
        (tmp_path / name).write_text(json.dumps(payload))
        return tmp_path / name

    runs = [
        resolved_run("new.json", 0.0003),
        resolved_run("old_default.json", 0.0001),
        resolved_run("flagged.json", 0.0003, ["--policy.rl_actor_slack=0.2", "--policy.optimizer_lr=3e-4"]),
    ]
    assert [c["setting"] for c in means.load_cells(runs, False)] == [
        "planar_push_efm_cpu optimizer_lr=3e-4 12k steps",
        "planar_push_efm_cpu 12k steps",
        "planar_push_efm_cpu optimizer_lr=3e-4 rl_actor_slack=0.2 12k steps",
    ]
    # a setting that is not a number (the state encoder) departs from its baseline by spelling
    encoders = []
    for name, encoder in (("fourier.json", "fourier"), ("raw.json", "identity")):
        payload = json.loads(resolved_run(name, 0.0001).read_text())
        payload["config"] = "train_configs/ogbench_pointmaze_efm_cpu.json"
        payload["cells"][0]["policy_config"]["state_encoder"] = encoder
        (tmp_path / name).write_text(json.dumps(payload))
        encoders.append(tmp_path / name)
    assert [c["setting"] for c in means.load_cells(encoders, False)] == [
        "ogbench_pointmaze_efm_cpu state_encoder=fourier 12k steps",
        "ogbench_pointmaze_efm_cpu 12k steps",
    ]
    table = means.main(reports)
    assert "| 20 / 30 | 25.0 ± 7.1 | 20 / 40 | 30.0 ± 14.1 | 50 / 50 | 50.0 ± 0.0 |" in table
    assert "| 60 | 60.0 |" in table
    with pytest.raises(ValueError, match="seed 1000 .* in two reports"):
        means.main([*reports, reports[1]])


def test_two_runners_sharing_a_data_root_generate_it_once(tmp_path, monkeypatch):
    """Two runner processes started side by side (one thread each) on one --data-root: the second waits for the
    first's recording and reuses it, instead of deleting it half-written and recording its own."""
    generations = tmp_path / "generations.txt"

    # a recorder that takes a while, then writes meta/info.json
    def slow_generator(suite, dataset, root, spec):
        script = (
            "import pathlib, sys, time; time.sleep(1.0); r = pathlib.Path(sys.argv[1]);"
            "(r / 'meta').mkdir(parents=True); (r / 'meta' / 'info.json').write_text('{}');"
            "open(sys.argv[2], 'a').write('once\\n')"
        )
        return [sys.executable, "-c", script, str(root), str(generations)]

    monkeypatch.setattr(pe, "generate_command", slow_generator)
    spec = pe.DataSpec(None, None, 100)
    with cf.ThreadPoolExecutor(2) as pool:
        results = list(
            pool.map(lambda _: pe.ensure_dataset("planar_push", "expert", tmp_path / "data", spec), range(2))
        )
    assert generations.read_text() == "once\n"
    assert results[0][0] == results[1][0] and (results[0][0] / "meta" / "info.json").exists()
    assert sorted(r[2] > 0 for r in results) == [True, True]  # both name the generating run and its time


def test_cells_trained_with_an_edited_config_are_refused(tmp_path):
    """A cached cell or a run to resume whose checkpoint holds other values than the config file now does would
    be reported under the new values: the runner names the key and both values instead."""
    config = {"policy": {"type": "efm_ac", "optimizer_lr": 3e-4, "mlp_hidden_dims": [256, 256]}}
    trained = {"type": "efm_pc", "optimizer_lr": 1e-4, "mlp_hidden_dims": [256, 256]}
    cmd = ["lerobot-train", "--policy.type=efm_pc"]
    with pytest.raises(RuntimeError, match=r"optimizer_lr: trained 0.0001, config now 0.0003.*--work-dir"):
        pe.check_config_unchanged(trained, cmd, config, tmp_path)
    # a value the train command sets itself (agent, budget, --train-arg) is the cell's own
    pe.check_config_unchanged(trained, [*cmd, "--policy.optimizer_lr=1e-4"], config, tmp_path)
    pe.check_config_unchanged({**trained, "optimizer_lr": 3e-4}, cmd, config, tmp_path)
