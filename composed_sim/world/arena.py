"""The world file's arena: its size and walls, lights, boxes and cylinders, the floor, the
range-and-bearing medium (world/schema.py holds the whole world)."""
from __future__ import annotations

from typing import Annotated, Literal, Optional, Union

from pydantic import Field, model_validator

from composed_sim.devices.common.settings import NonNegativeFloat, PositiveFloat, Strict
from composed_sim.world.validation import RGB, Vec2, invalid


class Arena(Strict):
    center: Vec2 = (0.0, 0.0)
    # Arena side lengths in metres. Required when walls are on; without walls it only
    # bounds where lights may stand (None = unbounded). The walls stand inside this
    # rectangle (outer faces on its edge): see inner_bounds() and wall_boxes().
    size: Optional[tuple[PositiveFloat, PositiveFloat]] = None
    walls: bool = False
    wall_thickness_m: PositiveFloat = 0.1
    wall_height_m: PositiveFloat = 0.5

    @model_validator(mode="after")
    def _walls_need_size(self) -> Arena:
        if self.walls and self.size is None:
            raise invalid([(("walls",), "walls need arena.size (the side lengths in m)", True)])
        if self.walls and 2 * self.wall_thickness_m >= min(self.size):
            raise invalid([(("wall_thickness_m",), f"two walls must fit in the arena size "
                             f"{list(self.size)}", self.wall_thickness_m)])
        return self

    def contains(self, x: float, y: float) -> bool:
        """True when (x, y) is inside the arena rectangle (always, when size is None)."""
        if self.size is None:
            return True
        return (abs(x - self.center[0]) <= self.size[0] / 2
                and abs(y - self.center[1]) <= self.size[1] / 2)

    def inner_bounds(self) -> Optional[tuple[float, float, float, float]]:
        """(x_min, y_min, x_max, y_max) of the floor inside the walls; None without walls."""
        if not self.walls:
            return None
        hx = self.size[0] / 2 - self.wall_thickness_m
        hy = self.size[1] / 2 - self.wall_thickness_m
        cx, cy = self.center
        return (cx - hx, cy - hy, cx + hx, cy + hy)

    def wall_boxes(self) -> list[Box]:
        """The four walls as static boxes (east, west, north, south); [] without walls."""
        if not self.walls:
            return []
        (cx, cy), (sx, sy), t = self.center, self.size, self.wall_thickness_m
        h = self.wall_height_m
        return [Box(position=(cx + (sx - t) / 2, cy), size=(t, sy), height_m=h),
                Box(position=(cx - (sx - t) / 2, cy), size=(t, sy), height_m=h),
                Box(position=(cx, cy + (sy - t) / 2), size=(sx, t), height_m=h),
                Box(position=(cx, cy - (sy - t) / 2), size=(sx, t), height_m=h)]


class Light(Strict):
    position: Vec2
    height_m: NonNegativeFloat = 0.5
    intensity: NonNegativeFloat = 1.0
    color: RGB = (255, 255, 0)


class Box(Strict):
    type: Literal["box"] = "box"
    position: Vec2
    size: tuple[PositiveFloat, PositiveFloat]   # along its own x and y
    height_m: PositiveFloat = 0.5
    yaw_rad: float = 0.0
    # A movable body is pushed by robots and held back by ground friction (ARGoS dynamics2d);
    # its mass only matters when it moves.
    movable: bool = False
    mass_kg: PositiveFloat = 1.0


class Cylinder(Strict):
    type: Literal["cylinder"] = "cylinder"
    position: Vec2
    radius_m: PositiveFloat
    height_m: PositiveFloat = 0.5
    movable: bool = False
    mass_kg: PositiveFloat = 1.0


Obstacle = Annotated[Union[Box, Cylinder], Field(discriminator="type")]


class FloorCircle(Strict):
    type: Literal["circle"] = "circle"
    position: Vec2
    radius_m: PositiveFloat
    color: RGB


class FloorRectangle(Strict):
    type: Literal["rectangle"] = "rectangle"
    position: Vec2
    size: tuple[PositiveFloat, PositiveFloat]   # along its own x and y
    yaw_rad: float = 0.0
    color: RGB


FloorShape = Annotated[Union[FloorCircle, FloorRectangle], Field(discriminator="type")]


class Floor(Strict):
    """What the ground sensors read: a colour, an image stretched over a rectangle, shapes on top."""
    color: RGB = (255, 255, 255)
    # An image file (PNG, JPEG, ...; read with imageio). A relative path is relative to the
    # world file; the loader makes it absolute and checks that it is a readable image.
    image: Optional[str] = None
    image_size_m: Optional[tuple[PositiveFloat, PositiveFloat]] = None   # None: the arena's size
    image_center: Vec2 = (0.0, 0.0)
    shapes: list[FloorShape] = []               # painted in this order, over the image


class RangeAndBearingMedium(Strict):
    """How range-and-bearing messages travel between the robots whose device is on."""
    # local: within the sender's range and line of sight; global: everyone hears everyone.
    mode: Literal["local", "global"] = "local"
    payload_bytes: Annotated[int, Field(ge=1, le=65535)] = 10   # docs/architecture.md: 10 by default
    check_occlusions: bool = True
