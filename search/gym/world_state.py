"""A digest of a Gymnasium environment's whole state, so a summary records the world and not only the agents.

An adapter's ``others`` shows what else a clip and a summary see of the world; an adapter without it has each
summary step record, per agent, the sha256 of that instance's observation and of the environment's state as Foil
copies it (the adapter's ``snapshot_env``). ``foil verify`` then fails on any change of an environment action that
changes the world, even where the agents' own paths stay the same.

The digest is the same in every process and run for the same state: it is taken over a canonical encoding of the
state's values (numbers by their bytes, arrays by dtype, shape and bytes, mappings and sets in sorted order,
objects by their class's name and what ``copy`` would copy of them), never of memory addresses or hash order.
"""

from __future__ import annotations

import hashlib
import struct
import types
from typing import Any

import numpy as np

from search.gym.adapter import Adapter

# written by their names: what code is, not the state it runs on
NAMED = (type, types.FunctionType, types.BuiltinFunctionType, types.MethodType, types.ModuleType)


def describes_others(adapter: Adapter) -> bool:
    """Whether the adapter lists the world's other parts itself (its summaries record those, not a digest)."""
    return type(adapter).others is not Adapter.others


def world_digest(adapter: Adapter, env: Any, observation: Any) -> str:
    """The hex sha256 of an instance's observation and of its environment's state as ``snapshot_env`` copies it."""
    digest = hashlib.sha256()
    digest.update(encoding(np.asarray(observation)))
    digest.update(encoding(adapter.snapshot_env(env)))
    return digest.hexdigest()


def encoding(value: Any) -> bytes:
    """Canonical bytes of ``value`` and everything it holds: equal states give equal bytes in any process.

    Each item is a tag and a length-prefixed payload; an object met again (a shared part or a cycle) is written as
    the index of its first visit, so the walk ends and the order of visits alone decides the indices."""
    out: list[bytes] = []
    seen: dict[int, int] = {}
    alive: list[Any] = []  # keeps every visited object alive, so no id is reused during the walk
    stack: list[Any] = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, _Raw):
            out.append(item.data)
            continue
        atom = _atom(item)
        if atom is not None:
            out.append(atom)
            continue
        if id(item) in seen:
            out.append(_token(b"R", str(seen[id(item)]).encode()))
            continue
        seen[id(item)] = len(seen)
        alive.append(item)
        out.append(_token(b"O", _class_name(item)))
        stack.extend(reversed(_parts(item)))
    return b"".join(out)


class _Raw:
    """Bytes already encoded (a mapping's sorted keys, a set's sorted members), written as they are."""

    def __init__(self, data: bytes):
        self.data = data


def _token(tag: bytes, payload: bytes) -> bytes:
    return tag + struct.pack("<Q", len(payload)) + payload


def _class_name(item: Any) -> bytes:
    kind = type(item)
    return f"{kind.__module__}.{kind.__qualname__}".encode()


def _atom(item: Any) -> bytes | None:
    """The encoding of a value that holds no other values, or None."""
    if item is None:
        return _token(b"N", b"")
    if isinstance(item, bool):
        return _token(b"B", b"1" if item else b"0")
    if isinstance(item, int):
        return _token(b"I", str(item).encode())
    if isinstance(item, float):
        return _token(b"F", struct.pack("<d", item))
    if isinstance(item, complex):
        return _token(b"C", struct.pack("<dd", item.real, item.imag))
    if isinstance(item, str):
        return _token(b"S", item.encode("utf-8", "surrogatepass"))
    if isinstance(item, bytes | bytearray):
        return _token(b"Y", bytes(item))
    if isinstance(item, np.generic):
        item = np.asarray(item)
    if isinstance(item, np.ndarray) and item.dtype != object:
        header = f"{item.dtype.str}{item.shape}".encode()
        return _token(b"A", _token(b"h", header) + np.ascontiguousarray(item).tobytes())
    if isinstance(item, NAMED):
        return _token(b"T", f"{getattr(item, '__module__', '')}.{getattr(item, '__qualname__', '')}".encode())
    return None


def _parts(item: Any) -> list[Any]:
    """What an object holds, in a fixed order: items of a sequence, sorted entries of a mapping or a set, and for
    any other object what ``copy`` reduces it to (nothing beyond its class where it cannot be reduced)."""
    if isinstance(item, np.ndarray):  # an array of objects
        return [_Raw(_token(b"h", str(item.shape).encode())), *item.reshape(-1).tolist()]
    if isinstance(item, list | tuple):
        return [_Raw(_token(b"L", str(len(item)).encode())), *item]
    if isinstance(item, dict):
        keyed = sorted(((encoding(key), value) for key, value in item.items()), key=lambda pair: pair[0])
        return [_Raw(_token(b"D", str(len(keyed)).encode()))] + [
            part for key, value in keyed for part in (_Raw(key), value)
        ]
    if isinstance(item, set | frozenset):
        return [_Raw(_token(b"E", b"".join(sorted(encoding(member) for member in item))))]
    try:
        reduced = item.__reduce_ex__(4)
    except Exception:  # a lock, a handle of the operating system: its class alone, the rest is in the observation
        return []
    if isinstance(reduced, str):
        return [reduced]
    parts = list(reduced[1:3])
    for extra in reduced[3:5]:
        if extra is not None:
            parts.append(list(extra))
    return parts
