"""From a package's .msg/.srv/.action files to C, C++ and Python sources, with the rosidl
generators' Python functions (what ``rosidl_generate_interfaces`` runs from CMake).

rosidl_cli's ``generate`` API would do the same in one call, but it finds the generators by entry
point, and the wheels install each generator's entry points twice (an egg-info and a dist-info),
which it refuses; so each generator is called here directly, with the arguments file it reads.
"""
from __future__ import annotations

import contextlib
import io
import re
from pathlib import Path, PurePosixPath

from composed_sim.interfaces.errors import InterfaceError
from composed_sim.interfaces.package import InterfacePackage

# The type supports rclpy's dispatch library (rosidl_typesupport_c) chooses among at run time;
# rmw_fastrtps_cpp takes the Fast DDS one, rosbag-like tools the introspection one.
TYPESUPPORTS = ("rosidl_typesupport_fastrtps_c", "rosidl_typesupport_introspection_c")

# Packages that generated services and actions use whether or not their files name them.
IMPLICIT_DEPENDENCIES = {"srv": ("service_msgs", "builtin_interfaces"),
                         "action": ("action_msgs", "unique_identifier_msgs", "service_msgs", "builtin_interfaces")}

_INCLUDE = re.compile(r'^#include "([a-z][a-z0-9_]*)/(msg|srv|action)/(\w+)\.idl"', re.M)
_ADAPTER_ERROR = re.compile(r"Error processing '(.*)' of '")


def translate(pkg: InterfacePackage, idl_dir: Path) -> list[str]:
    """Each interface file as .idl under ``idl_dir``; their paths relative to it. A file that
    rosidl_adapter refuses gives InterfaceError with its path, line and the adapter's words."""
    from rosidl_adapter.action import convert_action_to_idl
    from rosidl_adapter.msg import convert_msg_to_idl
    from rosidl_adapter.srv import convert_srv_to_idl

    convert = {"msg": convert_msg_to_idl, "srv": convert_srv_to_idl, "action": convert_action_to_idl}
    out = []
    for rel in pkg.files:
        kind = rel.split("/")[0]
        said = io.StringIO()
        try:
            with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(said):
                convert[kind](pkg.root, pkg.name, PurePosixPath(rel), idl_dir / kind)
        except Exception as e:    # noqa: BLE001 - the adapter raises many kinds; each is the user's file
            bad = _ADAPTER_ERROR.search(said.getvalue())
            line = _line_of(pkg.root / rel, lambda text: text.strip() == bad.group(1).strip()) if bad else None    # noqa: B023 - called here
            raise InterfaceError(_located(pkg.root / rel, line, f"{bad.group(1).strip()!r}: " if bad else "",
                                          _first_lines(str(e) or type(e).__name__))) from None
        out.append(str(PurePosixPath(rel).with_suffix(".idl")))
    return out


def dependencies(pkg: InterfacePackage, idl_dir: Path, idls: list[str], share_dirs: list[Path]) -> list[str]:
    """The other interface packages the package's files use (and those that generated services
    and actions use), each checked to be installed; a type that is nowhere gives InterfaceError
    with the file and line that names it."""
    found: dict[str, None] = {}
    own = {str(PurePosixPath(i).with_suffix("")) for i in idls}
    for idl, rel in zip(idls, pkg.files):
        for dep, kind, name in _INCLUDE.findall((idl_dir / idl).read_text(encoding="utf-8")):
            if dep == pkg.name:
                if f"{kind}/{name}" not in own:
                    raise _unknown_type(pkg.root / rel, dep, kind, name, f"{pkg.name} has no {kind}/{name}.{kind}")
                continue
            if not any((d / dep / kind / f"{name}.idl").is_file() for d in share_dirs):
                installed = any((d / dep).is_dir() for d in share_dirs)
                raise _unknown_type(pkg.root / rel, dep, kind, name,
                                    f"package {dep} has no {kind}/{name}" if installed else
                                    f"no interface package {dep} is installed or named before {pkg.name} "
                                    f"in the world's interfaces")
            found[dep] = None
        for implicit in IMPLICIT_DEPENDENCIES.get(rel.split("/")[0], ()):
            found[implicit] = None
    return list(found)


def generate_sources(pkg: InterfacePackage, idl_dir: Path, idls: list[str], share_dirs: list[Path],
                     out: Path) -> None:
    """Type hashes (.json beside the .idl files), C (``out/c``), the C type supports (``out/<typesupport>``) and
    Python (``out/py``) of the package's .idl files."""
    import rosidl_generator_c
    import rosidl_generator_py
    import rosidl_typesupport_c
    import rosidl_typesupport_fastrtps_c
    import rosidl_typesupport_introspection_c
    from rosidl_cli.command.helpers import (generate_visibility_control_file, generator_arguments_file,
                                            legacy_generator_arguments)
    from rosidl_generator_type_description import generate_type_hash

    templates = share_dirs[0]     # the toolchain's share: the generators' resource folders
    interface_files = [f"{idl_dir}:{i}" for i in idls]
    packages = sorted({p for d in share_dirs for p in d.iterdir() if any(p.glob("*/*.idl"))})

    def arguments(generator: str, output: Path, **extra):
        return generator_arguments_file(**legacy_generator_arguments(
            package_name=pkg.name, interface_files=interface_files, include_paths=[str(p) for p in packages],
            templates_path=templates / generator / "resource", output_path=output), **extra)

    name = pkg.name
    with _generator_errors(pkg):
        with arguments("rosidl_generator_type_description", idl_dir,
                       include_paths=[f"{p.name}:{p}" for p in packages]) as a:
            descriptions = generate_type_hash(a)
        for generator in ("rosidl_generator_c",) + TYPESUPPORTS:
            subdir = "c" if generator == "rosidl_generator_c" else generator
            for kind in sorted({f.split("/")[0] for f in pkg.files} | {"msg"}):
                generate_visibility_control_file(
                    package_name=name, output_path=out / subdir / name / kind / f"{generator}__visibility_control.h",
                    template_path=templates / generator / "resource" / f"{generator}__visibility_control.h.in")
        with arguments("rosidl_generator_c", out / "c" / name,
                       type_description_tuples=_type_description_tuples(idls, descriptions),
                       ros_interface_files=[str(pkg.root / f) for f in pkg.files]) as a:
            rosidl_generator_c.generate_c(a)
        with arguments("rosidl_typesupport_c", out / "rosidl_typesupport_c" / name) as a:
            rosidl_typesupport_c.generate_c(a, list(TYPESUPPORTS))
        with arguments("rosidl_typesupport_introspection_c", out / "rosidl_typesupport_introspection_c" / name) as a:
            rosidl_typesupport_introspection_c.generate_c(a)
        with arguments("rosidl_typesupport_fastrtps_c", out / "rosidl_typesupport_fastrtps_c" / name) as a:
            rosidl_typesupport_fastrtps_c.generate_typesupport_fastrtps_c(a)
        with arguments("rosidl_generator_py", out / "py" / name) as a:
            rosidl_generator_py.generate_py(a, ["rosidl_typesupport_c", *TYPESUPPORTS])


def _type_description_tuples(idls: list[str], descriptions: list) -> list[str]:
    """``msg/Empty.idl:<its .json>`` for each .idl, matched by kind and name: rosidl_cli's own helper
    matches by name alone, and gives a package's ``srv/Empty`` the description of its ``msg/Empty``."""
    by_path = {PurePosixPath(*Path(d).parts[-2:]).with_suffix(""): d for d in map(str, descriptions)}
    return [f"{idl}:{by_path[PurePosixPath(idl).with_suffix('')]}" for idl in idls]


@contextlib.contextmanager
def _generator_errors(pkg: InterfacePackage):
    """A generator's failure as one InterfaceError: the package and the generator's first lines
    (with the file it names, which is the .idl made from the user's file)."""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            yield
    except InterfaceError:
        raise
    except Exception as e:    # noqa: BLE001 - whatever a generator raises, it is about this package
        raise InterfaceError(f"{pkg.root}: the rosidl generators failed on package {pkg.name}: "
                             f"{type(e).__name__}: {_first_lines(str(e))}") from None


def _unknown_type(path: Path, dep: str, kind: str, name: str, why: str) -> InterfaceError:
    short = re.compile(rf"(^|[\s,]){re.escape(dep)}/({kind}/)?{re.escape(name)}\b")
    plain = re.compile(rf"(^|\s){re.escape(name)}\b")
    line = _line_of(path, lambda text: bool(short.search(text.split("#")[0]))) or \
        _line_of(path, lambda text: bool(plain.search(text.split("#")[0])))
    return InterfaceError(_located(path, line, "", f"unknown type {dep}/{kind}/{name}: {why}"))


def _line_of(path: Path, matches) -> int | None:
    for number, text in enumerate(path.read_text(encoding="utf-8", errors="replace").splitlines(), 1):
        if matches(text):
            return number
    return None


def _located(path: Path, line: int | None, what: str, message: str) -> str:
    return f"{path}{f':{line}' if line else ''}: {what}{message}"


def _first_lines(text: str, count: int = 3) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return "\n  ".join(lines[:count]) + (" …" if len(lines) > count else "")
