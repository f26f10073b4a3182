"""Read and write world files (YAML) with errors a user can act on.

Every problem becomes one line ``file:line: field.path: what is wrong (got value)``; the
line comes from the YAML node marks, kept in a map from field path to line while loading.
Only ``yaml.SafeLoader`` is used: a world file can never construct Python objects.
"""
from __future__ import annotations

import numbers
import os
from pathlib import Path
from typing import Any, NoReturn, Optional

import yaml
from pydantic import ValidationError

from composed_sim.world.problems import (FieldPath, field_at, format_path, got_text, kind_of, line_of, problems_of,
                                         show)
from composed_sim.world.schema import World

# Largest values of the command-line overrides, given as exclusive upper bounds.
_SEED_LIMIT = 2**32
# The world files shipped with the package: worlds/ of a source checkout (or an editable install).
SHIPPED_WORLDS = Path(__file__).resolve().parents[2] / "worlds"


class WorldFileError(Exception):
    """A world file, a world dict or an override that cannot be used.

    ``str(error)`` is the whole message for the user; ``problems`` holds its lines, one
    ``file:line: path: message (got value)`` per problem.
    """

    def __init__(self, message: str, problems: Optional[list[str]] = None):
        super().__init__(message)
        self.problems = problems if problems is not None else [message]


# --- public API ----------------------------------------------------------------------

def load_world(path: str | os.PathLike, *, robots: Optional[int] = None,
               ticks: Optional[int] = None, seed: Optional[int] = None) -> World:
    """Load a world file, then apply the command-line overrides (see ``with_overrides``)."""
    source = os.fspath(path)
    data, lines = _parse(read_file(source), source)
    world = check_has_robots(validate(data, source, lines), source, lines)
    return with_overrides(world, robots=robots, ticks=ticks, seed=seed, source=source)


def read_yaml(path: str | os.PathLike) -> Any:
    """A YAML file's data, read as world files are (safe, errors naming file:line), e.g. a sweep file."""
    source = os.fspath(path)
    data, _ = _parse(read_file(source), source)
    return data


def world_from_dict(data: Any, source: str = "<dict>") -> World:
    """Validate an already parsed world (e.g. a run's saved configuration); no line numbers."""
    return validate(data, source, {})


def field_line(source: str | os.PathLike, path: FieldPath) -> str:
    """``file:line`` of a field of a world file (or of its nearest ancestor that the file
    writes); just ``file`` where there is no line to give (an ARGoS file, an unreadable one)."""
    source = os.fspath(source)
    try:
        _, lines = _parse(read_file(source), source)
    except WorldFileError:
        return source
    line = line_of(lines, path)
    return f"{source}:{line}" if line else source


def dump_world(world: World) -> str:
    """YAML text that ``load_world`` reads back to an equal World (every field written)."""
    return yaml.dump(world.model_dump(mode="json"), Dumper=_Dumper, sort_keys=False,
                     allow_unicode=True)


class _Dumper(yaml.SafeDumper):
    """Block style, except lists of scalars inline: `position: [0.0, 10.0]`."""


_Dumper.add_representer(list, lambda dumper, value: dumper.represent_sequence(
    "tag:yaml.org,2002:seq", value,
    flow_style=not any(isinstance(v, (list, dict)) for v in value)))


def with_overrides(world: World, *, robots: Optional[int] = None, ticks: Optional[int] = None,
                   seed: Optional[int] = None, source: str = "<world>") -> World:
    """Apply --robots (total robot count), --ticks (length_ticks) and --seed.

    With several groups, --robots splits the total in proportion to the groups' counts
    (largest remainder, ties to the earlier group). Groups with explicit positions cannot
    be resized.
    """
    _check_override("robots", robots, 1, None)
    _check_override("ticks", ticks, 1, None)
    _check_override("seed", seed, 0, _SEED_LIMIT)
    data = world.model_dump()
    if robots is not None:
        counts = split_count(robots, [g.count for g in world.robots])
        for gi, (group, count) in enumerate(zip(world.robots, counts)):
            if group.placement.method == "explicit" and count != group.count:
                raise WorldFileError(
                    f"--robots: cannot resize robots[{gi}] from {group.count} to {count} robots "
                    f"(got {robots}): its placement lists explicit positions; change them in "
                    f"the world file instead")
            data["robots"][gi]["count"] = count
    if ticks is not None:
        data["length_ticks"] = ticks
    if seed is not None:
        data["seed"] = seed
    flags = " ".join(f"--{k} {v}" for k, v in (("robots", robots), ("ticks", ticks),
                                                ("seed", seed)) if v is not None)
    return validate(data, f"{source} (with {flags})", {}) if flags else world


def split_count(total: int, counts: list[int]) -> list[int]:
    """Split ``total`` in proportion to ``counts`` by largest remainder; equal if all are 0."""
    if not counts:
        raise WorldFileError("--robots: the world has no robot groups to resize")
    weights = counts if sum(counts) > 0 else [1] * len(counts)
    whole = sum(weights)
    shares = [total * w // whole for w in weights]          # exact integer arithmetic
    by_remainder = sorted(range(len(weights)), key=lambda i: (-(total * weights[i] % whole), i))
    for i in by_remainder[:total - sum(shares)]:
        shares[i] += 1
    return shares


# --- reading and parsing -------------------------------------------------------------

def read_file(source: str, what: str = "world file", error: type[WorldFileError] = WorldFileError,
              binary: bool = False) -> str | bytes:
    """The file's text (UTF-8), or its bytes; an ``error`` naming the file and ``what`` it should
    be when it cannot be read."""
    a = "an" if what[0].lower() in "aeiou" else "a"
    try:
        with open(source, "rb" if binary else "r", **({} if binary else {"encoding": "utf-8"})) as file:
            return file.read()
    except FileNotFoundError:
        raise error(f"{source}: no such {what}") from None
    except IsADirectoryError:
        raise error(f"{source}: is a directory, not {a} {what}") from None
    except UnicodeDecodeError as exc:
        raise error(f"{source}: not a UTF-8 text file (byte {exc.object[exc.start]:#04x} "
                    f"at offset {exc.start})") from None
    except OSError as exc:
        raise error(f"{source}: cannot read the {what}: {exc.strerror or exc}") from None


def _parse(text: str, source: str) -> tuple[Any, dict[FieldPath, int]]:
    """(data as yaml.safe_load gives it, {field path: 1-based line})."""
    try:
        loader = yaml.SafeLoader(text)     # checks for unprintable characters at once
    except yaml.reader.ReaderError as exc:
        line = text.count("\n", 0, exc.position) + 1
        raise WorldFileError(f"{source}:{line}: not valid YAML: character {exc.character:#06x} "
                             f"is not allowed") from None
    try:
        node = loader.get_single_node()
        data = None if node is None else loader.construct_document(node)
    except yaml.MarkedYAMLError as exc:
        mark = exc.problem_mark or exc.context_mark
        where = f"{source}:{mark.line + 1}" if mark else source
        context = f" ({exc.context} at line {exc.context_mark.line + 1})" \
            if exc.context and exc.context_mark else ""
        raise WorldFileError(f"{where}: not valid YAML: {exc.problem}{context}") from None
    except Exception as exc:    # noqa: BLE001 - e.g. a date like 2021-02-30; all are bad YAML
        raise WorldFileError(f"{source}: not valid YAML: {exc}") from None
    finally:
        loader.dispose()
    return data, ({} if node is None else _line_map(loader, node))


def _line_map(loader: yaml.SafeLoader, root: yaml.Node) -> dict[FieldPath, int]:
    # Walked after construction, so merge keys (<<) are already flattened into the nodes.
    # A node reached twice (an alias) is walked once: that also stops recursive aliases.
    lines: dict[FieldPath, int] = {(): root.start_mark.line + 1}
    seen: set[int] = set()
    stack = [(root, ())]
    while stack:
        node, path = stack.pop()
        if id(node) in seen:
            continue
        seen.add(id(node))
        if isinstance(node, yaml.MappingNode):
            # Duplicate keys: the last one wins, as in the data.
            pairs = {_key(loader, k): (k, v) for k, v in node.value}
            children = [(key, k.start_mark, v) for key, (k, v) in pairs.items()]
        elif isinstance(node, yaml.SequenceNode):
            children = [(i, v.start_mark, v) for i, v in enumerate(node.value)]
        else:
            continue
        for key, mark, child in children:
            lines[path + (key,)] = mark.line + 1
            stack.append((child, path + (key,)))
    return lines


def _key(loader: yaml.SafeLoader, node: yaml.Node) -> Any:
    try:
        return loader.construct_object(node)   # the key as the data holds it (1, true, "x")
    except Exception:   # noqa: BLE001 - already constructed once; fall back to its text
        return getattr(node, "value", None)


# --- validation and messages ---------------------------------------------------------

def validate(data: Any, source: str, lines: dict[FieldPath, int]) -> World:
    if data is None:
        raise WorldFileError(f"{source}: the world file is empty; it needs at least `robots:`")
    if not isinstance(data, dict):
        raise WorldFileError(f"{field_at(source, lines, ())}: the top level must be a mapping of "
                             f"world fields (name, seed, robots, ...), got {kind_of(data)} "
                             f"{show(data)}")
    try:
        world = World.model_validate(data)
    except ValidationError as exc:
        problems = [p for err in exc.errors() for p in problems_of(err)]
    except RecursionError:      # a pathological alias structure
        raise WorldFileError(f"{source}: the world refers to itself too deeply "
                             f"(recursive YAML aliases?)") from None
    else:
        for resolve in (_with_floor_image, _with_params_files, _with_interfaces):
            world = resolve(world, source, lines)
        return world
    _raise(problems, source, lines)


def _raise(problems: list[tuple[FieldPath, str, str]], source: str, lines: dict[FieldPath, int]) -> NoReturn:
    """One WorldFileError for the problems, each as file:line: field: message (got value)."""
    rows = sorted({(line_of(lines, path), format_path(path), message, got)
                   for path, message, got in problems}, key=lambda r: (r[0] or 0, r[1], r[2]))
    texts = [f"{source}{f':{line}' if line else ''}: {path}{': ' if path else ''}{message}{got}"
             for line, path, message, got in rows]
    if len(texts) == 1:
        raise WorldFileError(texts[0], texts)
    raise WorldFileError(f"{source}: {len(texts)} problems:\n" + "\n".join(f"  {t}" for t in texts),
                         texts)


def check_has_robots(world: World, source: str, lines: Optional[dict[FieldPath, int]] = None) -> World:
    """The world, if it has a robot to run; else one WorldFileError at its robots field. The
    schema allows an empty world (the core places and senses empty scenes), but a run does not:
    every host is made of its robots' participants or processes. A group of count 0
    beside others is fine."""
    if world.robot_count > 0:
        return world
    if not world.robots:
        _raise([(("robots",), "lists no robot group; a run needs at least one robot", "")], source, lines or {})
    _raise([(("robots", 0, "count"), "every group's count is 0; a run needs at least one robot", "")],
           source, lines or {})


def _with_floor_image(world: World, source: str, lines: dict[FieldPath, int]) -> World:
    """Make floor.image absolute (relative to the world file) and check it is a readable image."""
    image = world.floor.image
    if image is None:
        return world
    path = _relative_to(source, image)
    where = f"{field_at(source, lines, ('floor', 'image'))}: floor.image"
    if not os.path.isfile(path):
        raise WorldFileError(f"{where}: no such image file {path}{got_text(image)}")
    try:
        import imageio.v3 as iio     # only worlds with an image floor pay for the import
        shape = tuple(iio.improps(path).shape)
        problem = None
    except Exception as exc:    # noqa: BLE001 - any reader failure means the same to the user
        shape, problem = (), str(exc)
    if problem is None and (len(shape) not in (2, 3) or 0 in shape
                            or (len(shape) == 3 and shape[2] not in (3, 4))):
        problem = f"pixels of shape {list(shape)}, not [rows, columns] grey or [rows, columns, 3 or 4]"
    if problem is not None:
        raise WorldFileError(f"{where}: cannot read {path} as a grey or RGB(A) image: {problem}"
                             f"{got_text(image)}")
    return world.model_copy(update={"floor": world.floor.model_copy(update={"image": path})})


def _relative_to(source: str, path: str) -> str:
    """``path`` as written in the world file ``source``: relative to the file's folder."""
    base = os.path.dirname(os.path.abspath(source)) if os.path.isfile(source) else os.getcwd()
    return os.path.normpath(os.path.join(base, os.path.expanduser(path)))


def _with_params_files(world: World, source: str, lines: dict[FieldPath, int]) -> World:
    """Make every node's params_file absolute (relative to the world file) and check that it is a
    ROS 2 parameters file: a mapping of node names (or ``/**``) to ``ros__parameters``."""
    data = None
    places = [(("robots", gi, "nodes", ni), spec) for gi, group in enumerate(world.robots)
              for ni, spec in enumerate(group.nodes)] + [(("nodes", ni), spec) for ni, spec in enumerate(world.nodes)]
    for path, spec in places:
        if spec.params_file is None:
            continue
        field = path + ("params_file",)
        where = f"{field_at(source, lines, field)}: {format_path(field)}"
        resolved = _relative_to(source, spec.params_file)
        problem = params_file_problem(resolved)
        if problem is not None:
            raise WorldFileError(f"{where}: {problem}{got_text(spec.params_file)}")
        data = data if data is not None else world.model_dump()
        target = data
        for key in path:
            target = target[key]
        target["params_file"] = resolved
    return world if data is None else World.model_validate(data)


def params_file_problem(path: str) -> Optional[str]:
    """Why ``path`` is not a ROS 2 parameters file, or None."""
    if not os.path.isfile(path):
        return f"no such parameters file {path}"
    try:
        with open(path, encoding="utf-8") as f:
            data = yaml.safe_load(f)
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as exc:
        return f"cannot read {path} as YAML: {str(exc).splitlines()[0]}"
    nodes = data if isinstance(data, dict) else {}
    if not nodes or not all(isinstance(v, dict) and isinstance(v.get("ros__parameters"), dict)
                            for v in _param_sections(nodes)):
        return (f"{path} is not a ROS 2 parameters file: it must map node names (or /**) to "
                f"`ros__parameters:` mappings")
    return None


def _param_sections(nodes: dict) -> list:
    """The sections of a parameters file that carry ``ros__parameters``: a node name maps to them
    directly, or a namespace maps to node names that do (``ns: {node: {ros__parameters: …}}``)."""
    out = []
    for value in nodes.values():
        if isinstance(value, dict) and "ros__parameters" not in value and value \
                and all(isinstance(v, dict) for v in value.values()):
            out += _param_sections(value)
        else:
            out.append(value)
    return out


def _with_interfaces(world: World, source: str, lines: dict[FieldPath, int]) -> World:
    """Make each interfaces entry absolute (relative to the world file) and check it is an
    interface package folder; building it is the host's (composed_sim.interfaces.activate)."""
    if not world.interfaces:
        return world
    from composed_sim.interfaces.package import InterfaceError, read_package
    paths = []
    for i, entry in enumerate(world.interfaces):
        path = _relative_to(source, entry)
        try:
            read_package(path)
        except InterfaceError as e:
            raise WorldFileError(f"{field_at(source, lines, ('interfaces', i))}: interfaces[{i}]: {e}{got_text(entry)}") from None
        paths.append(path)
    return world.model_copy(update={"interfaces": paths})


def _check_override(name: str, value: Any, low: int, high: Optional[int]) -> None:
    if value is None:
        return
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise WorldFileError(f"--{name}: must be a whole number (got {show(value)})")
    if value < low:
        raise WorldFileError(f"--{name}: must be >= {low} (got {value})")
    if high is not None and value >= high:
        raise WorldFileError(f"--{name}: must be < {high} (got {value})")


