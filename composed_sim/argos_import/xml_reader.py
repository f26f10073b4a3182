"""The XML reader of the ARGoS importer: expat, no DTD, every element with its line.

No DTD is accepted (a DOCTYPE is an error), so no entity can be declared or expanded (no "billion
laughs", no external entities), and every element keeps its line for the messages.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Optional
from xml.parsers import expat

from composed_sim.world.loader import WorldFileError, read_file as read_world_file


class ArgosFileError(WorldFileError):
    """An ARGoS file that cannot be imported; ``problems`` holds one
    ``file:line: element/attribute: message (got "value")`` per problem; ``warnings`` what the
    import noticed before it failed (the CLI prints them after the reason)."""
    warnings: tuple[str, ...] = ()


@dataclass
class XmlElement:
    """One XML element: its tag, attributes, line in the file and child elements."""
    tag: str
    attrib: dict[str, str]
    line: int
    children: list["XmlElement"] = field(default_factory=list)

    def find(self, tag: str) -> Optional["XmlElement"]:
        return next((c for c in self.children if c.tag == tag), None)

    def findall(self, tag: str) -> list["XmlElement"]:
        return [c for c in self.children if c.tag == tag]


class _Forbidden(Exception):
    def __init__(self, line: int, what: str):
        super().__init__(what)
        self.line, self.what = line, what


def parse_xml(data: bytes, source: str) -> XmlElement:
    """Parse XML into Nodes with line numbers; DTDs (and so entity declarations) are refused."""
    parser = expat.ParserCreate()
    parser.SetParamEntityParsing(expat.XML_PARAM_ENTITY_PARSING_NEVER)
    stack: list[XmlElement] = []
    roots: list[XmlElement] = []

    def forbid(what: str):
        def handler(*_args):
            raise _Forbidden(parser.CurrentLineNumber, what)
        return handler

    def start(tag: str, attrib: dict[str, str]) -> None:
        node = XmlElement(tag, dict(attrib), parser.CurrentLineNumber)
        (stack[-1].children if stack else roots).append(node)
        stack.append(node)

    def end(_tag: str) -> None:
        stack.pop()

    parser.StartDoctypeDeclHandler = forbid("a DOCTYPE (DTD) is not accepted in an ARGoS file")
    parser.EntityDeclHandler = forbid("entity declarations are not accepted")
    parser.ExternalEntityRefHandler = forbid("external entities are not accepted")
    parser.StartElementHandler = start
    parser.EndElementHandler = end
    try:
        parser.Parse(data, True)
    except _Forbidden as e:
        raise ArgosFileError(f"{source}:{e.line}: unsafe XML: {e.what}") from None
    except expat.ExpatError as e:
        raise ArgosFileError(f"{source}:{e.lineno}: not well-formed XML: "
                             f"{expat.ErrorString(e.code)} (column {e.offset + 1})") from None
    if not roots:
        raise ArgosFileError(f"{source}: no XML element in the file")
    return roots[0]


def read_file(source: str) -> bytes:
    return read_world_file(source, "ARGoS file", ArgosFileError, binary=True)
