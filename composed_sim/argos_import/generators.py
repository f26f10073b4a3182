"""ARGoS's position and orientation generators (``uniform``, ``gaussian``, ``constant``, ``grid``),
the ``<position>`` and ``<orientation>`` of a ``<distribute>`` block: read as the world's placement and
heading fields for distributed robots (drawn when the run starts), and drawn here, once, for
distributed obstacles and lights (entities.py)."""
from __future__ import annotations

import math

import numpy as np

from composed_sim.argos_import.attributes import AttributeReader
from composed_sim.argos_import.xml_reader import XmlElement

_TINY_M = 1e-6      # stands for a zero extent where the schema needs a positive one


class GeneratorReader(AttributeReader):
    """The generators as world fields (``placement``, ``heading``) and as draws (``draw_position``,
    ``draw_yaw``)."""

    def placement(self, node: XmlElement, count: int, max_trials: int) -> dict:
        method = self.text(node, "method")
        what = "position"
        if method == "uniform":
            self.unknown(node, {"method", "min", "max"}, what)
            lo, hi = self.vector(node, "min", unit=" in m"), self.vector(node, "max", unit=" in m")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "position/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            self.planar(node, lo[2], hi[2])
            sx, sy = hi[0] - lo[0], hi[1] - lo[1]
            if min(sx, sy) == 0 and count > 0:
                self.warn(node, "position", "a zero-width range: placed on a line (as ARGoS)")
            return {"method": "uniform", "center": [(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2],
                    "size": [max(sx, _TINY_M), max(sy, _TINY_M)], "max_trials": max_trials}
        if method == "gaussian":
            self.unknown(node, {"method", "mean", "std_dev"}, what)
            mean = self.vector(node, "mean", unit=" in m")
            std = self.vector(node, "std_dev", nonnegative=True, unit=" in m")
            self.planar(node, mean[2], mean[2] + std[2])
            s = std[0]
            if std[0] != std[1]:
                s = math.sqrt(std[0] * std[1])
                self.warn(node, "position/std_dev", f"different x and y spreads: one std of "
                          f"{s:.4g} m (their geometric mean) is used")
            return {"method": "gaussian", "center": [mean[0], mean[1]], "std_m": max(s, _TINY_M),
                    "max_trials": max_trials}
        if method == "constant":
            self.unknown(node, {"method", "values"}, what)
            x, y, z = self.vector(node, "values", unit=" in m")
            self.planar(node, z, z)
            if count > 1:
                raise self.error(node, "position/values", f"{count} robots at one constant position "
                                 "can never be placed without overlap (ARGoS fails too)",
                                 node.attrib["values"])
            return {"method": "explicit", "positions": [[x, y]] * count}
        if method == "grid":
            return {"method": "explicit", "positions": [[x, y] for x, y, _ in self.grid(node, count)]}
        raise self.error(node, "position/method", "must be uniform, gaussian, constant or grid", method)

    def grid(self, node: XmlElement, count: int) -> list[tuple[float, float, float]]:
        """ARGoS's GridGenerator: the i-th value, exactly as ARGoS computes it."""
        self.unknown(node, {"method", "center", "distances", "layout"}, node.tag)
        center = self.vector(node, "center")
        dist = self.vector(node, "distances")
        raw = self.text(node, "layout")
        try:
            layout = [int(v) for v in raw.split(",")]
        except ValueError:
            layout = []
        if len(layout) != 3 or min(layout) < 1:
            raise self.error(node, f"{node.tag}/layout", 'must be three whole numbers >= 1 "nx,ny,nz"', raw)
        nx, ny, nz = layout
        if count > nx * ny * nz:
            raise self.error(node, f"{node.tag}/layout", f"holds {nx * ny * nz} entities, fewer than "
                             f"the quantity {count}", raw)
        if node.tag == "position" and count > nx * ny:
            raise self.error(node, "position/layout", "more than one layer (nz > 1) would stack "
                             "robots on top of each other; the simulation is planar", raw)
        out = []
        for i in range(count):
            out.append((center[0] + (nx - 1) * dist[0] * 0.5 - (i % nx) * dist[0],
                        center[1] + (ny - 1) * dist[1] * 0.5 - (i // nx) % ny * dist[1],
                        center[2] + (nz - 1) * dist[2] * 0.5 - (i // (nx * ny)) * dist[2]))
        return out

    def planar(self, node: XmlElement, z_lo: float, z_hi: float) -> None:
        if z_lo != 0 or z_hi != 0:
            self.warn(node, f"{node.tag}", "z is not simulated (planar): placed on the floor")

    def heading(self, node: XmlElement) -> dict:
        method = self.text(node, "method")
        if method == "constant":
            self.unknown(node, {"method", "values"}, "orientation")
            yaw, pitch, roll = self.vector(node, "values", unit=" in degrees")
            self.flat(node, pitch, roll)
            return {"method": "constant", "value_rad": math.radians(yaw)}
        if method == "gaussian":
            self.unknown(node, {"method", "mean", "std_dev"}, "orientation")
            mean = self.vector(node, "mean", unit=" in degrees")
            std = self.vector(node, "std_dev", nonnegative=True, unit=" in degrees")
            self.flat(node, mean[1] or std[1], mean[2] or std[2])
            return {"method": "gaussian", "value_rad": math.radians(mean[0]),
                    "std_rad": math.radians(std[0])}
        if method == "uniform":
            self.unknown(node, {"method", "min", "max"}, "orientation")
            lo, hi = self.vector(node, "min", unit=" in degrees"), self.vector(node, "max", unit=" in degrees")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "orientation/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            self.flat(node, lo[1] or hi[1], lo[2] or hi[2])
            span = hi[0] - lo[0]
            if span >= 360:
                return {"method": "uniform"}
            if span == 0:
                return {"method": "constant", "value_rad": math.radians(lo[0])}
            return {"method": "uniform", "range_rad": [math.radians(lo[0]), math.radians(hi[0])]}
        if method == "grid":
            self.grid(node, 0)
            self.warn(node, "orientation/method", "grid orientations are not supported: every "
                      "robot gets the grid's center yaw")
            return {"method": "constant", "value_rad": math.radians(self.vector(node, "center")[0])}
        raise self.error(node, "orientation/method", "must be uniform, gaussian, constant or grid", method)

    def flat(self, node: XmlElement, pitch: float, roll: float) -> None:
        if pitch or roll:
            self.warn(node, "orientation", "pitch and roll are not simulated; only the yaw is used")

    def draw_position(self, node: XmlElement, rng: np.random.Generator) -> tuple[float, float, float]:
        method = self.text(node, "method")
        if method == "uniform":
            lo, hi = self.vector(node, "min"), self.vector(node, "max")
            if any(a > b for a, b in zip(lo, hi)):
                raise self.error(node, "position/min", "must not exceed max in any coordinate",
                                 node.attrib["min"])
            return tuple(float(rng.uniform(a, b)) for a, b in zip(lo, hi))
        if method == "gaussian":
            mean, std = self.vector(node, "mean"), self.vector(node, "std_dev", nonnegative=True)
            return tuple(float(rng.normal(m, d)) for m, d in zip(mean, std))
        if method == "constant":
            return self.vector(node, "values")
        raise self.error(node, "position/method", "must be uniform, gaussian, constant or grid", method)


def draw_yaw(spec: dict, rng: np.random.Generator) -> float:
    """A yaw (rad) drawn from a ``heading`` field."""
    if spec["method"] == "constant":
        return spec["value_rad"]
    if spec["method"] == "gaussian":
        return float(rng.normal(spec["value_rad"], spec["std_rad"]))
    low, high = spec.get("range_rad", (-math.pi, math.pi))
    return float(rng.uniform(low, high))
