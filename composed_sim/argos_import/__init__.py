"""Import an ARGoS 3 experiment file (``.argos``) as a World.

``load_argos(path, controller=...)`` returns ``(world, warnings)``: the World to run and one line
per ARGoS element or attribute that the import does not simulate as written (the CLI prints them
as one warning, also when the import then fails). Problems that make the file unusable raise
``ArgosFileError``, one line each: ``file:line: element/attribute: what is wrong (got "value")``.

The package: ``xml_reader.py`` (safe XML, every element with its line), ``attributes.py`` (values
and messages), and one translator per section: ``controllers.py`` (plugins and their parameters),
``devices.py`` (sensors and actuators), ``entities.py`` (the arena, obstacles, lights, robots and
<distribute>, whose position and orientation generators are ``generators.py``), ``importer.py`` (the
document, <framework>, <physics_engines>). What maps to what, with units, is in docs/argos_import.md.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Optional

from composed_sim.argos_import.controllers import ControllerChoice
from composed_sim.argos_import.importer import ArgosImporter
from composed_sim.argos_import.xml_reader import ArgosFileError, XmlElement, parse_xml, read_file
from composed_sim.world.schema import World

__all__ = ["ArgosFileError", "XmlElement", "is_argos_file", "load_argos", "loads_argos", "parse_xml",
           "warning_text"]

ARGOS_SUFFIXES = (".argos",)


# --- public API ----------------------------------------------------------------------

def is_argos_file(path: str | os.PathLike) -> bool:
    """True for a path that names an ARGoS experiment file (by its suffix)."""
    return Path(path).suffix.lower() in ARGOS_SUFFIXES


def load_argos(path: str | os.PathLike, *, controller: ControllerChoice = None,
               ticks: Optional[int] = None) -> tuple[World, list[str]]:
    """Read an ARGoS experiment file → (World, warnings). ``ticks``: the run's --ticks, for the
    warnings. An ArgosFileError carries the warnings collected before it (``.warnings``)."""
    source = os.fspath(path)
    root = parse_xml(read_file(source), source)
    return ArgosImporter(source, controller, ticks).run(root)


def loads_argos(text: str | bytes, *, controller: ControllerChoice = None,
                source: str = "<argos>", ticks: Optional[int] = None) -> tuple[World, list[str]]:
    """``load_argos`` for a file's contents."""
    data = text.encode("utf-8") if isinstance(text, str) else text
    return ArgosImporter(source, controller, ticks).run(parse_xml(data, source))


def warning_text(source: str, warnings: list[str]) -> Optional[str]:
    """The one warning the CLI prints for an import's warnings (None when there are none)."""
    if not warnings:
        return None
    head = (f"{source}: {len(warnings)} ARGoS setting{'s' if len(warnings) != 1 else ''} "
            f"not simulated as written:")
    return head + "".join(f"\n  {w}" for w in warnings)


