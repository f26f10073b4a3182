"""The grid of a sweep: seeds, swarm sizes and world fields by dotted path, checked against the
world schema before any run starts."""
from __future__ import annotations

import hashlib
import itertools
import re
import types
from dataclasses import dataclass, field
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union, get_args, get_origin

import yaml
from pydantic import BaseModel

from composed_sim.world.loader import WorldFileError, check_has_robots, dump_world, load_world, world_from_dict
from composed_sim.world.schema import World


class GridError(ValueError):
    """A sweep's grid cannot be run; the message is one line naming what is wrong."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a sweep: the world (overrides applied) and the swept values that made it."""
    world: World
    values: dict[str, Any]          # swept name → value, e.g. {"seed": 1, "robots": 20, "robots.0.params.gain": 500}
    ticks: Optional[int] = None

    @property
    def name(self) -> str:
        """The run's folder name, from its swept values: seed=1_robots=20_gain=500."""
        parts = [f"{k.rsplit('.', 1)[-1]}={v}" for k, v in self.values.items()]
        return re.sub(r"[^A-Za-z0-9_.=+-]", "-", "_".join(parts)) or "run"

    def world_text(self) -> str:
        return dump_world(self.world)

    def spec_hash(self, run_args: list[str]) -> str:
        """What decides the run's results: the resolved world, the run's options, the version."""
        from importlib.metadata import version
        text = "\n".join([self.world_text(), " ".join(run_args), version("composed_sim")])
        return hashlib.sha256(text.encode()).hexdigest()


@dataclass
class Grid:
    world_path: Path
    seeds: list[int] = field(default_factory=list)
    robots: list[int] = field(default_factory=list)
    sets: dict[str, list[Any]] = field(default_factory=dict)   # dotted path → values
    ticks: Optional[int] = None

    def specs(self) -> list[RunSpec]:
        """Every combination, each world validated (a bad value is a GridError before any run)."""
        try:
            base = load_world(self.world_path, ticks=self.ticks)
        except WorldFileError as e:
            raise GridError(str(e)) from None
        sets = {path: [check_override(base, path, value) for value in values] for path, values in self.sets.items()}
        axes: list[tuple[str, list]] = [(k, v) for k, v in (("seed", self.seeds), ("robots", self.robots)) if v]
        axes += list(sets.items())
        out = []
        for combo in itertools.product(*(values for _, values in axes)):
            values = dict(zip((name for name, _ in axes), combo))
            try:
                world = _apply(base, values, str(self.world_path))
            except WorldFileError as e:     # e.g. a seed past the schema's limit
                raise GridError(str(e)) from None
            out.append(RunSpec(world, values, self.ticks))
        return out


def parse_list(text: str, what: str) -> list[Any]:
    """``1,2,3``, ``1-5`` (whole numbers) or a mix; other values as YAML scalars (``true``, ``0.5``,
    ``[1, 2]``), split at the commas outside brackets."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(text + ","):
        depth += ch in "[{"
        depth -= ch in "]}"
        if ch == "," and depth == 0:
            items.append(text[start:i].strip())
            start = i + 1
    out: list[Any] = []
    for item in items:
        if not item:
            raise GridError(f"{what}: an empty value in {text!r}")
        m = re.fullmatch(r"(\d+)-(\d+)", item)
        if m:
            lo, hi = int(m.group(1)), int(m.group(2))
            if lo > hi:
                raise GridError(f"{what}: the range {item} runs backwards")
            out += list(range(lo, hi + 1))
            continue
        try:
            out.append(yaml.safe_load(item))
        except yaml.YAMLError:
            raise GridError(f"{what}: cannot read the value {item!r}") from None
    return out


def whole_numbers(values: list[Any], what: str, *, minimum: int, example: str) -> list[int]:
    """Seeds (minimum 0) or swarm sizes (minimum 1) as parsed: each a whole number, else one
    GridError naming where it came from (``--seeds`` or the sweep file's ``seeds``)."""
    for value in values:
        if isinstance(value, bool) or not isinstance(value, int):
            raise GridError(f"{what}: {value!r} is not a whole number (give e.g. {example})")
        if value < minimum:
            raise GridError(f"{what}: must be >= {minimum} (got {value})")
    return values


def parse_set(text: str) -> tuple[str, list[Any]]:
    """``robots.0.params.gain=500,1000`` → ("robots.0.params.gain", [500, 1000])."""
    path, sep, values = text.partition("=")
    if not sep or not path.strip():
        raise GridError(f"--set {text!r}: expected PATH=V1,V2,... e.g. robots.0.params.gain=500,1000")
    return path.strip(), parse_list(values, f"--set {path.strip()}")


def _apply(base: World, values: dict[str, Any], source: str) -> World:
    data = base.model_dump(mode="json")
    for name, value in values.items():
        if name == "seed":
            data["seed"] = value
        elif name == "robots":
            from composed_sim.world.loader import with_overrides
            data = with_overrides(world_from_dict(data), robots=value).model_dump(mode="json")
        else:
            _set(data, name.split("."), value)
    return check_has_robots(world_from_dict(data, f"{source} (sweep)"), f"{source} (sweep)")


def _set(data: Any, keys: list[str], value: Any) -> None:
    *parents, last = keys
    for key in parents:
        data = data[int(key)] if isinstance(data, list) else data[key]
    if isinstance(data, list):
        data[int(last)] = value
    else:
        data[last] = value


def check_override(base: World, path: str, value: Any) -> Any:
    """The value to set at a dotted path, checked: the path names a world field and the value fits
    it (a whole number where the world has a float, e.g. a controller's gain, becomes a float);
    else one GridError line naming the path and the field's type."""
    where = field_type(base, path)
    current = _get(base.model_dump(mode="json"), path.split("."))
    if isinstance(current, float) and isinstance(value, int) and not isinstance(value, bool):
        value = float(value)
    if current is not None and type(current) is not type(value) and not isinstance(current, (list, dict)):
        raise GridError(f"--set {path}={value!r}: the field is {where} and holds {type(current).__name__} "
                        f"{current!r}; {value!r} is {type(value).__name__}")
    try:
        _apply(base, {path: value}, "sweep")
    except WorldFileError as e:
        reason = str(e).split(": ", 2)[-1] if ": " in str(e) else str(e)
        raise GridError(f"--set {path}={value!r}: the field is {where}; {reason}") from None
    return value


def _get(data: Any, keys: list[str]) -> Any:
    for key in keys:
        data = data[int(key)] if isinstance(data, list) else data.get(key) if isinstance(data, dict) else None
    return data


def field_type(base: World, path: str) -> str:
    """The type of the world field at a dotted path, in words; a GridError for a path that names none."""
    data: Any = base
    annotation: Any = World
    walked: list[str] = []
    for key in path.split("."):
        origin = get_origin(annotation)
        if isinstance(data, BaseModel):
            fields = type(data).model_fields
            if key not in fields:
                raise GridError(f"--set {path}: unknown field {'.'.join(walked + [key])} "
                                f"({'.'.join(walked) or 'the world'} has: {', '.join(fields)})")
            info = fields[key]
            annotation, data = (Annotated[(info.annotation, *info.metadata)] if info.metadata else info.annotation,
                                getattr(data, key))
        elif isinstance(data, (list, tuple)):
            if not key.isdigit() or int(key) >= len(data):
                raise GridError(f"--set {path}: {'.'.join(walked)} is a list of {len(data)}; "
                                f"{key!r} is not an index of it")
            args = get_args(_unwrap(annotation))
            annotation, data = (args[0] if args else Any), data[int(key)]
        elif isinstance(data, dict):
            args = get_args(_unwrap(annotation))
            if key not in data and origin is None and not args:
                raise GridError(f"--set {path}: {'.'.join(walked)} has no field {key!r}")
            annotation, data = (args[1] if len(args) == 2 else Any), data.get(key)
        else:
            raise GridError(f"--set {path}: {'.'.join(walked)} is a {_words(annotation)}, with no field {key!r}")
        walked.append(key)
    return _words(annotation)


def _unwrap(annotation: Any) -> Any:
    """Optional[X] → X; Annotated[X, ...] → X."""
    if get_origin(annotation) is Annotated:
        return _unwrap(get_args(annotation)[0])
    if get_origin(annotation) in (Union, types.UnionType):
        args = [a for a in get_args(annotation) if a is not type(None)]
        if len(args) == 1:
            return args[0]
    return annotation


def _words(annotation: Any) -> str:
    """A type annotation in words: float, int >= 0, float or int or str or bool or list[float]."""
    origin, args = get_origin(annotation), get_args(annotation)
    if origin is Annotated:
        limits = [f"{op} {getattr(m, name)}" for m in args[1:] for f in getattr(m, "metadata", [m])
                  for name, op in (("ge", ">="), ("gt", ">"), ("le", "<="), ("lt", "<")) for m in [f]
                  if getattr(m, name, None) is not None]
        return " ".join([_words(args[0]), *limits])
    if origin in (Union, types.UnionType):
        return " or ".join(_words(a) for a in args)
    if origin is Literal:
        return " or ".join(repr(a) for a in args)
    if origin is not None:
        return f"{origin.__name__}[{', '.join(_words(a) for a in args)}]"
    return "None" if annotation is type(None) else getattr(annotation, "__name__", str(annotation))
