"""The scripted operators of ``lerobot-efm-record`` as draccus choices: ``--operator.type=planar_push_full
--operator.noise=0.003 --operator.wall_slides=0``, as LeRobot selects ``--policy.type`` / ``--env.type``.

Each registered operator class (:data:`lerobot_efm.recording.OPERATORS`) becomes a config dataclass whose fields are
its scalar keyword arguments (bool, int, float, str, optionally None) with the class's own defaults, so the options
have one source of truth: the operator's signature. An operator whose simulator extra is not installed is not
registered (its name is then refused with the list of those that are).
"""

from __future__ import annotations

import dataclasses
import inspect
import types
import typing
from dataclasses import dataclass
from typing import ClassVar

import draccus

from .recording import OPERATORS, operator_class

SCALARS = (bool, int, float, str)


@dataclass
class OperatorConfig(draccus.ChoiceRegistry):
    """A scripted operator and its keyword options."""

    env_type: ClassVar[str] = ""
    name: ClassVar[str] = ""  # its name among the env's operators (lerobot_efm.recording.OPERATORS)

    @property
    def type(self) -> str:
        return self.get_choice_name(self.__class__)

    def options(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    def build(self, env, rng):
        return operator_class(self.env_type, self.name)(env, rng, **self.options())


def choice_name(env_type: str, name: str) -> str:
    return f"{env_type.removeprefix('efm_')}_{name}"


def default_operator(env_type: str) -> OperatorConfig:
    """The env's play operator (``--operator.type`` not given)."""
    name = {"planar_push": "full"}.get(env_type, "play")
    return OperatorConfig.get_choice_class(choice_name(env_type, name))()


def _scalar(annotation) -> bool:
    if annotation in SCALARS:
        return True
    args = typing.get_args(annotation)
    is_union = typing.get_origin(annotation) in (typing.Union, types.UnionType)
    return is_union and all(a in SCALARS or a is type(None) for a in args)


def _options_of(cls) -> list[tuple[str, object, dataclasses.Field]]:
    """(name, type, field) of the scalar keyword arguments of ``cls.__init__`` and its bases."""
    options = {}
    for klass in reversed(cls.__mro__[:-1]):
        if "__init__" not in vars(klass):
            continue
        for name, p in inspect.signature(klass.__init__, eval_str=True).parameters.items():
            if name in ("self", "env", "rng") or p.default is p.empty or not _scalar(p.annotation):
                continue
            options[name] = (name, p.annotation, dataclasses.field(default=p.default))
    return list(options.values())


def register_operators() -> list[str]:
    """Register every operator whose module imports; returns the registered choice names."""
    names = []
    for env_type, name in OPERATORS:
        choice = choice_name(env_type, name)
        if choice in OperatorConfig.get_known_choices():
            names.append(choice)
            continue
        try:
            cls = operator_class(env_type, name)
        except ImportError:  # its simulator's extra is not installed
            continue
        config = dataclasses.make_dataclass(
            f"{cls.__name__}Config", _options_of(cls), bases=(OperatorConfig,)
        )
        config.env_type, config.name, config.__doc__ = env_type, name, cls.__doc__
        OperatorConfig.register_subclass(choice)(config)
        names.append(choice)
    return names
