"""The simulators are optional: ``pip install lerobot_policy_efm`` brings the policies, the extras their worlds.

``[planar]`` (MuJoCo: planar push), ``[talos]`` (MuJoCo + the Talos meshes of example-robot-data: the kitchen),
``[ogbench]`` (OGBench: pointmaze, with MuJoCo and dm_control), ``[all]`` every one. Modules that need one import
it through :func:`require`, so a missing extra is named in the error instead of a bare ``ModuleNotFoundError``.
"""

from __future__ import annotations

import importlib
import importlib.metadata
from types import ModuleType

PACKAGE = "lerobot_policy_efm"


def install_hint(extra: str) -> str:
    return f"pip install '{PACKAGE}[{extra}]'"


def require(module: str, extra: str, needed_by: str) -> ModuleType:
    """``import module``, or an ImportError that names the extra providing it."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        raise ImportError(
            f"{needed_by} needs the Python package '{module}', which comes with the [{extra}] extra: "
            f"{install_hint(extra)}"
        ) from err


def require_distribution(name: str, extra: str, needed_by: str) -> importlib.metadata.Distribution:
    """An installed distribution (data files, e.g. robot meshes), or an ImportError that names the extra."""
    try:
        return importlib.metadata.distribution(name)
    except importlib.metadata.PackageNotFoundError as err:
        raise ImportError(
            f"{needed_by} needs the '{name}' distribution, which comes with the [{extra}] extra: "
            f"{install_hint(extra)}"
        ) from err
