"""Camera: the omnidirectional coloured-blob camera, ARGoS's
``colored_blob_omnidirectional_camera_rotzonly_sensor.cpp`` (docs/architecture.md, "Blob camera and
LEDs"), over all robots at once.

``/<r>/blobs``, sensor_msgs/PointCloud2 in base_link: one point per blob, x/y of the seen LED (m;
z = 0, the camera is planar), rgb = 0x00RRGGBB (uint32). A controller's Tick: ``blobs``, a ``Blobs``
(bearing, distance, colour per blob). The LEDs it sees are the robot models' (``led_positions_m``);
the window's aperture is a robot group's ``camera.aperture_deg`` in the world file.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable, Optional, Sequence

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common import cdr_clouds
from composed_sim.devices.common.device import Device, DevicePublisher, csr_take, reads_cloud_into
from composed_sim.devices.common.geometry import StaticScene
from composed_sim.devices.common.noise import entry_noise
from composed_sim.devices.common.poses import wrap_angle
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import (_check_noise, _observer_rows, _pair_order, _ranges, kd_tree, near_pairs,
                                                 _robots, blocked_by_robots)
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import Topic, base_link

NAME = "camera"


@dataclass(frozen=True)
class BlobCamera:
    """Omnidirectional coloured-blob camera looking down a mirror above the body."""
    height_m: float
    aperture_rad: float   # the square window's half-side is height * tan(aperture)


class BlobCameraConfig(DeviceSwitch):
    noise_std: NonNegativeFloat = 0.0    # relative planar position noise (ARGoS)


# Camera work per chunk, in (observer, lit LED) candidates; ~15 float64 temporaries each, so
# about 150 MB of them, plus the occlusion walk's samples.
_BLOB_CHUNK = 1 << 20


@dataclass
class BlobReadings:
    """Every robot's blobs, CSR by robot: robot i's are rows offsets[i]:offsets[i+1]."""
    offsets: np.ndarray    # [n+1] int64
    angles: np.ndarray     # [m] bearing relative to the observer's heading, (-pi, pi]
    distances: np.ndarray  # [m] planar, m, from the observer's centre to the LED
    colors: np.ndarray     # [m, 3] uint8 RGB

    def of(self, i: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(angles [b], distances [b], colors [b, 3]) of robot i's blobs."""
        s = slice(self.offsets[i], self.offsets[i + 1])
        return self.angles[s], self.distances[s], self.colors[s]

    @classmethod
    def empty(cls, n: int) -> "BlobReadings":
        return cls(offsets=np.zeros(n + 1, dtype=np.int64), angles=np.zeros(0), distances=np.zeros(0),
                   colors=np.zeros((0, 3), dtype=np.uint8))


def led_world_positions(positions: np.ndarray, headings: np.ndarray, led_body: np.ndarray) -> np.ndarray:
    """positions [n, 2], headings [n], led_body [L, 3] body-frame → [n, L, 3] world-frame LEDs."""
    positions = np.asarray(positions, dtype=np.float64)
    led_body = np.asarray(led_body, dtype=np.float64).reshape(-1, 3)
    n, n_leds = len(positions), len(led_body)
    robots, leds = np.repeat(np.arange(n), n_leds), np.tile(np.arange(n_leds), n)
    return leds_at(positions, headings, led_body[None], robots, leds).reshape(n, n_leds, 3)


def leds_at(positions: np.ndarray, headings: np.ndarray, led_bodies: np.ndarray, robots: np.ndarray,
            leds: np.ndarray) -> np.ndarray:
    """World-frame position [l, 3] of LED ``leds[k]`` of robot ``robots[k]``: positions [n, 2],
    headings [n], led_bodies [n, L, 3] every robot's LEDs in its body frame, or [1, L, 3] when all
    robots share them. Only these LEDs are placed (a worker's cameras need the lit ones)."""
    body = np.asarray(led_bodies, dtype=np.float64)[robots if len(led_bodies) > 1 else 0, leds]   # [l, 3]
    headings = np.asarray(headings, dtype=np.float64)
    # cos and sin of every heading, then taken: each value as the whole swarm's arrays give it
    c, s = np.cos(headings).take(robots), np.sin(headings).take(robots)
    x, y = positions[:, 0].take(robots), positions[:, 1].take(robots)
    return np.stack([x + c * body[:, 0] - s * body[:, 1], y + s * body[:, 0] + c * body[:, 1], body[:, 2]], axis=-1)


def blob_camera(positions, headings, radii, heights, camera_heights, half_windows, led_world,
                led_colors, scene: StaticScene, *, noise_std: float = 0.0,
                rng: Optional[np.random.Generator] = None, tree: Optional[cKDTree] = None,
                observers=None) -> BlobReadings:
    """The omnidirectional camera's blobs for every robot (or, CSR over ``observers`` [m], for
    those robots only: every robot's LEDs are still seen).

    positions [n, 2], headings [n], radii [n], heights [n], camera_heights [n] m,
    half_windows [n] m (= height · tan(aperture)), led_world [n, L, 3] world-frame LED
    positions, or a function (robots [l], leds [l]) → [l, 3] of those LEDs (only the lit ones
    are asked for), led_colors [n, L, 3] uint8. LED l of robot j is a blob of robot i when it is
    lit (not black), j != i, |dx| and |dy| (world axes) are both below half_windows[i], it is
    lower than the camera, and the segment camera(i) → LED is not blocked by a robot other
    than i (the LED's owner included, as in ARGoS) nor by a static body. Blobs of a robot are ordered by owner, then LED index.
    Noise (ARGoS): the planar camera→LED vector gets |v| · N(0, noise_std) added in a uniform
    direction.
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    n = len(positions)
    camera_heights, half_windows, led_colors, led_world = _camera_arrays(n, camera_heights, half_windows,
                                                                         led_colors, led_world)
    _check_noise("noise_std", noise_std, rng)

    # Most LEDs are off: the work below follows the lit ones only.
    n_leds = led_colors.shape[1]
    rgb = led_colors.astype(np.uint8, copy=False)
    own, led = np.nonzero(rgb[..., 0] | rgb[..., 1] | rgb[..., 2])   # sorted by owner, then LED
    if n < 2 or len(own) == 0:
        return BlobReadings.empty(n if observers is None else len(observers))
    n_lit = np.bincount(own, minlength=n)
    first_lit = np.cumsum(n_lit) - n_lit
    lit = led_world(own, led) if callable(led_world) else led_world[own, led]   # [l, 3], as own and led
    # Observer/owner pairs whose centres are close enough for a lit LED to be in the window.
    reach = np.abs(lit[:, :2] - positions.take(own, axis=0)).max()
    tree = kd_tree(positions) if tree is None else tree
    observers, row_of = _observer_rows(observers, n)
    obs, owner = near_pairs(tree, positions, half_windows.max() + reach, observers, p=np.inf)
    if len(own) < n:
        keep = np.flatnonzero(n_lit[owner] > 0)
        obs, owner = obs[keep], owner[keep]
    n_out = n if observers is None else len(observers)
    if len(obs) == 0:
        return BlobReadings.empty(n_out)
    order = _pair_order(obs, owner, n)                # the output order: observer, owner, LED
    obs, owner = obs[order], owner[order]
    i, f, rx, ry = _visible_in_chunks(obs, owner, n_lit, first_lit, led, n_leds, lit, positions, radii, heights,
                                      camera_heights, half_windows, scene, tree)
    if noise_std > 0.0:
        rx, ry = _with_position_noise(rx, ry, i, f, noise_std, rng)
    return _blob_readings(i, f, rx, ry, headings, rgb, n_out, observers)


def _camera_arrays(n: int, camera_heights, half_windows, led_colors, led_world):
    """camera_heights [n], half_windows [n] (float64), led_colors [n, L, 3] and led_world (an array
    of led_colors' shape, float64, or a function) as numpy arrays; ValueError naming a wrong shape."""
    camera_heights = np.asarray(camera_heights, dtype=np.float64)
    half_windows = np.asarray(half_windows, dtype=np.float64)
    led_colors = np.asarray(led_colors)
    for name, a in (("camera_heights", camera_heights), ("half_windows", half_windows)):
        if a.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {a.shape}")
    if led_colors.ndim != 3 or led_colors.shape[::2] != (n, 3):
        raise ValueError(f"led_colors must have shape ({n}, L, 3), got {led_colors.shape}")
    if not callable(led_world):
        led_world = np.asarray(led_world, dtype=np.float64)
        if led_world.shape != led_colors.shape:
            raise ValueError(f"led_world must have the shape of led_colors {led_colors.shape}, got {led_world.shape}")
    return camera_heights, half_windows, led_colors, led_world


def _visible_in_chunks(obs, owner, n_lit, *visible_leds_args):
    """``_visible_leds`` of the (observer, owner) pairs obs [p], owner [p], in chunks of about
    _BLOB_CHUNK (observer, LED) candidates: with every LED lit, 10^4 robots give ~10^7 candidates,
    and their temporaries would need gigabytes at once."""
    ends = np.cumsum(n_lit[owner])                    # candidates up to each pair, inclusive
    parts, start, done = [], 0, 0
    while start < len(obs):
        stop = max(start + 1, int(np.searchsorted(ends, done + _BLOB_CHUNK, "right")))
        parts.append(_visible_leds(obs[start:stop], owner[start:stop], n_lit, *visible_leds_args))
        start, done = stop, ends[stop - 1]
    return parts[0] if len(parts) == 1 else tuple(np.concatenate(x) for x in zip(*parts))


def _with_position_noise(rx, ry, i, f, noise_std: float, rng):
    """ARGoS's camera noise: each planar camera→LED vector (rx [m], ry [m]) plus |v| · N(0, noise_std)
    in a uniform direction, drawn per observer i [m] and LED seen f [m]."""
    draws = entry_noise(rng, i, f)
    length = np.sqrt(rx * rx + ry * ry) * draws.normal(0.0, noise_std, 0)
    direction = draws.uniform(0.0, 2.0 * math.pi, 1)
    return rx + length * np.cos(direction), ry + length * np.sin(direction)


def _blob_readings(i, f, rx, ry, headings, rgb, n_out: int, observers) -> BlobReadings:
    """The blobs seen, observer i [m] (ordered), flat LED index f [m], camera→LED rx, ry [m], as
    CSR over every robot (n_out of them) or over ``observers`` [n_out]."""
    counts = np.bincount(i, minlength=len(headings))
    offsets = np.zeros(n_out + 1, dtype=np.int64)
    # Blobs are ordered by observer, so an observer subset's rows are already contiguous.
    np.cumsum(counts if observers is None else counts[observers], out=offsets[1:])
    return BlobReadings(offsets=offsets,
                        angles=wrap_angle(np.arctan2(ry, rx) - headings[i]),
                        distances=np.sqrt(rx * rx + ry * ry),
                        colors=rgb.reshape(-1, 3).take(f, axis=0))


def _visible_leds(obs, owner, n_lit, first_lit, led, n_leds, lit, positions, radii, heights, camera_heights,
                  half_windows, scene, tree):
    """The lit LEDs of `owner` [p] that `obs` [p] sees → (observer, flat LED index, dx, dy) [m] each.

    n_lit [n], first_lit [n]: each robot's count of lit LEDs and where they start in `led` [l];
    lit [l, 3] where those LEDs are; a flat LED index is owner · n_leds + LED.
    """
    if n_lit.max() == 1:                                # e.g. flocking: only the beacon is lit
        i, j = obs, owner
        k = first_lit[j]                                # index into the lit LEDs
    else:
        rows, within = _ranges(n_lit[owner])
        i, j = obs[rows], owner[rows]
        k = first_lit[j] + within
    f = j * n_leds + led[k]
    # One 1-D array per coordinate: fancy indexing [m, 2]/[m, 3] arrays is far slower.
    tx, ty, tz = lit[:, 0].take(k), lit[:, 1].take(k), lit[:, 2].take(k)
    rx, ry = tx - positions[:, 0].take(i), ty - positions[:, 1].take(i)
    hw, cz = half_windows[i], camera_heights[i]
    shown = (np.abs(rx) < hw) & (np.abs(ry) < hw) & (tz < cz)
    # Occlusion: static bodies anywhere; robots only where the segment dips below the tallest
    # robot (never for the beacon, which is taller than every foot-bot).
    test = np.flatnonzero(shown if scene.n_bodies else shown & (np.minimum(tz, cz) < heights.max()))
    if len(test):
        led_p = np.stack([tx[test], ty[test], tz[test]], axis=1)
        cam_p = np.stack([tx[test] - rx[test], ty[test] - ry[test], cz[test]], axis=1)
        # Walk from the LED end: a ring LED is hidden, if at all, near its robot.
        # As in ARGoS, only the observer's own body is ignored: a robot's body hides its own
        # far-side ring LEDs (they sit 5 mm outside its rim).
        hidden = scene.blocks(cam_p, led_p) | blocked_by_robots(led_p, cam_p, i[test], np.full(len(test), -1),
                                                                positions, radii, heights, tree)
        shown[test[hidden]] = False
    shown = np.flatnonzero(shown)
    return i[shown], f[shown], rx[shown], ry[shown]


def read(s: Sensing, group: SensedGroup, out) -> None:
    out.blobs = blob_camera(s.positions, s.headings, s.radii, s.heights, s.camera_heights, s.half_windows,
                            s.led_world, s.led_colors, s.scene, noise_std=group.settings.config(NAME).noise_std,
                            rng=s.noise(NAME, group), tree=s.tree, observers=s.observers(group))


# --- its topic ------------------------------------------------------------------------------------

TOPIC = Topic("blobs", "sensor_msgs/msg/PointCloud2", "sensor",
              "coloured-blob omnidirectional camera: one point per blob, x/y of the LED in "
              "base_link (m; z = 0, the camera is planar), rgb = 0x00RRGGBB (uint32)")
# One point per blob. float32 coordinates are ample for a camera with cm-level range.
BLOB_DTYPE = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])


def encoder(robot: str) -> cdr_clouds.CloudEncoder:
    return cdr_clouds.CloudEncoder(cdr_clouds.cloud_bytes(base_link(robot), BLOB_DTYPE))


def points_of(angles: np.ndarray, distances: np.ndarray, colors: np.ndarray) -> np.ndarray:
    """Blobs given as (bearing [m], planar distance [m], RGB [m,3]) → BLOB_DTYPE points (z = 0)."""
    points = np.empty(len(angles), dtype=BLOB_DTYPE)
    points["x"] = distances * np.cos(angles)
    points["y"] = distances * np.sin(angles)
    points["z"] = 0.0
    c = colors.astype(np.uint32)
    points["rgb"] = (c[:, 0] << 16) | (c[:, 1] << 8) | c[:, 2]
    return points


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.names[i])

    def publish(self, plan, frame, out):
        places, rows = self.to_send(plan, out)
        if rows:
            blobs = frame.groups[plan.group].blobs
            take, local = csr_take(blobs.offsets, plan.within)
            self.send_clouds(places, rows, out,
                             points_of(blobs.angles[take], blobs.distances[take], blobs.colors[take]), local.tolist(),
                             hand=_handed)


# --- the controller's side -----------------------------------------------------------------------

_NO_FLOATS, _NO_WORDS = np.empty(0), np.empty(0, dtype=np.uint32)
for _empty in (_NO_FLOATS, _NO_WORDS):
    _empty.flags.writeable = False
_CLOUD_DTYPES: dict = {}


class Blobs:
    """The coloured blobs a camera sees this tick. Colours are kept as 0x00RRGGBB words when decoded
    from a cloud; ``colors`` (RGB rows) is derived on first use. Read-only by convention: ``of_color``
    returns this very object when every blob has that colour."""
    __slots__ = ("angles", "distances", "rgb", "_colors")

    def __init__(self, angles: np.ndarray, distances: np.ndarray, colors: Optional[np.ndarray] = None,
                 rgb: Optional[np.ndarray] = None):
        if colors is None and rgb is None:
            raise ValueError("Blobs needs colors ([m, 3] uint8) or rgb ([m] uint32)")
        self.angles = angles          # [m] rad, bearing relative to the heading, CCW
        self.distances = distances    # [m] planar distance from the robot centre, m
        self.rgb = rgb                # [m] uint32 0x00RRGGBB, or None
        self._colors = colors         # [m, 3] uint8 RGB, or None until asked for

    @property
    def colors(self) -> np.ndarray:
        """[m, 3] uint8 RGB."""
        if self._colors is None:
            colors = np.empty((len(self.rgb), 3), dtype=np.uint8)
            colors[:, 0], colors[:, 1], colors[:, 2] = self.rgb >> 16, self.rgb >> 8, self.rgb  # uint8 keeps the low byte
            self._colors = colors
        return self._colors

    def __len__(self) -> int:
        return len(self.angles)

    def of_color(self, rgb: Sequence[int]) -> "Blobs":
        if self.rgb is not None:
            keep = self.rgb == ((int(rgb[0]) << 16) | (int(rgb[1]) << 8) | int(rgb[2]))
        else:
            keep = np.all(self.colors == np.asarray(rgb, dtype=np.uint8), axis=1)
        if keep.all():      # the common case in a swarm of one beacon colour: no copies
            return self
        return Blobs(self.angles[keep], self.distances[keep], None if self._colors is None else self._colors[keep],
                     None if self.rgb is None else self.rgb[keep])


def decode(data: bytes, decoder: Optional[cdr_clouds.CloudDecoder] = None) -> Blobs:
    """``decoder``: one per stream of clouds (a subscription), so their layout is parsed once."""
    width, fields, point_step, points = (decoder or cdr_clouds.CloudDecoder()).decode(data)
    return _blobs(np.frombuffer(points, dtype=_cloud_dtype(fields, point_step), count=width))


def _blobs(points: np.ndarray) -> Blobs:
    if len(points) == 0:
        return Blobs(_NO_FLOATS, _NO_FLOATS, rgb=_NO_WORDS)
    x = points["x"].astype(float)
    y = points["y"].astype(float)
    return Blobs(np.arctan2(y, x), np.hypot(x, y), rgb=points["rgb"] & 0xFFFFFF)


def _handed(points: np.ndarray, offsets: Sequence[int]) -> Callable[[int], Blobs]:
    """The k-th cloud's ``decode``, for every cloud of ``points`` at once (devices/common/handoff.py):
    the same elementwise operations over all of them."""
    whole = _blobs(points)

    def of(k: int) -> Blobs:
        start, end = offsets[k], offsets[k + 1]
        if start == end:
            return Blobs(_NO_FLOATS, _NO_FLOATS, rgb=_NO_WORDS)
        return Blobs(whole.angles[start:end], whole.distances[start:end], rgb=whole.rgb[start:end])
    return of


def _cloud_dtype(fields: tuple, point_step: int) -> np.dtype:
    """The numpy dtype of a blob cloud's points from its fields ((name, offset, datatype) …):
    x, y float32 and rgb uint32, wherever the publisher put them."""
    key = (fields, point_step)
    dtype = _CLOUD_DTYPES.get(key)
    if dtype is None:
        found = {name: (offset, datatype) for name, offset, datatype in fields}
        wanted = {"x": cdr_clouds.FLOAT32, "y": cdr_clouds.FLOAT32, "rgb": cdr_clouds.UINT32}
        if any(found.get(name, (0, None))[1] != datatype for name, datatype in wanted.items()):
            raise ValueError(f"not a blob cloud: fields {sorted(found)} (need x, y float32 and rgb uint32)")
        dtype = _CLOUD_DTYPES[key] = np.dtype({"names": list(wanted), "formats": ["<f4", "<f4", "<u4"],
                                               "offsets": [found[n][0] for n in wanted], "itemsize": point_step})
    return dtype


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_cloud_into("blobs", decode), tick_fields=("blobs",),
                settings=BlobCameraConfig, layout=BlobCamera, read=read, csr_readings=("blobs",))
