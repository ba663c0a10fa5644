"""Errors in TOML files that name the line: reading the text, finding the line that defines a key path, and refusing
a file with one message listing every problem as "file, line N, field: message".

A problem is a key path in the file (``("parts", 0, "questions", 1)``) and what is wrong there, found by a pydantic
model or by a check across tables. The server's study file (`app.survey.study`) and the bundle builder's `[build]`
table (`search.bundle.spec`) both report through this module, so a bad line reads alike on either side.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

Loc = tuple[str | int, ...]
Problem = tuple[Loc, str]
Model = TypeVar("Model", bound=BaseModel)


class TomlFileError(ValueError):
    """A TOML file that cannot be used; the message names the file, and the line and field of every problem."""


def load_toml(text: str, source: str, error: type[TomlFileError] = TomlFileError) -> dict[str, Any]:
    """The tables of TOML ``text``, or ``error`` naming ``source`` and tomllib's line and column."""
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as decode_error:
        raise error(f"{source}: not valid TOML: {decode_error}") from None


def _table_path(header: str, arrays: dict[Loc, int], new_element: bool = False) -> Loc:
    """Resolve a dotted header to a path with the current index of every array-of-tables along it; a `[[...]]`
    header (`new_element`) starts the next element of the array it names, so that one gets no index here."""
    names = [name.strip().strip('"') for name in header.split(".")]
    path: Loc = ()
    for i, name in enumerate(names):
        path += (name,)
        if path in arrays and not (new_element and i == len(names) - 1):
            path += (arrays[path],)
    return path


def locate(text: str, loc: Loc) -> int | None:
    """The line of `text` that best matches a key path (the deepest key or table defining it)."""
    want = tuple(str(x) for x in loc)
    arrays: dict[Loc, int] = {}
    table: Loc = ()
    best, best_depth = None, -1
    for number, raw in enumerate(text.splitlines(), start=1):
        line = raw.strip()
        path: Loc
        if line.startswith("[["):
            names = _table_path(line[2 : line.find("]]")], arrays, new_element=True)
            arrays[names] = arrays.get(names, -1) + 1
            table = names + (arrays[names],)
            path = table
        elif line.startswith("["):
            table = _table_path(line[1 : line.find("]")], arrays)
            path = table
        elif "=" in line and not line.startswith("#"):
            key = line.split("=", 1)[0].strip()
            path = table + tuple(k.strip().strip('"') for k in key.split("."))
        else:
            continue
        found = tuple(str(x) for x in path)
        depth = len(found) if want[: len(found)] == found else len(want) if found[: len(want)] == want else -1
        if depth > best_depth:  # a table only made by its subtables is found at the first of them
            best, best_depth = number, depth
    return best


def field_name(loc: Loc) -> str:
    """A key path as the file's reader writes it: ``parts[0].questions[1]``."""
    out = ""
    for part in loc:
        out += f"[{part}]" if isinstance(part, int) else (f".{part}" if out else str(part))
    return out or "(top level)"


def refuse(text: str, source: str, problems: list[Problem], error: type[TomlFileError] = TomlFileError) -> None:
    """Raise ``error`` listing every (key path, message) problem with the file, the line and the field."""
    if problems:
        lines = []
        for loc, message in problems:
            line = locate(text, loc)
            lines.append(f"{source}, {f'line {line}' if line else 'no line'}, {field_name(loc)}: {message}")
        raise error("\n".join(lines))


def validation_problems(
    failure: ValidationError, at: Loc = (), unknown_key: str = "unknown key", tidy: Callable[[Loc], Loc] | None = None
) -> list[Problem]:
    """A pydantic error's problems at their key paths in the file (under ``at``, the path of the table validated),
    put the way a reader of the file says them: ``unknown_key`` for a key the model does not have; ``tidy`` takes
    out of a path what pydantic adds and the file does not have (such as the member of a tagged union)."""
    problems: list[Problem] = []
    for item in failure.errors():
        loc: Loc = at + tuple(item["loc"])
        if tidy is not None:
            loc = tidy(loc)
        message = unknown_key if item["type"] == "extra_forbidden" else item["msg"].removeprefix("Value error, ")
        problems.append((loc, message))
    return problems


def validated(
    model: type[Model],
    data: Any,
    text: str,
    source: str,
    *,
    at: Loc = (),
    checks: Callable[[Model], list[Problem]] = lambda value: [],
    error: type[TomlFileError] = TomlFileError,
    unknown_key: str = "unknown key",
    tidy: Callable[[Loc], Loc] | None = None,
) -> Model:
    """``data`` (the table at key path ``at`` of the file's ``text``) as ``model``, then ``checks(value)``'s
    problems across its tables; every problem of either refused with its line and field."""
    try:
        value = model.model_validate(data)
    except ValidationError as failure:
        refuse(text, source, validation_problems(failure, at, unknown_key, tidy), error)
        raise  # refuse raised: a ValidationError always has a problem
    refuse(text, source, checks(value), error)
    return value
