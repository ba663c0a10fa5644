"""Settings tables (world, reward, network, solver, training): frozen dataclasses read from and written to plain
dicts, as study, training and summary files hold them, the one check of their keys that every reader uses, and
the lengths of time a study or the command line gives in seconds where a dataclass holds steps."""

from __future__ import annotations

import warnings
from collections.abc import Iterable
from dataclasses import fields
from typing import Any, ClassVar, Self


def check_keys(given: Iterable[str], known: Iterable[str], what: str) -> None:
    """Refuse keys that are not ``known``, naming them and the known ones: ``what`` is what a key is called in the
    message ("world setting", "key")."""
    known = set(known)
    unknown = sorted(set(given) - known)
    if unknown:
        raise ValueError(f"unknown {what}(s) {unknown}; known {what}s: {sorted(known)}")


STEPS = "_steps"  # the suffix that gives a length of time in steps: horizon_steps = 10


def durations(cls: type) -> dict[str, float]:
    """The fields of dataclass ``cls`` that are lengths of time, each with its default in seconds (its field's
    ``seconds`` metadata): the dataclass holds them in steps, a study file or the command line gives them in
    seconds, or in steps as NAME_steps."""
    return {f.name: f.metadata["seconds"] for f in fields(cls) if "seconds" in f.metadata}


def field_types(cls: type) -> dict[str, type]:
    """The type each setting of dataclass ``cls`` is given in: its default's type, and for a length of time
    (`durations`) seconds as a float or NAME_steps as a whole number."""
    types = {f.name: type(f.default) for f in fields(cls)}
    for name in durations(cls):
        types |= {name: float, name + STEPS: int}
    return types


FEWEST_STEPS = 5  # a length of time shorter than this many steps shows too little to read (a moment, a window)


class ShortLength(UserWarning):
    """A length of time given in seconds that is fewer than `FEWEST_STEPS` steps in this world."""


def in_steps(cls: type, given: dict[str, Any], step_seconds: float, defaults: bool = False) -> dict[str, Any]:
    """Settings of dataclass ``cls`` as given (`field_types`) with each length of time in steps under its field's
    name: seconds divided by the world's ``step_seconds`` and rounded, NAME_steps as they are; with ``defaults``,
    each length not given too, from its default in seconds but never fewer than `FEWEST_STEPS` steps (a default
    is a decision for every world: 2.5 s is 10 steps of the crowd's, 2 of a world of 1-s steps). A length given in
    seconds that is fewer than `FEWEST_STEPS` steps warns (`ShortLength`), naming the setting; NAME_steps is
    taken as it is. The other settings pass through."""
    settings = dict(given)
    for name, default in durations(cls).items():
        steps_name = name + STEPS
        if name in settings and steps_name in settings:
            raise ValueError(f"give {name} in seconds or {steps_name} in steps, not both")
        if steps_name in settings:
            settings[name] = settings.pop(steps_name)
        elif name in settings:
            seconds = settings[name]
            settings[name] = round(seconds / step_seconds)
            if settings[name] < 1:
                raise ValueError(
                    f"{name} = {seconds} s is less than one step of {step_seconds:g} s in this world: give more "
                    f"seconds, or {steps_name} in steps"
                )
            if settings[name] < FEWEST_STEPS:
                warnings.warn(
                    f"{name} = {seconds} s is only {settings[name]} step{'s' if settings[name] > 1 else ''} of "
                    f"{step_seconds:g} s in this world, too few to show much: give more seconds, or {steps_name} = "
                    f"{settings[name]} to keep it",
                    ShortLength,
                    stacklevel=2,
                )
        elif defaults:
            settings[name] = max(round(default / step_seconds), FEWEST_STEPS)
    return settings


def check_values(cls: type, values: dict[str, Any], what: str) -> dict[str, Any]:
    """Settings for dataclass ``cls`` given as typed values (a study file's table), each checked against its
    field's type (`field_types`); a whole number is taken where a float is expected, as ``foil search --set
    key=10`` takes it."""
    types = field_types(cls)
    check_keys(values, types, f"{what} setting")
    settings = {}
    for key, value in values.items():
        kind = types[key]
        if kind is float and type(value) is int:
            value = float(value)
        if type(value) is not kind:
            raise ValueError(f"bad {what} setting {key} = {value!r}: {key} takes a {kind.__name__}")
        settings[key] = value
    return settings


class ConfigTable:
    """A dataclass of settings: `from_dict` refuses keys it does not have, naming them and the known ones; `to_dict`
    gives every field. Subclasses say what their settings are called in messages (`what`)."""

    what: ClassVar[str] = "settings"

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> Self:
        check_keys(values, (f.name for f in fields(cls)), f"{cls.what} setting")  # type: ignore[arg-type]
        return cls(**values)

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in fields(self)}  # type: ignore[arg-type]
