"""Loop functions, the ARGoS concept: per-experiment Python code run by the tick loop.

ROS-free. A world names its loop functions (``loop_functions: {name, params, every_ticks}``); the
name is an entry point of the group ``composed_sim.loop_functions`` whose class is made with
``params`` as keyword arguments. Every hook is optional (``LoopFunctions`` gives them all, doing
nothing):

- ``init(world, sim)``: once, before tick 0 is sensed (a world edit made here is seen at tick 0);
- ``pre_step(sim)``: each tick, once the controllers' commands are in, before the physics step;
- ``post_step(sim)``: each tick, after the step and its sensing (``sim.frame``: the readings the
  controllers get next); a world edit here is seen by the physics and the sensors of the next tick;
- ``is_finished(sim) -> bool``: after ``post_step``; true ends the run as a normal end;
- ``metrics(sim) -> dict``: at tick 0 and every ``every_ticks`` ticks (and at the last tick), one
  row of ``metrics.csv`` each; the last row is the run's final metrics in summary.json;
- ``describe(initial, final) -> list[str]`` (a static method): lines for the run's printed summary.

The world edits go through the simulation (``sim.move_object``, ``sim.add_object``,
``sim.set_floor_shape``, ``sim.add_floor_shape``, ``sim.set_light``; core/world_edits.py), read
state from ``sim.positions``, ``sim.headings``, ``sim.led_colors``, ``sim.frame``. The
controllers never see the loop functions: they are ROS nodes and only get their readings.
"""
from __future__ import annotations

from typing import Any, Callable, Optional

from composed_sim import entry_points

from composed_sim.core.simulation import Simulation
from composed_sim.world.schema import LOOP_FUNCTIONS_GROUP, World

GROUP = LOOP_FUNCTIONS_GROUP


class LoopFunctionsError(Exception):
    """Loop functions that cannot be loaded or made; ``field`` is the world file's field."""

    def __init__(self, message: str, field: tuple = ("loop_functions",)):
        super().__init__(message)
        self.field = field


class LoopFunctions:
    """A base class with every hook, each doing nothing; subclassing it is optional."""

    def init(self, world: World, sim: Simulation) -> None: ...
    def pre_step(self, sim: Simulation) -> None: ...
    def post_step(self, sim: Simulation) -> None: ...

    def is_finished(self, sim: Simulation) -> bool:
        return False

    def metrics(self, sim: Simulation) -> dict:
        return {}

    @staticmethod
    def describe(initial: dict, final: dict) -> list[str]:
        """Default: the final metrics, one line."""
        if not final:
            return []
        return ["  metrics: " + ", ".join(f"{k} {v:.3g}" if isinstance(v, float) else f"{k} {v}"
                                          for k, v in final.items() if k != "tick")]


def load_class(name: str) -> type:
    return entry_points.load(GROUP, name, "loop functions",
                             lambda message: LoopFunctionsError(message, ("loop_functions", "name")))


def make(world: World):
    """The world's loop functions object, or None; a bad parameter is a LoopFunctionsError."""
    ref = world.loop_functions
    if ref is None:
        return None
    cls = load_class(ref.name)
    params = checked_params(cls, ref.name, ref.params)
    try:
        return cls(**params)
    except (TypeError, ValueError) as e:      # an unknown or missing keyword, a value the class refuses
        raise LoopFunctionsError(f"loop functions {ref.name!r}: {e}", ("loop_functions", "params")) from e


def checked_params(cls: type, name: str, params: dict) -> dict:
    """``params`` checked against the constructor's signature, as the world's own fields are
    (pydantic): each annotated parameter's type, every number finite, no keyword the constructor
    lacks; the values as pydantic made them. A LoopFunctionsError names the first bad field."""
    import inspect

    import pydantic
    fields = {}
    for p in list(inspect.signature(cls.__init__, eval_str=True).parameters.values())[1:]:
        if p.kind in (p.VAR_POSITIONAL, p.VAR_KEYWORD):
            return params                     # **kwargs: the class takes what it is given
        annotation = Any if p.annotation is p.empty else p.annotation
        fields[p.name] = (annotation, ... if p.default is p.empty else p.default)
    model = pydantic.create_model(f"{cls.__name__}Params", __config__=pydantic.ConfigDict(
        extra="forbid", allow_inf_nan=False, arbitrary_types_allowed=True), **fields)
    try:
        made = model(**params)
    except pydantic.ValidationError as e:
        error = e.errors()[0]
        where = tuple(str(part) for part in error["loc"])
        value = f" (got {error['input']!r})" if error["type"] != "missing" else ""
        said = f"not a parameter of theirs (they take: {', '.join(fields) or 'none'})" \
            if error["type"] == "extra_forbidden" else f"{error['msg']}{value}"
        raise LoopFunctionsError(f"loop functions {name!r}: {'.'.join(where)}: {said}",
                                 ("loop_functions", "params", *where[:1])) from None
    return {key: getattr(made, key) for key in params}


def describe(world: World, initial: dict, final: dict) -> list[str]:
    """The loop functions' lines for a run's printed summary (none without loop functions)."""
    if world.loop_functions is None:
        return []
    cls = load_class(world.loop_functions.name)
    return getattr(cls, "describe", LoopFunctions.describe)(initial, final)


class LoopHooks:
    """What the tick loop (hosts/tick_loop.py) calls: the world's loop functions, if any, with
    their metric rows and whether they ended the run."""

    def __init__(self, sim: Simulation):
        self.functions = make(sim.world)
        self.every = sim.world.loop_functions.every_ticks if self.functions is not None else 1
        self.rows: list[dict] = []
        # Where each row goes as it is taken (a results stream); then ``rows`` keeps only the
        # first and the last, so that memory does not grow with the ticks.
        self.rows_to: Optional[Callable[[dict], None]] = None
        self.finished = False        # is_finished() said so

    def _call(self, hook: str, *args):
        fn = getattr(self.functions, hook, None)
        return None if fn is None else fn(*args)

    def start(self, sim: Simulation) -> None:
        if self.functions is not None:
            self._call("init", sim.world, sim)

    def at_tick_0(self, sim: Simulation) -> None:
        self._take_metrics(sim)

    def pre_step(self, sim: Simulation) -> None:
        if self.functions is not None:
            self._call("pre_step", sim)

    def post_step(self, sim: Simulation) -> bool:
        """After a step; true: the loop functions ended the run."""
        if self.functions is None:
            return False
        self._call("post_step", sim)
        self.finished = bool(self._call("is_finished", sim))
        if sim.tick % self.every == 0 or self.finished:
            self._take_metrics(sim)
        return self.finished

    def end(self, sim: Simulation) -> None:
        """The run's last tick has a row (the final metrics), whatever ``every_ticks``."""
        if self.functions is not None and (not self.rows or self.rows[-1]["tick"] != sim.tick):
            self._take_metrics(sim)

    def _take_metrics(self, sim: Simulation) -> None:
        values = self._call("metrics", sim) if self.functions is not None else None
        if values:
            row = {"tick": sim.tick, **{k: _plain(v) for k, v in values.items()}}
            if self.rows_to is not None:
                self.rows_to(row)
                del self.rows[1:]
            self.rows.append(row)

    @property
    def final(self) -> Optional[dict]:
        return self.rows[-1] if self.rows else None


def _plain(value):
    """numpy scalars as Python numbers (for JSON and CSV)."""
    return value.item() if hasattr(value, "item") else value
