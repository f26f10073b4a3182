"""The ARGoS importer: the document and its <framework> and <physics_engines> sections; the
controllers and the arena are translated by the classes it builds on."""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Optional

from composed_sim.argos_import.controllers import ControllerChoice
from composed_sim.argos_import.entities import EntityTranslator
from composed_sim.argos_import.xml_reader import ArgosFileError, XmlElement
from composed_sim.core.seeding import STREAM_OBSTACLES, stream
from composed_sim.world.loader import WorldFileError
from composed_sim.world.schema import World


class ArgosImporter(EntityTranslator):
    def __init__(self, source: str, controller: ControllerChoice, ticks: Optional[int] = None):
        super().__init__(source, controller)
        self.ticks = ticks                      # --ticks, for the length warning

    def run(self, root: XmlElement) -> tuple[World, list[str]]:
        """(World, warnings); on failure the ArgosFileError carries the warnings collected so far."""
        try:
            world = self.document(root)
        except ArgosFileError as e:
            e.warnings = tuple(self.sorted_warnings())
            raise
        return world, self.sorted_warnings()

    def sorted_warnings(self) -> list[str]:
        return [text for _, text in sorted(dict.fromkeys(self.warnings), key=lambda w: w[0])]

    # -- document --

    def document(self, root: XmlElement) -> World:
        if root.tag != "argos-configuration":
            raise self.error(root, root.tag, "the root element of an ARGoS file must be "
                             "<argos-configuration>", root.tag)
        known = {"framework", "controllers", "loop_functions", "arena", "physics_engines", "media",
                 "visualization"}
        for child in root.children:
            if child.tag not in known:
                self.warn(child, child.tag, "unknown element, ignored")
        data: dict[str, Any] = {"name": _world_name(self.source)}
        framework = root.find("framework")
        if framework is None:
            raise self.error(root, "argos-configuration", "needs a <framework> with an <experiment>")
        data.update(self.framework(framework))
        controllers = root.find("controllers")
        if controllers is not None:
            self.read_controllers(controllers)
        loops = root.find("loop_functions")
        if loops is not None:
            self.warn(loops, "loop_functions", "ARGoS loop functions (C++ code) are not run (ours "
                      "are Python, named in a world file: docs/experiments.md)")
        engines = root.find("physics_engines")
        if engines is not None:
            data["physics"] = self.physics(engines)
        media = root.find("media")
        if media is not None:
            for medium in media.children:
                if medium.tag not in ("led", "range_and_bearing"):     # ours need no medium
                    self.warn(medium, f"media/{medium.tag}", "this medium is not simulated")
        arena = root.find("arena")
        if arena is None:
            raise self.error(root, "argos-configuration", "needs an <arena>")
        data.update(self.arena(arena, stream(data.get("seed", 0), STREAM_OBSTACLES)))
        if not any(g["count"] for g in data["robots"]):
            why = (" (its robots may come from the loop functions, which are not run)"
                   if loops is not None else "")
            raise self.error(arena, "arena", f"has no robot we simulate (foot-bot, e-puck or kheperaiv){why}")
        return self.validate(data)

    def validate(self, data: dict) -> World:
        from composed_sim.world import loader
        try:
            return loader.validate(data, self.source, self.lines)
        except ArgosFileError:
            raise
        except WorldFileError as e:
            raise ArgosFileError(str(e), e.problems) from None

    def framework(self, node: XmlElement) -> dict:
        out: dict[str, Any] = {}
        for child in node.children:
            if child.tag not in ("system", "experiment", "profiling"):
                self.warn(child, f"framework/{child.tag}", "unknown element, ignored")
        exp = node.find("experiment")
        if exp is None:
            raise self.error(node, "framework", "needs an <experiment length=.. ticks_per_second=..>")
        self.unknown(exp, {"length", "ticks_per_second", "random_seed"}, "experiment")
        tps = self.integer(exp, "ticks_per_second", low=1)
        if tps > 1000:
            raise self.error(exp, "experiment/ticks_per_second", "must be at most 1000", exp.attrib["ticks_per_second"])
        length_s = self.number(exp, "length", 0.0, low=0.0, unit=" (seconds)")
        ticks = math.floor(length_s * tps + 1e-9)
        for key in ("ticks_per_second", "length_ticks", "seed"):
            self.lines[(key,)] = exp.line
        out["ticks_per_second"] = tps
        if length_s == 0:
            default = World.model_fields["length_ticks"].default
            runs = (f"--ticks {self.ticks} are run" if self.ticks is not None
                    else f"{default} ticks are run (give --ticks to change it)")
            self.warn(exp, "experiment/length", f"0 (run until stopped) is not supported: {runs}")
        elif ticks < 1:
            raise self.error(exp, "experiment/length", f"is shorter than one tick (1/{tps} s)",
                             exp.attrib["length"])
        else:
            out["length_ticks"] = ticks
        seed = self.integer(exp, "random_seed", 0)
        if seed >= 2**32:
            raise self.error(exp, "experiment/random_seed", "must be below 2^32", seed)
        if seed == 0:
            self.warn(exp, "experiment/random_seed", "0 or missing: ARGoS would seed from the "
                      "clock; seed 0 is used (give --seed to change it)")
        out["seed"] = seed
        return out

    def physics(self, node: XmlElement) -> dict:
        out: dict[str, Any] = {}
        engines = [e for e in node.children if e.tag == "dynamics2d"]
        if len(engines) > 1:
            self.warn(engines[1], "physics_engines", f"{len(engines)} dynamics2d engines (each with "
                      "its <boundaries>) become one 2D space over the whole arena")
        for engine in node.children:
            if engine.tag != "dynamics2d":
                self.warn(engine, f"physics_engines/{engine.tag}", "only a dynamics2d engine is "
                          "simulated (as a 2D engine over the whole arena)")
                continue
            self.unknown(engine, {"id", "iterations"}, "dynamics2d")
            for child in engine.children:
                if child.tag != "boundaries":
                    self.warn(child, f"dynamics2d/{child.tag}", "not supported, ignored")
            if "iterations" in engine.attrib:
                steps = self.integer(engine, "iterations", low=1)
                if steps > 100:
                    raise self.error(engine, "dynamics2d/iterations", "must be at most 100", steps)
                out["substeps"] = steps
                self.lines[("physics",)] = engine.line
        return out


def _world_name(source: str) -> str:
    stem = Path(source).stem
    return stem if stem and not stem.startswith("<") else "argos"

