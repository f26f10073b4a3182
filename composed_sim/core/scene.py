"""The world's immovable bodies as the devices see them: a ``StaticScene`` of the arena walls and
the fixed obstacles (the movable ones are added at their pose of each tick, ``Simulation.current_scene``)."""
from __future__ import annotations

import numpy as np

from composed_sim.devices.common.geometry import StaticScene, box_corners
from composed_sim.world.schema import Box, Cylinder, World


def static_scene(world: World) -> StaticScene:
    boxes: list[np.ndarray] = []
    heights: list[float] = []
    arena = world.arena
    if arena.walls:
        if arena.size is None:
            raise ValueError("arena.walls is on but arena.size is None")
        # The walls the physics has (the schema owns their geometry: inside the arena
        # rectangle), so the sensors see them where the robots bump into them.
        for wall in arena.wall_boxes():
            boxes.append(box_corners(wall.position, wall.size, 0.0))
            heights.append(wall.height_m)
    fixed = [ob for ob in world.obstacles if not ob.movable]
    cyls = [ob for ob in fixed if isinstance(ob, Cylinder)]
    for ob in fixed:
        if isinstance(ob, Box):
            boxes.append(box_corners(ob.position, ob.size, ob.yaw_rad))
            heights.append(ob.height_m)
    return StaticScene(cyl_centres=np.array([ob.position for ob in cyls], dtype=float).reshape(-1, 2),
                       cyl_radii=np.array([ob.radius_m for ob in cyls], dtype=float),
                       cyl_heights=np.array([ob.height_m for ob in cyls], dtype=float),
                       box_corners=np.array(boxes, dtype=float).reshape(-1, 4, 2),
                       box_heights=np.array(heights, dtype=float))
