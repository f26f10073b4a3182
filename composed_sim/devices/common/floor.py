"""The floor's grey level, and the motor ground sensors that read it.

ARGoS (docs/architecture.md, "Motor ground sensor"): a reading is the floor's colour under the
sensor as grey, 0.299 R + 0.587 G + 0.114 B over 255, plus optional uniform noise, clamped to
[0, 1]. The floor is a base colour, optionally an image stretched over a rectangle, and simple
coloured shapes painted on top in the world file's order.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

# ITU-R BT.601 luma weights, as ARGoS's CColor::ToGrayScale.
_LUMA = np.array([0.299, 0.587, 0.114])


def grey_of(rgb) -> np.ndarray:
    """[..., 3] 0-255 colours → [...] grey level in [0, 1]."""
    return np.asarray(rgb, dtype=np.float64) @ _LUMA / 255.0


@dataclass(frozen=True)
class FloorImage:
    grey: np.ndarray            # [rows, cols] in [0, 1]; row 0 is the image's top (+y edge)
    center: tuple[float, float]
    size_m: tuple[float, float]  # (x extent, y extent) the image is stretched over

    @classmethod
    def read(cls, path: str, center, size_m) -> "FloorImage":
        import imageio.v3 as iio   # only worlds with an image floor pay for the import
        pixels = np.asarray(iio.imread(path))
        if pixels.ndim == 2:                       # already grey, 0-255
            grey = pixels.astype(np.float64) / 255.0
        elif pixels.ndim == 3 and pixels.shape[2] in (3, 4):
            grey = grey_of(pixels[..., :3])        # alpha ignored, as ARGoS's floor does
        else:
            raise ValueError(f"{path}: not a grey or RGB(A) image (shape {pixels.shape})")
        if pixels.dtype == np.uint16:
            grey = grey / 257.0
        return cls(grey=grey, center=tuple(center), size_m=tuple(size_m))

    def sample(self, points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """points [m, 2] → (inside [m] bool, grey [m]) with the nearest pixel's grey."""
        rows, cols = self.grey.shape
        u = (points[:, 0] - self.center[0]) / self.size_m[0] + 0.5      # 0 at the -x edge
        v = 0.5 - (points[:, 1] - self.center[1]) / self.size_m[1]      # 0 at the +y edge (top row)
        inside = (u >= 0.0) & (u < 1.0) & (v >= 0.0) & (v < 1.0)
        col = np.clip((u * cols).astype(np.intp), 0, cols - 1)
        row = np.clip((v * rows).astype(np.intp), 0, rows - 1)
        return inside, self.grey[row, col]


@dataclass(frozen=True)
class Floor:
    """Grey level as a function of (x, y): base, then the image, then the shapes in order."""
    base_grey: float = 1.0
    image: Optional[FloorImage] = None
    # Shapes as arrays so that sampling is one vectorised test per shape.
    circle_centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))   # [c, 2]
    circle_radii: np.ndarray = field(default_factory=lambda: np.zeros(0))          # [c]
    rect_centres: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))     # [b, 2]
    rect_half_sizes: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # [b, 2] own axes
    rect_yaws: np.ndarray = field(default_factory=lambda: np.zeros(0))             # [b]
    # Painting order over both kinds: ("circle" | "rect", index, grey).
    paint: tuple[tuple[str, int, float], ...] = ()

    @classmethod
    def from_world(cls, floor, *, arena_size=None, base_dir: str = ".") -> "Floor":
        """From a schema ``Floor`` section; a relative image path is read from ``base_dir``, and
        an image without ``image_size_m`` is stretched over ``arena_size``."""
        import os
        image = None
        if floor.image is not None:
            path = floor.image if os.path.isabs(floor.image) else os.path.join(base_dir, floor.image)
            size = floor.image_size_m or arena_size
            if size is None:
                raise ValueError("an image floor needs floor.image_size_m or arena.size")
            image = FloorImage.read(path, floor.image_center, size)
        circles, rects, paint = [], [], []
        for shape in floor.shapes:
            if shape.type == "circle":
                paint.append(("circle", len(circles), float(grey_of(shape.color))))
                circles.append(shape)
            else:
                paint.append(("rect", len(rects), float(grey_of(shape.color))))
                rects.append(shape)
        return cls(base_grey=float(grey_of(floor.color)), image=image,
                   circle_centres=np.array([c.position for c in circles], float).reshape(-1, 2),
                   circle_radii=np.array([c.radius_m for c in circles], float),
                   rect_centres=np.array([r.position for r in rects], float).reshape(-1, 2),
                   rect_half_sizes=np.array([r.size for r in rects], float).reshape(-1, 2) / 2.0,
                   rect_yaws=np.array([r.yaw_rad for r in rects], float),
                   paint=tuple(paint))

    def grey(self, points: np.ndarray) -> np.ndarray:
        """points [..., 2] world frame → [...] grey level in [0, 1]."""
        points = np.asarray(points, dtype=np.float64)
        flat = points.reshape(-1, 2)
        out = np.full(len(flat), self.base_grey)
        if self.image is not None:
            inside, grey = self.image.sample(flat)
            out[inside] = grey[inside]
        for kind, i, level in self.paint:
            if kind == "circle":
                d = flat - self.circle_centres[i]
                hit = d[:, 0] ** 2 + d[:, 1] ** 2 <= self.circle_radii[i] ** 2
            else:
                d = flat - self.rect_centres[i]
                c, s = math.cos(self.rect_yaws[i]), math.sin(self.rect_yaws[i])
                hx, hy = self.rect_half_sizes[i]
                hit = (np.abs(c * d[:, 0] + s * d[:, 1]) <= hx) & (np.abs(-s * d[:, 0] + c * d[:, 1]) <= hy)
            out[hit] = level
        return out.reshape(points.shape[:-1])


# What a robot's ground sensors say it stands on (foraging: loop functions and controllers both
# decide from the same readings with this one rule, as ARGoS's foraging example does).
FLOOR, NEST, FOOD = 0, 1, 2


def ground_zone(readings: np.ndarray, food_below: float = 0.25, nest_below: float = 0.75) -> np.ndarray:
    """readings [..., s] grey levels of each robot's sensors → [...] FOOD where a sensor reads
    darker than ``food_below``, else NEST where one reads darker than ``nest_below``, else FLOOR."""
    darkest = np.min(readings, axis=-1)
    return np.where(darkest < food_below, FOOD, np.where(darkest < nest_below, NEST, FLOOR))


def body_points(positions: np.ndarray, headings: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """positions [n, 2], headings [n], offsets [k, 2] body frame → [n, k, 2] world points."""
    c, s = np.cos(headings)[:, None], np.sin(headings)[:, None]
    ox, oy = offsets[None, :, 0], offsets[None, :, 1]
    return np.stack([positions[:, 0:1] + c * ox - s * oy, positions[:, 1:2] + s * ox + c * oy], axis=-1)
