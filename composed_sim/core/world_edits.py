"""World edits between ticks, for loop functions: move or add an object, change a floor shape
(recolour or move it), change a light.

An edit made between two ticks is seen by the physics and by every sensor of the next tick: the
simulation owns the physics, the floor and the lights in every host mode. ``sim.world`` follows
the edits (a new frozen World each time), so what reads the lights or the floor from it (the
light sensors) sees them too. Each function takes the ``Simulation`` (core/simulation.py, which
calls them: not imported here, to keep the two modules acyclic).
"""
from __future__ import annotations

import dataclasses
from typing import Optional

from composed_sim.devices.common.floor import Floor
from composed_sim.world.schema import Box, Cylinder, FloorCircle, FloorRectangle


def move_object(sim, index: int, position, yaw_rad: Optional[float] = None) -> None:
    """Put movable object ``index`` (in the world's order of movable obstacles) at rest at
    ``position``, keeping its yaw unless given."""
    movable = sim.physics.movable
    if not 0 <= index < len(movable):
        raise IndexError(f"movable object {index}: the world has {len(movable)} movable objects")
    _, yaws = sim.physics.movable_poses()
    sim.physics.place_movable(index, position, yaws[index] if yaw_rad is None else yaw_rad)


def add_object(sim, obstacle: Box | Cylinder) -> int:
    """Add a movable box or cylinder; returns its index among the movable objects."""
    if not isinstance(obstacle, (Box, Cylinder)) or not obstacle.movable:
        raise ValueError("add_object takes a movable Box or Cylinder (movable=True)")
    return sim.physics.add_movable(obstacle)


def set_floor_shape(sim, index: int, **changes) -> None:
    """Change fields of floor shape ``index`` (e.g. ``color=(0, 0, 0)``, ``position=(x, y)``)."""
    shapes = list(sim.world.floor.shapes)
    if not 0 <= index < len(shapes):
        raise IndexError(f"floor shape {index}: the floor has {len(shapes)} shapes")
    shapes[index] = type(shapes[index]).model_validate({**shapes[index].model_dump(), **changes})
    _set_floor_shapes(sim, shapes)


def add_floor_shape(sim, shape: FloorCircle | FloorRectangle) -> int:
    """Paint a shape on top of the floor; returns its index."""
    _set_floor_shapes(sim, [*sim.world.floor.shapes, shape])
    return len(sim.world.floor.shapes) - 1


def set_light(sim, index: int, **changes) -> None:
    """Change fields of light ``index`` (e.g. ``intensity=0`` to switch it off)."""
    lights = list(sim.world.lights)
    if not 0 <= index < len(lights):
        raise IndexError(f"light {index}: the world has {len(lights)} lights")
    lights[index] = type(lights[index]).model_validate({**lights[index].model_dump(), **changes})
    sim.world = sim.world.model_copy(update={"lights": lights})


def _set_floor_shapes(sim, shapes: list) -> None:
    floor = sim.world.floor.model_copy(update={"shapes": shapes})
    sim.world = sim.world.model_copy(update={"floor": floor})
    if sim.floor is not None:   # only a world whose robots read the floor samples it
        # The image (read once) stays; only the painted shapes change.
        shapes_only = Floor.from_world(floor.model_copy(update={"image": None}))
        sim.floor = dataclasses.replace(shapes_only, image=sim.floor.image)
