"""The simulators are extras: a missing one is named in the error, and the package declares what it imports."""

import ast
import importlib.metadata
import re
import sys
import tomllib
from pathlib import Path

import pytest

from lerobot_efm.extras import require_distribution

ROOT = Path(__file__).resolve().parents[1]


def test_a_missing_simulator_names_its_extra(monkeypatch):
    from lerobot_efm.envs.planar_push.env import PlanarPushEnv
    from lerobot_efm.ogbench.env import OGBenchEnv

    monkeypatch.setitem(
        sys.modules, "mujoco", None
    )  # as if not installed: `import mujoco` raises ImportError
    with pytest.raises(
        ImportError, match=r"planar_push environment needs .*'mujoco'.*lerobot_policy_efm\[planar\]"
    ):
        PlanarPushEnv(task="pair0")
    monkeypatch.setitem(sys.modules, "ogbench", None)
    with pytest.raises(ImportError, match=r"lerobot_policy_efm\[ogbench\]"):
        OGBenchEnv("pointmaze-large-navigate-v0", task="task1")
    with pytest.raises(ImportError, match=r"'no-such-meshes' distribution.*lerobot_policy_efm\[talos\]"):
        require_distribution("no-such-meshes", "talos", "the Talos kitchen")


def _imported_top_level_modules() -> set[str]:
    names = set()
    for path in (ROOT / "lerobot_efm").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(alias.name.split(".")[0] for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names.add(node.module.split(".")[0])
            elif (
                isinstance(node, ast.Call)
                and getattr(node.func, "id", None) == "require"
                and isinstance(node.args[0], ast.Constant)
            ):  # extras.require("mujoco", ...)
                names.add(node.args[0].value.split(".")[0])
    return {
        n
        for n in names
        if n not in sys.stdlib_module_names and n not in ("lerobot_efm", "lerobot_policy_efm")
    }


def _requirement_name(spec: str) -> str:
    return re.split(r"[\[<>=!~; ]", spec, maxsplit=1)[0].lower().replace("_", "-")


def test_the_package_declares_what_it_imports_and_nothing_else():
    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    runtime_extras = {k: v for k, v in project["optional-dependencies"].items() if k not in ("test", "bench")}
    declared = {_requirement_name(s) for s in project["dependencies"]}
    declared |= {_requirement_name(s) for specs in runtime_extras.values() for s in specs}
    declared.discard("lerobot-policy-efm")  # [all] = the other extras
    owners = importlib.metadata.packages_distributions()
    needed = set()
    for module in _imported_top_level_modules():
        dists = {d.lower().replace("_", "-") for d in owners.get(module, [])} or {f"{module}-sdk"}  # rerun
        assert dists & declared, (
            f"'import {module}' comes from {sorted(dists)}, declared in no dependency list"
        )
        needed |= dists & declared
    assert declared - needed == {"example-robot-data"}, (
        declared - needed
    )  # meshes: data files, never imported
