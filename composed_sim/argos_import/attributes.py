"""Reading ARGoS attributes (numbers, vectors, colours) with one error or warning naming the
file, line, element and attribute."""
from __future__ import annotations

import math
from typing import Any, Optional

from composed_sim.argos_import.xml_reader import ArgosFileError, XmlElement

# ARGoS's named colours (core/utility/datatypes/color.cpp).
_COLORS = {
    "black": (0, 0, 0), "white": (255, 255, 255), "red": (255, 0, 0), "green": (0, 255, 0),
    "blue": (0, 0, 255), "magenta": (255, 0, 255), "cyan": (0, 255, 255),
    "yellow": (255, 255, 0), "orange": (255, 140, 0), "brown": (160, 82, 45),
    "purple": (160, 32, 240), "gray10": (26, 26, 26), "gray20": (51, 51, 51),
    "gray30": (77, 77, 77), "gray40": (102, 102, 102), "gray50": (127, 127, 127),
    "gray60": (153, 153, 153), "gray70": (179, 179, 179), "gray80": (204, 204, 204),
    "gray90": (229, 229, 229),
}

class AttributeReader:
    """The messages and value parsers every section translator uses."""

    def __init__(self, source: str):
        self.source = source
        self.warnings: list[tuple[int, str]] = []   # (line, message)

    # -- messages --

    def error(self, node: XmlElement, what: str, message: str, value: Any = None) -> ArgosFileError:
        got = "" if value is None else f' (got "{value}")'
        return ArgosFileError(f"{self.source}:{node.line}: {what}: {message}{got}")

    def warn(self, node: XmlElement, what: str, message: str) -> None:
        self.warnings.append((node.line, f"{self.source}:{node.line}: {what}: {message}"))

    def unknown(self, node: XmlElement, known: set[str], what: Optional[str] = None,
                message: str = "not supported, ignored") -> None:
        """Warn about attributes of ``node`` outside ``known``."""
        for name in node.attrib:
            if name not in known:
                self.warn(node, f"{what or node.tag}/{name}", message)

    # -- values --

    def given(self, node: XmlElement, attr: str, *, required: bool) -> Optional[str]:
        """The attribute's text; None when it is absent and optional; an error when required."""
        value = node.attrib.get(attr)
        if value is None and required:
            raise self.error(node, f"{node.tag}/{attr}", "is required")
        return value

    def text(self, node: XmlElement, attr: str, default: Optional[str] = None) -> str:
        value = self.given(node, attr, required=default is None)
        return default if value is None else value

    def number(self, node: XmlElement, attr: str, default: Optional[float] = None, *,
               low: Optional[float] = None, positive: bool = False, unit: str = "") -> float:
        raw = self.given(node, attr, required=default is None)
        if raw is None:
            return default
        try:
            value = float(raw)
        except ValueError:
            value = math.nan
        kind = "a positive number" if positive else "a number"
        if not math.isfinite(value) or (positive and value <= 0) or (low is not None and value < low):
            need = f"a number >= {low:g}" if low is not None else kind
            raise self.error(node, f"{node.tag}/{attr}", f"must be {need}{unit}", raw)
        return value

    def integer(self, node: XmlElement, attr: str, default: Optional[int] = None, *, low: int = 0) -> int:
        raw = self.given(node, attr, required=default is None)
        if raw is None:
            return default
        try:
            value = int(raw.strip())
        except ValueError:
            raise self.error(node, f"{node.tag}/{attr}", f"must be a whole number >= {low}", raw) from None
        if value < low:
            raise self.error(node, f"{node.tag}/{attr}", f"must be a whole number >= {low}", raw)
        return value

    def vector(self, node: XmlElement, attr: str, default: Optional[tuple] = None, *,
               positive: bool = False, nonnegative: bool = False, unit: str = "") -> tuple[float, float, float]:
        raw = self.given(node, attr, required=default is None)
        if raw is None:
            return default
        parts = raw.split(",")
        try:
            values = tuple(float(p) for p in parts)
        except ValueError:
            values = ()
        sign = " positive" if positive else " non-negative" if nonnegative else ""
        if len(values) != 3 or not all(math.isfinite(v) for v in values) \
                or (positive and min(values) <= 0) or (nonnegative and min(values) < 0):
            raise self.error(node, f"{node.tag}/{attr}",
                             f'must be three{sign} numbers "x,y,z"{unit}', raw)
        return values

    def boolean(self, node: XmlElement, attr: str, default: bool) -> bool:
        raw = node.attrib.get(attr)
        if raw is None:
            return default
        value = raw.strip().lower()
        if value in ("true", "1"):
            return True
        if value in ("false", "0"):
            return False
        raise self.error(node, f"{node.tag}/{attr}", 'must be "true" or "false"', raw)

    def color(self, node: XmlElement, attr: str, default: tuple[int, int, int]) -> tuple[int, int, int]:
        raw = node.attrib.get(attr)
        if raw is None:
            return default
        if raw.strip() in _COLORS:
            return _COLORS[raw.strip()]
        try:
            values = [int(p) for p in raw.split(",")]
        except ValueError:
            values = []
        if len(values) not in (3, 4) or not all(0 <= v <= 255 for v in values):
            raise self.error(node, f"{node.tag}/{attr}", f'must be a colour name '
                             f'({", ".join(_COLORS)}) or "r,g,b[,a]" with values 0..255', raw)
        if len(values) == 4 and values[3] != 255:
            self.warn(node, f"{node.tag}/{attr}", "the alpha channel is not simulated, ignored")
        return tuple(values[:3])

