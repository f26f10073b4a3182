"""Interface packages made importable in this process and in the processes it starts."""
from __future__ import annotations

import importlib.util
import os
import sys
from pathlib import Path
from typing import Iterable

from composed_sim.interfaces.build import BuiltPackage, build_package
from composed_sim.interfaces.errors import InterfaceError

# Interface packages that ship with composed_sim (composed_sim/data/interfaces/): the messages of
# the robots it simulates that no PyPI wheel carries (Crazyswarm2's crazyflie_interfaces, with its
# names and fields, so its type hashes), so that every shipped world runs from a fresh install.
SHIPPED = Path(__file__).resolve().parents[1] / "data" / "interfaces"


def activate(paths: Iterable[str | os.PathLike], shipped: Iterable[str] = ()) -> list[BuiltPackage]:
    """Build (or find built) each interface package folder, in order (a package may use those
    before it), and make its messages importable: its ``python`` folder goes first on sys.path
    and on PYTHONPATH (child processes: workers, multi-process controllers), its prefix first on
    AMENT_PREFIX_PATH (where bags and the Foxglove server find the .msg definitions). The
    libraries need no LD_LIBRARY_PATH (see composed_sim/interfaces/compile.py). ``shipped``: the
    names of packages in SHIPPED the caller needs, built (once, cached) and activated after
    ``paths`` where neither ``paths`` nor this process's path has one of that name already (the
    user's own build comes first). InterfaceError names the package's file and line, or the
    missing tool."""
    built: list[BuiltPackage] = []
    for path in paths:
        package = build_package(path, after=built)
        _check_not_shadowed(package)
        built.append(package)
    for name in shipped:
        if name not in {p.name for p in built} and importlib.util.find_spec(name) is None:
            built.append(build_package(SHIPPED / name, after=built))
    for package in reversed(built):     # the first named ends up first
        _prepend(sys.path, str(package.python_path))
        _prepend_env("PYTHONPATH", str(package.python_path))
        _prepend_env("AMENT_PREFIX_PATH", str(package.prefix))
    return built


def _check_not_shadowed(package: BuiltPackage) -> None:
    """A module of the package's name already imported from elsewhere would hide the build."""
    module = sys.modules.get(package.name)
    where = getattr(module, "__file__", None)
    if module is not None and (where is None or package.python_path not in Path(where).resolve().parents):
        raise InterfaceError(f"{package.source}: interface package {package.name} is already imported from "
                             f"{where or 'elsewhere'} in this process; its new build ({package.prefix}) "
                             f"cannot replace it (start a new process)")


def _prepend(items: list[str], item: str) -> None:
    if item in items:
        items.remove(item)
    items.insert(0, item)


def _prepend_env(variable: str, item: str) -> None:
    parts = [p for p in os.environ.get(variable, "").split(os.pathsep) if p]
    _prepend(parts, item)
    os.environ[variable] = os.pathsep.join(parts)
