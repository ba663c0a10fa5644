"""Settings tables (world, reward, network): frozen dataclasses read from and written to plain dicts, as study,
training and summary files hold them."""

from __future__ import annotations

from dataclasses import fields
from typing import Self


class Settings:
    """`from_dict` refuses keys the dataclass does not have, naming them and the known ones; `to_dict` gives every
    field. Subclasses say what their settings are called in messages (`what`)."""

    what = "settings"

    @classmethod
    def from_dict(cls, values: dict) -> Self:
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown {cls.what} setting(s) {unknown}; known settings: {sorted(known)}")
        return cls(**values)

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}
