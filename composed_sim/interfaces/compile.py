"""The generated sources compiled into the libraries a colcon build would install, with the C and
C++ compilers directly (no CMake: five libraries and three extension modules, each one command).

    lib/lib<pkg>__rosidl_generator_c.so                  the message structs' functions
    lib/lib<pkg>__rosidl_typesupport_introspection_c.so  field layout, for introspecting tools
    lib/lib<pkg>__rosidl_typesupport_fastrtps_c.so       CDR (de)serialisation for Fast DDS
    lib/lib<pkg>__rosidl_typesupport_c.so                the dispatch: loads one of the two above by name
    lib/lib<pkg>__rosidl_generator_py.so                 Python object <-> C struct conversions
    python/<pkg>/<pkg>_s__<typesupport>.<ext>            the extension modules rclpy imports

Each library links what it calls, finds it by its run path ($ORIGIN, the dependencies' lib
folders, the ROS tree's lib) and carries its own name as soname: the dispatch library dlopens its
type supports by bare name, which glibc answers with an already loaded library of that soname,
so the package's ``__init__`` loads them first and no LD_LIBRARY_PATH is needed.
"""
from __future__ import annotations

import subprocess
import sysconfig
from pathlib import Path

from composed_sim.interfaces.errors import InterfaceError
from composed_sim.interfaces.toolchain import Compilers, Toolchain

# (library, compiler, sources under the generated folder, what it links of its own package,
# what it links of each dependency, what of the ROS tree), in link order.
LIBRARIES = (
    ("rosidl_generator_c", "cc", ("c", "*.c"), (), ("rosidl_generator_c",), ("rosidl_runtime_c", "rcutils")),
    ("rosidl_typesupport_introspection_c", "cc", ("rosidl_typesupport_introspection_c", "*.c"),
     ("rosidl_generator_c",), ("rosidl_typesupport_introspection_c",),
     ("rosidl_typesupport_introspection_c", "rosidl_runtime_c", "rcutils")),
    ("rosidl_typesupport_fastrtps_c", "cxx", ("rosidl_typesupport_fastrtps_c", "*.cpp"),
     ("rosidl_generator_c",), ("rosidl_typesupport_fastrtps_c", "rosidl_generator_c"),
     ("rosidl_typesupport_fastrtps_c", "fastcdr", "rmw", "rosidl_runtime_c", "rcutils")),
    ("rosidl_typesupport_c", "cxx", ("rosidl_typesupport_c", "*.cpp"), ("rosidl_generator_c",), ("rosidl_typesupport_c",),
     ("rosidl_typesupport_c", "rcpputils", "rosidl_runtime_c", "rcutils")),
    ("rosidl_generator_py", "cc", ("py", "_*_s.c"), ("rosidl_generator_c", "rosidl_typesupport_c"),
     ("rosidl_generator_py", "rosidl_generator_c"), ("rosidl_runtime_c", "rcutils")),
)
EXTENSION_TYPESUPPORTS = ("rosidl_typesupport_c", "rosidl_typesupport_fastrtps_c", "rosidl_typesupport_introspection_c")
_FLAGS = ("-shared", "-fPIC", "-O2", "-w")    # -w: generated code; its warnings are not the user's


def compile_package(name: str, generated: Path, out: Path, deps: list[str], dep_prefixes: list[Path],
                    tools: Toolchain, compilers: Compilers) -> None:
    """Compile the sources generated under ``generated`` into ``out/lib`` and ``out/python/<name>``.
    ``deps``: the interface packages it uses; ``dep_prefixes``: built packages' folders (their
    ``include``, ``lib``) that some of those come from, besides the ROS tree."""
    lib = out / "lib"
    lib.mkdir(parents=True, exist_ok=True)
    includes = [generated / "c", *(generated / ts for ts in ("rosidl_typesupport_introspection_c",
                                                             "rosidl_typesupport_fastrtps_c"))]
    for prefix in dep_prefixes:
        includes += [prefix / "include", *sorted((prefix / "include").iterdir())]
    includes += [*tools.include_dirs(), compilers.python_include, compilers.numpy_include]
    lib_dirs = [lib, *(p / "lib" for p in dep_prefixes), tools.lib]
    search = [f"-I{d}" for d in includes] + [f"-L{d}" for d in lib_dirs]
    run_path = ["-Wl,-rpath,$ORIGIN", *(f"-Wl,-rpath,{d}" for d in lib_dirs[1:])]

    for library, compiler, (folder, pattern), own, per_dep, ros in LIBRARIES:
        sources = sorted((generated / folder).rglob(pattern))
        target = lib / f"lib{name}__{library}.so"
        links = [f"{name}__{x}" for x in own] + [f"{d}__{x}" for d in deps for x in per_dep] + list(ros)
        _run([compilers.cc if compiler == "cc" else compilers.cxx, *_FLAGS, f"-Wl,-soname,{target.name}", *search,
              *run_path, "-o", str(target), *map(str, sources), *(f"-l{x}" for x in links)], name, library)

    suffix = sysconfig.get_config_var("EXT_SUFFIX")
    package_dir = out / "python" / name
    for ts in EXTENSION_TYPESUPPORTS:
        source = generated / "py" / name / f"_{name}_s.ep.{ts}.c"
        links = [f"{name}__rosidl_generator_py", f"{name}__{ts}", f"{name}__rosidl_generator_c", "rosidl_runtime_c"]
        _run([compilers.cc, *_FLAGS, *search, "-Wl,-rpath,$ORIGIN/../../lib", *run_path[1:],
              "-o", str(package_dir / f"{name}_s__{ts}{suffix}"), str(source), *(f"-l{x}" for x in links)],
             name, f"{ts} extension module")


def _run(command: list[str], name: str, what: str) -> None:
    r = subprocess.run(command, capture_output=True, text=True)
    if r.returncode != 0:
        said = [line for line in (r.stderr or r.stdout).splitlines() if line.strip()]
        raise InterfaceError(f"package {name}: compiling its {what} failed ({Path(command[0]).name} exit "
                             f"{r.returncode}):\n  " + "\n  ".join(said[:8]))
