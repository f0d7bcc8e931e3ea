# The two set-up commands of the README: `make demo` (main job) and `make test`.
PY := .venv/bin/python
export HF_HUB_OFFLINE := 1
export MUJOCO_GL := egl

.PHONY: demo test test-fast test-slow bench lint

.venv/.installed: pyproject.toml scripts/setup.sh
	bash scripts/setup.sh

demo: .venv/.installed
	$(PY) -m lerobot_efm.demo

# Everything, the slow tests too (two-process training, the long Talos task plans): what CI runs. Two pytest
# workers with one thread each (two 2-thread jobs on the 2 cores thrash), then, alone, the tests whose loops are
# paced by the wall clock (lerobot-record / lerobot-rollout at a fixed fps: beside another test they drop frames).
test: .venv/.installed lint
	OMP_NUM_THREADS=1 $(PY) -m pytest -q -n 2 --dist loadfile -m "(slow or not slow) and not realtime" --durations=15
	$(PY) -m pytest -q -m realtime --durations=5

# LeRobot's house style (pyproject [tool.ruff]): lint and formatting, checked in CI before the tests.
lint: .venv/.installed
	$(PY) -m ruff check .
	$(PY) -m ruff format --check .

test-fast: .venv/.installed
	$(PY) -m pytest -q

test-slow: .venv/.installed
	$(PY) -m pytest -q -m slow

bench: .venv/.installed
	$(PY) benchmarks/bench_agents.py
