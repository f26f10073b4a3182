"""One interface package built into a folder named by its content, or found there.

The folder, ``<cache>/<name>-<hash>`` (``$XDG_CACHE_HOME/composed_sim/interfaces``, by default
``~/.cache/…``), is an install prefix as colcon would make it:

    python/<name>/                 the importable package (sys.path / PYTHONPATH entry)
    lib/lib<name>__*.so            its libraries
    include/<name>/<name>/msg/…    its C headers (for packages that use it)
    share/<name>/msg/*.msg|idl|json, package.xml, share/ament_index/…   its definitions (for
                                   packages that use it, for bags' schemas: AMENT_PREFIX_PATH entry)
    build.json                     written last: the build is complete

The hash covers the package's files, the toolchain (composed_sim.interfaces.toolchain) and the
packages it was built against, so a second build of the same thing is found, not repeated. A build
runs in a temporary folder beside the final one and is renamed into place in one step: two
processes building the same package at once both succeed, and one of the two results stays.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Optional

from composed_sim.interfaces.compile import compile_package
from composed_sim.interfaces.generate import dependencies, generate_sources, translate
from composed_sim.interfaces.package import read_package
from composed_sim.interfaces.toolchain import find_compilers, find_toolchain

MARKER = "build.json"

# Loaded by the built package's __init__: the type supports rosidl_typesupport_c opens by name
# (each library's run path brings the rest).
_INIT = '''"""Interface package {name}, built by composed_sim from {source}."""
import ctypes as _ctypes
import os as _os

_lib = _os.path.join(_os.path.dirname(_os.path.abspath(__file__)), "..", "..", "lib")
for _typesupport in ("rosidl_typesupport_introspection_c", "rosidl_typesupport_fastrtps_c"):
    _ctypes.CDLL(_os.path.join(_lib, "lib{name}__" + _typesupport + ".so"))
'''


@dataclass(frozen=True)
class BuiltPackage:
    name: str
    prefix: Path            # the build folder (see the module's docstring)
    cached: bool            # found built, nothing run
    seconds: float          # what this call took
    source: Path

    @property
    def python_path(self) -> Path:
        return self.prefix / "python"


def cache_root() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    # Resolved: a build's path is compared with where a module was imported from (resolved by
    # Python), and one folder spelt two ways (``/a/b/../c``) must be one build.
    return Path(base).resolve() / "composed_sim" / "interfaces"


def build_package(path: str | os.PathLike, *, after: Iterable[BuiltPackage] = (),
                  cache: Optional[Path] = None) -> BuiltPackage:
    """Build the interface package in folder ``path`` (or find its build); ``after``: packages
    already built that it may use. InterfaceError with the file and line, or the missing tool."""
    start = time.perf_counter()
    pkg = read_package(path)
    tools = find_toolchain()
    after = list(after)
    key = hashlib.sha256("\n".join([pkg.content_hash(), tools.fingerprint(),
                                    *(p.prefix.name for p in after)]).encode()).hexdigest()[:16]
    root = Path(cache).resolve() if cache is not None else cache_root()
    final = root / f"{pkg.name}-{key}"
    if (final / MARKER).is_file():
        return BuiltPackage(pkg.name, final, True, time.perf_counter() - start, pkg.root)
    compilers = find_compilers()
    root.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=f".{final.name}.", dir=root))
    try:
        out = work / "prefix"
        generated = work / "generated"
        share_dirs = [tools.share, *(p.prefix / "share" for p in after)]
        idls = translate(pkg, out / "share" / pkg.name)
        deps = dependencies(pkg, out / "share" / pkg.name, idls, share_dirs)
        generate_sources(pkg, out / "share" / pkg.name, idls, share_dirs, generated)
        _install_python_and_headers(pkg.name, pkg.root, generated, out)
        compile_package(pkg.name, generated, out, deps, [p.prefix for p in after], tools, compilers)
        _install_share(pkg, out)
        seconds = time.perf_counter() - start
        (out / MARKER).write_text(json.dumps({"name": pkg.name, "source": str(pkg.root), "seconds": round(seconds, 3),
                                              "dependencies": deps}, indent=1))
        try:
            os.rename(out, final)
        except OSError:
            if not (final / MARKER).is_file():    # not another process's complete build: ours failed
                raise
        return BuiltPackage(pkg.name, final, False, seconds, pkg.root)
    finally:
        shutil.rmtree(work, ignore_errors=True)


def _install_python_and_headers(name: str, source: Path, generated: Path, out: Path) -> None:
    shutil.copytree(generated / "py" / name, out / "python" / name, ignore=shutil.ignore_patterns("*.c"))
    (out / "python" / name / "__init__.py").write_text(_INIT.format(name=name, source=source))
    include = out / "include" / name
    for folder in ("c", "rosidl_typesupport_introspection_c", "rosidl_typesupport_fastrtps_c"):
        shutil.copytree(generated / folder, include, dirs_exist_ok=True,
                        ignore=lambda d, names: [n for n in names if not (n.endswith(".h") or Path(d, n).is_dir())])


def _install_share(pkg, out: Path) -> None:
    """The definitions (.msg beside .idl and .json), package.xml and the ament index entries
    that ROS tools (and ``ament_index_python``) look a package up by."""
    share = out / "share" / pkg.name
    shutil.copy2(pkg.root / "package.xml", share / "package.xml")
    for rel in pkg.files:
        shutil.copy2(pkg.root / rel, share / rel)
    index = out / "share" / "ament_index" / "resource_index"
    (index / "packages").mkdir(parents=True, exist_ok=True)
    (index / "packages" / pkg.name).write_text("")
    (index / "rosidl_interfaces").mkdir(parents=True, exist_ok=True)
    (index / "rosidl_interfaces" / pkg.name).write_text(
        "\n".join(f for rel in pkg.files for f in (rel, str(Path(rel).with_suffix(".idl")))))
