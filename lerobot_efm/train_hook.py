"""Hindsight goals under LeRobot's own ``lerobot-train``.

LeRobot 0.6 has no dataset hook: ``lerobot/scripts/lerobot_train.py`` calls the module-level name
``make_train_eval_datasets`` and feeds the result to its sampler and DataLoader. ``lerobot-train`` imports
this plugin (``register_third_party_plugins()``) at the start of ``main()``, before ``train()`` runs, so
re-binding that name there wraps the datasets in :class:`HindsightGoalDataset` for ``efm_*`` policies and
leaves every other policy untouched. The script module is ``lerobot.scripts.lerobot_train`` for the console
script and ``accelerate launch``, and ``__main__`` under ``python -m``; both are patched.

If a LeRobot upgrade renames the function, :func:`install` logs an error, and ``EFMPolicy.forward`` raises
on the first batch because the goal keys are missing (tests/test_train_hook.py checks both paths).
"""

from __future__ import annotations

import functools
import logging
import sys

TRAIN_MODULE = "lerobot.scripts.lerobot_train"
HOOKED_NAME = "make_train_eval_datasets"


def wrap_datasets(cfg, datasets):
    """Wrap (train, eval) datasets when the policy being trained is an EFM policy."""
    from .configuration_efm import EFMConfig
    from .hindsight import HindsightGoalDataset, HindsightSpec

    policy_cfg = getattr(cfg, "policy", None)
    if not isinstance(policy_cfg, EFMConfig):
        return datasets
    train, evaluation = datasets
    if not hasattr(train, "hf_dataset"):
        raise TypeError(
            f"{policy_cfg.type} trains with hindsight goals on a single map-style LeRobotDataset; got {type(train).__name__} "
            "(streaming and multi-dataset training are not supported)."
        )
    spec = HindsightSpec.from_config(policy_cfg)
    return HindsightGoalDataset(train, spec), None if evaluation is None else HindsightGoalDataset(
        evaluation, spec
    )


def _script_modules() -> list:
    modules = [sys.modules.get(TRAIN_MODULE)]
    main = sys.modules.get("__main__")
    if main is not None and getattr(getattr(main, "__spec__", None), "name", None) == TRAIN_MODULE:
        modules.append(main)
    return [m for m in modules if m is not None]


def install() -> bool:
    """Patch every loaded copy of the lerobot-train script; returns whether one was patched."""
    patched = False
    for module in _script_modules():
        original = getattr(module, HOOKED_NAME, None)
        if original is None:
            logging.error(
                "lerobot_efm: %s.%s not found: this lerobot version is not supported by the hindsight-goal hook; "
                "efm_* policies cannot train under lerobot-train.",
                module.__name__,
                HOOKED_NAME,
            )
            continue
        if getattr(original, "_efm_hindsight", False):
            patched = True
            continue

        @functools.wraps(original)
        def hooked(cfg, _original=original):
            return wrap_datasets(cfg, _original(cfg))

        hooked._efm_hindsight = True
        setattr(module, HOOKED_NAME, hooked)
        patched = True
    return patched
