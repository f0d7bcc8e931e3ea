"""eval_more_episodes.py's --variant: each checkpoint is evaluated once as trained and once per variant, the
variant's overrides reaching lerobot-eval's command line (an inference-time setting needs no retraining)."""

import json
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import eval_more_episodes  # noqa: E402

# A stand-in lerobot-eval: records its arguments and writes an eval_info.json whose success depends on them.
FAKE_EVAL = """#!{python}
import json, pathlib, sys
args = sys.argv[1:]
out = pathlib.Path(next(a.split("=", 1)[1] for a in args if a.startswith("--output_dir=")))
out.mkdir(parents=True, exist_ok=True)
(out / "argv.json").write_text(json.dumps(args))
ok = "--policy.critic_inference_solver=heun" in args
n = 10
metrics = {{"successes": [ok] * n, "sum_rewards": [0.5] * n}}
info = {{"overall": {{"pc_success": 100.0 * ok, "n_episodes": n}}, "per_task": [{{"metrics": metrics}}]}}
(out / "eval_info.json").write_text(json.dumps(info))
"""


def test_variants_reach_lerobot_eval_and_get_their_own_rows(tmp_path, monkeypatch):
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    fake = bin_dir / "lerobot-eval"
    fake.write_text(FAKE_EVAL.format(python=sys.executable))
    fake.chmod(0o755)
    monkeypatch.setattr(eval_more_episodes, "BIN", bin_dir)
    out = tmp_path / "report.md"
    heun = "--policy.critic_inference_solver=heun --policy.critic_inference_steps=5"
    eval_more_episodes.main(
        ["ac=ckpt", "--episodes", "10", "--work-dir", str(tmp_path / "w"), "--variant", f"heun5={heun}"]
        + ["--out", str(out)]
    )
    plain = json.loads((tmp_path / "w" / "ac" / "argv.json").read_text())
    varied = json.loads((tmp_path / "w" / "ac-heun5" / "argv.json").read_text())
    assert not any(a.startswith("--policy.critic_inference") for a in plain)
    assert varied[-2:] == heun.split() and varied[:-2] == [
        a.replace("/ac", "/ac-heun5") if a.startswith("--output_dir") else a for a in plain
    ]
    report = out.read_text()
    assert "| ac | as trained | 10 | 0.0 | 50 |" in report and "| ac | heun5 | 10 | 100.0 | 50 |" in report
    with pytest.raises(SystemExit, match="--variant expects"):
        eval_more_episodes.parse_variant("heun5=critic_inference_solver=heun")
