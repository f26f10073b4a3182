"""A world file's problems as lines a user can act on: ``file:line: field.path: what is wrong
(got value)``, from pydantic's errors and the schema's own checks (world/validation.py)."""
from __future__ import annotations

import json
import reprlib
import types
from typing import Annotated, Any, Optional, Union, get_args, get_origin

from pydantic import BaseModel

from composed_sim.world.schema import World

FieldPath = tuple[Union[str, int], ...]      # a field path, e.g. ("robots", 0, "count")


def problems_of(err: dict) -> list[tuple[FieldPath, str, str]]:
    """(path the user wrote, message, " (got value)" or "") for one pydantic error."""
    ctx = err.get("ctx") or {}
    if err["type"] == "world":      # the schema's own checks, possibly several at once
        out = []
        for sub, message, value in ctx["problems"]:
            path, _, _ = _resolve(tuple(err["loc"]) + tuple(sub))
            out.append((path, message, "" if value is ... else got_text(value)))   # ...: no value to show
        return out
    path, owner, tp = _resolve(tuple(err["loc"]))
    kind, value = err["type"], err.get("input")
    if kind == "missing" and path and isinstance(path[-1], int):    # a tuple too short
        parent = _resolve(tuple(err["loc"])[:-1])[2]
        return [(path[:-1], f"must have exactly {len(get_args(parent))} items", got_text(value))]
    if kind == "too_long" and get_origin(tp) is tuple and Ellipsis not in get_args(tp):
        return [(path, f"must have exactly {len(get_args(tp))} items", got_text(value))]
    if kind == "missing":
        return [(path, "is required", "")]
    if kind == "extra_forbidden":
        allowed = ", ".join(owner.model_fields) if owner else "?"
        return [(path, f"unknown field (allowed here: {allowed})", got_text(value))]
    if kind == "union_tag_invalid":
        return [(path + ("type",), f"must be one of {ctx['expected_tags']}", got_text(ctx["tag"]))]
    if kind == "union_tag_not_found":
        return [(path + ("type",), f"is required: one of {', '.join(map(repr, _tags(tp)))}", "")]
    if kind == "invalid_key":
        return [(path[:-1], "field names must be text", got_text(value))]
    return [(path, _MESSAGES.get(kind, _rephrase)(ctx, err["msg"]), got_text(value))]


_MESSAGES = {
    "greater_than": lambda c, m: f"must be > {c['gt']}",
    "greater_than_equal": lambda c, m: f"must be >= {c['ge']}",
    "less_than": lambda c, m: f"must be < {c['lt']}",
    "less_than_equal": lambda c, m: f"must be <= {c['le']}",
    "int_type": lambda c, m: "must be a whole number",
    "int_parsing": lambda c, m: "must be a whole number",
    "int_from_float": lambda c, m: "must be a whole number",
    "float_type": lambda c, m: "must be a number",
    "float_parsing": lambda c, m: "must be a number",
    "finite_number": lambda c, m: "must be a finite number",
    "bool_type": lambda c, m: "must be true or false",
    "bool_parsing": lambda c, m: "must be true or false",
    "string_type": lambda c, m: "must be text",
    "string_too_short": lambda c, m: "must not be empty",
    "list_type": lambda c, m: "must be a list",
    "tuple_type": lambda c, m: "must be a list",
    "too_long": lambda c, m: f"must have at most {c['max_length']} items",
    "too_short": lambda c, m: f"must have at least {c['min_length']} items",
    "literal_error": lambda c, m: f"must be one of {c['expected']}",
    "dict_type": lambda c, m: "must be a mapping (key: value lines)",
    "model_type": lambda c, m: "must be a mapping (key: value lines)",
    "model_attributes_type": lambda c, m: "must be a mapping (key: value lines)",
    "recursion_loop": lambda c, m: "refers to itself (a recursive YAML alias)",
}


def _rephrase(ctx: dict, msg: str) -> str:
    return msg.replace("Input should be", "must be").replace("Input should", "must")


def _resolve(loc: tuple) -> tuple[FieldPath, Optional[type[BaseModel]], Any]:
    """Walk the schema along a pydantic loc.

    Returns the path as the user wrote it (pydantic inserts the name of the union member it
    tried, e.g. ``obstacles.0.box.size``: dropped), the model owning the last element, and
    the type found at the end of the path (None once the path leaves the schema).
    """
    path: list = []
    tp: Any = World
    owner = None
    for item in loc:
        tp, owner = _unwrap(tp), None
        if isinstance(tp, type) and issubclass(tp, BaseModel):
            owner = tp
            field = tp.model_fields.get(item) if isinstance(item, str) else None
            tp = field.annotation if field else None
        elif get_origin(tp) is Union and isinstance(item, str):
            tp = {t: m for m in get_args(tp) for t in _tags(m)}.get(item)
            continue            # a union member's name, not part of the user's path
        elif get_origin(tp) in (list, tuple) and isinstance(item, int):
            args = [a for a in get_args(tp) if a is not Ellipsis]
            tp = args[min(item, len(args) - 1)] if args else None
        elif get_origin(tp) is dict:
            tp = get_args(tp)[1]
        else:
            tp = None
        path.append(item)
    return tuple(path), owner, _unwrap(tp)


def _unwrap(tp: Any) -> Any:
    """Strip Annotated[...] and Optional[...] wrappers."""
    while True:
        if get_origin(tp) is Annotated:
            tp = get_args(tp)[0]
        elif get_origin(tp) in (Union, types.UnionType) and type(None) in get_args(tp):
            rest = [a for a in get_args(tp) if a is not type(None)]
            tp = rest[0] if len(rest) == 1 else Union[tuple(rest)]
        else:
            return tp


def _tags(tp: Any) -> list[str]:
    """Discriminator values (the ``type`` field) of a model or of a union of models."""
    members = get_args(tp) if get_origin(tp) is Union else (tp,)
    return [m.model_fields["type"].default for m in members
            if isinstance(m, type) and issubclass(m, BaseModel) and "type" in m.model_fields]


def line_of(lines: dict[FieldPath, int], path: FieldPath) -> Optional[int]:
    """Line of the path, or of its nearest ancestor that the file has (e.g. a missing field)."""
    for end in range(len(path), 0, -1):
        line = lines.get(path[:end])
        if line is not None:
            return line
    return None     # the top level: a line number would say nothing


def field_at(source: str, lines: dict[FieldPath, int], path: FieldPath) -> str:
    line = lines.get(path)
    return f"{source}:{line}" if line else source


def format_path(path: FieldPath) -> str:
    """``robots[0].placement``"""
    out = ""
    for item in path:
        out += f"[{item}]" if isinstance(item, int) and not isinstance(item, bool) else \
            (f".{item}" if out else str(item))
    return out


def got_text(value: Any) -> str:
    return f" (got {show(value)})"


def show(value: Any, limit: int = 80) -> str:
    """The value as the user would write it in YAML/JSON, shortened."""
    try:
        text = json.dumps(value, ensure_ascii=False, default=str)
    except Exception:   # noqa: BLE001 - recursive or odd keys: Python's repr copes with all
        text = reprlib.repr(value)
    return text if len(text) <= limit else text[:limit - 3] + "..."


def kind_of(value: Any) -> str:
    return {list: "a list", str: "text", bool: "true/false", int: "a number",
            float: "a number"}.get(type(value), f"a {type(value).__name__}")
