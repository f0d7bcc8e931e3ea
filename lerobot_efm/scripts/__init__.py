"""Command-line scripts of lerobot_efm (recording, goals, rerun rollouts and dataset logging)."""

from __future__ import annotations

import sys
from collections.abc import Callable


def run_cli(entry: Callable, argv: list[str] | None, prog: str):
    """Run a ``parser.wrap()`` entry point as LeRobot's own CLIs do (logging set-up, plugin discovery);
    with ``argv`` it runs in-process on those arguments (LeRobot's parser reads ``sys.argv``) and returns the
    entry point's result. Without ``argv`` (a console script) it returns None: a returned object would be printed."""
    from lerobot.utils.import_utils import register_third_party_plugins
    from lerobot.utils.utils import init_logging

    init_logging()
    register_third_party_plugins()
    if argv is None:
        entry()
        return None
    saved = sys.argv
    sys.argv = [saved[0] if saved else prog, *argv]
    try:
        return entry()
    finally:
        sys.argv = saved


def run_config_cli(config_cls: type, body: Callable, argv: list[str] | None, prog: str):
    """:func:`run_cli` of ``parser.wrap()`` over ``body(cfg)`` with ``cfg: config_cls``: for modules whose
    annotations are postponed strings (``from __future__ import annotations``), which ``parser.wrap`` cannot read."""
    from lerobot.configs import parser

    def entry(cfg):
        return body(cfg)

    entry.__annotations__ = {"cfg": config_cls}
    return run_cli(parser.wrap()(entry), argv, prog)
