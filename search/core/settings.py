"""Settings tables (world, reward, network, solver, training): frozen dataclasses read from and written to plain
dicts, as study, training and summary files hold them, and the one check of their keys that every reader uses."""

from __future__ import annotations

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


def field_types(cls: type) -> dict[str, type]:
    """The type of each field of dataclass ``cls``, as its default's type."""
    return {f.name: type(f.default) for f in fields(cls)}


def check_values(cls: type, values: dict[str, Any], what: str) -> dict[str, Any]:
    """Settings for dataclass ``cls`` given as typed values (a study file's table), each checked against its
    field's type; a whole number is taken where a float is expected, as ``foil search --set key=10`` takes it."""
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
