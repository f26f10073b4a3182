"""An interface package as its author wrote it: its name (from package.xml) and its interface
files, and the hash of their contents that names its build."""
from __future__ import annotations

import hashlib
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path

from composed_sim.interfaces.errors import InterfaceError

KINDS = ("msg", "srv", "action")     # the folders rosidl reads, each with files of that suffix

_NAME = re.compile(r"[a-z][a-z0-9_]*")    # REP 144: what rosidl accepts as a package name


@dataclass(frozen=True)
class InterfacePackage:
    name: str
    root: Path                       # absolute
    files: tuple[str, ...]           # relative POSIX paths: 'msg/Opinion.msg', sorted

    def content_hash(self) -> str:
        """sha256 of package.xml and the interface files, names and bytes: what the build depends
        on in the package (a README or CMakeLists.txt changing does not rebuild)."""
        h = hashlib.sha256()
        for rel in ("package.xml",) + self.files:
            data = (self.root / rel).read_bytes()
            h.update(f"{rel}\0{len(data)}\0".encode())
            h.update(data)
        return h.hexdigest()


def read_package(path: str | Path) -> InterfacePackage:
    """The package in folder ``path``; InterfaceError naming the path if it is not one."""
    root = Path(path).expanduser().resolve()
    if not root.is_dir():
        raise InterfaceError(f"{root}: no such interface package folder")
    manifest = root / "package.xml"
    if not manifest.is_file():
        raise InterfaceError(f"{root}: not a ROS interface package (no package.xml)")
    try:
        name = (ET.parse(manifest).getroot().findtext("name") or "").strip()
    except ET.ParseError as e:
        raise InterfaceError(f"{manifest}: not readable XML: {e}") from None
    if not _NAME.fullmatch(name):
        raise InterfaceError(f"{manifest}: <name> must be a ROS package name (lower case letters, digits, "
                             f"underscores; got {name!r})")
    files = tuple(sorted(f"{kind}/{p.name}" for kind in KINDS if (root / kind).is_dir()
                         for p in (root / kind).glob(f"*.{kind}") if p.is_file()))
    if not files:
        raise InterfaceError(f"{root}: no interface files (msg/*.msg, srv/*.srv or action/*.action)")
    return InterfacePackage(name=name, root=root, files=files)
