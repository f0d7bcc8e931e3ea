"""bench_agents.py's --set: config overrides reach every measured policy (e.g. the bootstrap's ODE solver)."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_agents  # noqa: E402


def test_set_overrides_reach_the_policy_config(tmp_path):
    out = tmp_path / "bench.md"
    bench_agents.main(
        [
            "--configs",
            "state",
            "--agents",
            "efm_ac",
            "--rl",
            "use",
            "--train-steps",
            "1",
            "--repeats",
            "1",
            "--batch",
            "8",
            "--skip-latency",
            "--set",
            "rl_target_solver=heun",
            "--set",
            "rl_target_inference_steps=3",
            "--set",
            "rl_actor_slack=0.2",
            "--out",
            str(out),
        ]  # fmt: skip
    )
    variant = json.loads(out.with_suffix(".json").read_text())["configs"]["state"]["variants"][0]
    assert variant["config_overrides"] == {
        "rl_target_solver": "heun",
        "rl_target_inference_steps": 3,
        "rl_actor_slack": 0.2,
    }
    assert variant["train"]["steps_per_s"] > 0
    assert "rl_target_solver=heun" in out.read_text()


def test_set_rejects_a_malformed_override():
    with pytest.raises(SystemExit, match="NAME=VALUE"):
        bench_agents.parse_overrides(["rl_target_solver"])
    assert bench_agents.parse_overrides(["a=null", "b=0.5", "c=heun"]) == {"a": None, "b": 0.5, "c": "heun"}
