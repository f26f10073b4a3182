"""A user's ROS 2 interface packages (a folder with ``package.xml`` and ``msg/``, ``srv/``,
``action/`` files) built into importable Python messages without colcon or an apt ROS.

``activate(paths)`` builds each package (or finds its cached build) and makes it importable here
and in child processes; ``build_package(path)`` builds one and says where and whether it was cached.

The build uses the pip-installed rosidl toolchain, the same steps ``rosidl_generate_interfaces``
takes in CMake: ``.msg`` → ``.idl`` (rosidl_adapter) → type hashes, C structs, the C type supports
(dispatch, introspection, Fast DDS) and the Python module (rosidl generators) → shared libraries
compiled with the system's C and C++ compilers. Nothing here imports rclpy. See docs/interfaces.md.
"""
from composed_sim.interfaces.activate import activate
from composed_sim.interfaces.build import BuiltPackage, build_package
from composed_sim.interfaces.errors import InterfaceError
from composed_sim.interfaces.package import InterfacePackage, read_package

__all__ = ["activate", "build_package", "BuiltPackage", "InterfaceError", "InterfacePackage", "read_package"]
