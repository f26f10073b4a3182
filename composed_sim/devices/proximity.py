"""Proximity: the IR ring, ARGoS's ``footbot_proximity_default_sensor.cpp`` and
``proximity_default_sensor.cpp`` (docs/architecture.md, "Proximity ring"), over all robots at once.

The ring (where the rays are) belongs to the robot; how a ray's distance becomes a reading is the
sensor's, as in ARGoS, where each sensor element (``footbot_proximity``, ``epuck_proximity``,
``kheperaiv_proximity``, the generic ``proximity``) has its own ``CalculateReading`` over the same
rays. A world file picks it with ``devices: {proximity: {model: generic}}``; without one the
robot's own sensor's (``ProximityRing.calibration``) reads.

``/<r>/proximity``, sensor_msgs/LaserScan in base_link: one ray per sensor at the ring's angles;
ranges = the nearest hit's distance from the rim (m, +inf: nothing within range), intensities =
ARGoS's reading in [0, 1]. A controller's Tick: ``proximity`` and ``proximity_distances``.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Literal, Optional

import numpy as np

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

from composed_sim.devices.common import cdr
from composed_sim.devices.common.device import Device, DevicePublisher, reads_into
from composed_sim.devices.common.geometry import StaticScene, ray_circle_distance
from composed_sim.devices.common.sensing import SensedGroup, Sensing
from composed_sim.devices.common.sensors import _check_noise, _observer_rows, _robots, _uniform_noise, kd_tree, near_pairs
from composed_sim.devices.common.settings import DeviceSwitch, NonNegativeFloat
from composed_sim.devices.common.topic import Topic, base_link

NAME = "proximity"

# How a proximity ray's distance becomes a reading: ARGoS's sensor elements, each its own model.
#   foot-bot   footbot_proximity (footbot_proximity_default_sensor.cpp)
#   e-puck     epuck_proximity (epuck_proximity_default_sensor.cpp)
#   kheperaiv  kheperaiv_proximity (the Khepera IV plugin's kheperaiv_proximity_default_sensor.cpp)
#   generic    proximity (proximity_default_sensor.cpp: exp(-d)), which any robot with a ring can run
ProximityCalibration = Literal["foot-bot", "e-puck", "generic", "kheperaiv"]


@dataclass(frozen=True)
class ProximityRing:
    """IR rays cast outward from the body: radially from the rim, or from given body-frame points."""
    angles_rad: tuple[float, ...]   # [k] ray directions, CCW from the front
    range_m: float                   # ray length measured from the ray's origin
    elevation_m: float               # height of the rays: lower bodies are not seen
    # [k] (x, y) body-frame ray origins; None: on the rim, at the ray's own angle.
    origins_m: Optional[tuple[tuple[float, float], ...]] = None
    calibration: ProximityCalibration = "foot-bot"


class ProximityConfig(DeviceSwitch):
    noise: NonNegativeFloat = 0.0        # uniform(-noise, noise) on each reading
    # The reading model (which ARGoS sensor element reads the ring); None: the robot's own.
    model: Optional[ProximityCalibration] = None


def ring_for(ring: ProximityRing, model: Optional[str]) -> ProximityRing:
    """The ring read by the reading model ``model`` (None: its own)."""
    return ring if model is None or model == ring.calibration else replace(ring, calibration=model)


def footbot_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance from the rim (m, inf = nothing) → [...] reading (footbot CalculateReading)."""
    return np.where(distances < 0.009889556, 1.0, 0.0100527 / (distances + 0.000163144))


def epuck_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance (m, inf = nothing) → [...] reading: ARGoS epuck_proximity_default_sensor.cpp,
    298.701 d² − 36.8961 d + 1.08212 up to 5 cm, else 0, clamped to [0, 1]."""
    with np.errstate(invalid="ignore"):   # inf * 0 never happens: inf fails d <= 0.05 first
        value = np.where(distances <= 0.05, (298.701 * distances - 36.8961) * distances + 1.08212, 0.0)
    return np.clip(value, 0.0, 1.0)


def generic_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance (m, inf = nothing) → [...] exp(-d), 0 for no hit: ARGoS's generic
    proximity_default_sensor.cpp CalculateReading."""
    return np.exp(-distances)


def kheperaiv_proximity_reading(distances: np.ndarray) -> np.ndarray:
    """[...] distance from the rim (m, inf = nothing) → [...] reading: the ARGoS Khepera IV
    plugin's curve (docs/architecture.md "Khepera IV"), 1 below 4 cm, 0 beyond 12 cm, clamped
    at 0 (the curve dips to −0.007 just before 12 cm)."""
    with np.errstate(over="ignore", invalid="ignore"):
        curve = 4.14 * np.exp(-33.0 * distances) - 0.085
    return np.where(distances < 0.04, 1.0, np.where(distances > 0.12, 0.0, np.maximum(curve, 0.0)))


PROXIMITY_READINGS = {"foot-bot": footbot_proximity_reading, "e-puck": epuck_proximity_reading,
                      "kheperaiv": kheperaiv_proximity_reading,
                      "generic": generic_proximity_reading}


def proximity_ring(positions, headings, radii, heights, ring: ProximityRing, scene: StaticScene, *,
                   noise: float = 0.0, rng: Optional[np.random.Generator] = None,
                   tree: Optional[cKDTree] = None, observers=None) -> tuple[np.ndarray, np.ndarray]:
    """IR rays cast outward from the body of every robot (or of ``observers`` [m] only).

    positions [n, 2], headings [n], radii [n], heights [n] of all robots → (distances [m, k] m
    from the ray's origin, inf when nothing is hit within ``ring.range_m``; readings [m, k] in
    [0, 1] by the ring's calibration). Rays start on the rim at their own angle, or at
    ``ring.origins_m`` (body frame) when given. A ray sees other robots and static bodies
    taller than ``ring.elevation_m``; starting inside one reads 0 m.
    Noise: uniform(-noise, noise) added to every reading, then clamped (ARGoS).
    """
    positions, headings, radii, heights = _robots(positions, headings, radii, heights)
    _check_noise("noise", noise, rng)
    observers, row_of = _observer_rows(observers, len(positions))
    obs_pos = positions if observers is None else positions[observers]
    obs_head = headings if observers is None else headings[observers]
    n, reach, elevation_m = len(obs_pos), ring.range_m, ring.elevation_m
    sensor = np.asarray(ring.angles_rad)                                                 # [k]
    k = len(sensor)
    # cos(h + a) expanded: n + k trig calls instead of n * k
    ch, sh = np.cos(obs_head)[:, None], np.sin(obs_head)[:, None]
    ca, sa = np.cos(sensor)[None, :], np.sin(sensor)[None, :]
    dirs = np.stack([ch * ca - sh * sa, sh * ca + ch * sa], axis=-1)                     # [n, k, 2]
    if ring.origins_m is None:
        obs_radii = radii if observers is None else radii[observers]
        rim = obs_radii[:, None, None] * dirs                                            # [n, k, 2]
    else:
        ox, oy = np.asarray(ring.origins_m, dtype=np.float64).T[:, None, :]              # [1, k] each
        rim = np.stack([ch * ox - sh * oy, sh * ox + ch * oy], axis=-1)                  # [n, k, 2]
    dist = np.full((n, k), np.inf)
    if scene.n_bodies:
        origins = (obs_pos[:, None, :] + rim).reshape(-1, 2)
        dist = scene.ray_distance(origins, dirs.reshape(-1, 2), reach, min_height=elevation_m).reshape(n, k)
    if len(positions) > 1 and n:
        tree = kd_tree(positions) if tree is None else tree
        lever = radii.max() if ring.origins_m is None else float(np.hypot(*np.asarray(ring.origins_m).T).max())
        obs, tgt = near_pairs(tree, positions, lever + radii.max() + reach, observers)
        seen = np.flatnonzero(heights[tgt] > elevation_m)
        obs, tgt = obs[seen], tgt[seen]
        row = obs if observers is None else row_of[obs]
        # In the observer's frame (small numbers): ray origins vs the target's relative centre.
        centre = positions.take(tgt, axis=0) - positions.take(obs, axis=0)               # [p, 2]
        d = ray_circle_distance(rim.take(row, axis=0), dirs.take(row, axis=0), centre[:, None, :],
                                radii[tgt][:, None])                                     # [p, k]
        np.minimum.at(dist, row, d)
    dist[dist > reach] = np.inf
    return dist, _uniform_noise(PROXIMITY_READINGS[ring.calibration](dist), noise, rng)


def read(s: Sensing, group: SensedGroup, out) -> None:
    """The group's readings into ``out`` (its GroupReadings)."""
    out.proximity_distances, out.proximity = proximity_ring(
        s.positions, s.headings, s.radii, s.heights,
        ring_for(group.model.proximity, group.settings.config(NAME).model), s.scene,
        noise=group.settings.config(NAME).noise, rng=s.noise(NAME, group), tree=s.tree,
        observers=s.observers(group))


# --- its topic ------------------------------------------------------------------------------------

TOPIC = Topic("proximity", "sensor_msgs/msg/LaserScan", "sensor",
              "IR proximity ring: ranges = distance from the rim in m (+inf: nothing within "
              "range), intensities = ARGoS reading in [0, 1]; angle_min/increment give the ring")


def encoder(ring: ProximityRing, robot: str) -> cdr.ScanEncoder:
    """Robot's scans: the ring's angles and range, one range and one intensity per sensor."""
    k = len(ring.angles_rad)
    return cdr.ScanEncoder(cdr.ring_scan_bytes(base_link(robot), ring.angles_rad, ring.range_m, k, k))


def decode(data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """A scan's bytes → distances [k] (m from the rim, inf = none), readings [k] in [0, 1]."""
    return cdr.decode_scan(data)


class Publisher(DevicePublisher):
    topic, device = TOPIC, NAME

    def template(self, robots, i):
        return encoder(robots.models[i].proximity, robots.names[i])

    def publish(self, plan, frame, out):
        places, rows = self.to_send(plan, out)
        if rows:
            group = frame.groups[plan.group]
            self.send_scans(places, rows, out, group.proximity_distances[plan.within], group.proximity[plan.within],
                            hand=lambda ranges, intensities: lambda k: (ranges[k], intensities[k]))  # decode's


DEVICE = Device(NAME, (TOPIC,), Publisher, reads_into(("proximity_distances", "proximity"), decode),
                tick_fields=("proximity", "proximity_distances"), settings=ProximityConfig, layout=ProximityRing,
                read=read, readings=("proximity_distances", "proximity"))
