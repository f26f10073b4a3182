"""Robot models as data: dimensions, drive limits and device layouts.

One place for every robot fact, with its source next to it: the foot-bot and the TurtleBot 3
burger from ``docs/architecture.md`` (read from the ARGoS 3 sources and the paper's
bridge), the e-puck from ARGoS's own e-puck plugin, the Thymio II from the Enki simulator and
the manufacturer where the reference is silent. A model lists the devices it carries; which
of them run is the world file's choice (``default_devices`` when it says nothing).
Units are SI (REP-103): metres, radians, kilograms; x forward, y left, angles CCW.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping, Optional

import numpy as np

from composed_sim.devices import ALWAYS_ON, BY_NAME, WITH_LAYOUT, camera, differential_steering, ground, lidar, light, \
    odometry, positioning, proximity, range_and_bearing, tf
from composed_sim.devices.camera import BlobCamera
from composed_sim.devices.ground import GroundSensors
from composed_sim.devices.lidar import Lidar
from composed_sim.devices.light import LightRing
from composed_sim.devices.proximity import ProximityRing
from composed_sim.devices.range_and_bearing import RangeAndBearingDevice


def _ring_angles(first_deg: float, step_deg: float, count: int) -> tuple[float, ...]:
    return tuple(math.radians(first_deg + step_deg * i) for i in range(count))


# The devices' names, as world files and sensor frames spell them (each defined in its module).
PROXIMITY, LIGHT, CAMERA, GROUND = proximity.NAME, light.NAME, camera.NAME, ground.NAME
RANGE_AND_BEARING, LIDAR = range_and_bearing.NAME, lidar.NAME
DIFFERENTIAL_STEERING, POSITIONING, ODOMETRY = differential_steering.NAME, positioning.NAME, odometry.NAME
# Not a device of the robot: its frames (world → odom → base_link → sensor mounts) as tf, made
# from the positioning and odometry readings every model has.
TF = tf.NAME


@dataclass(frozen=True)
class FlightLimits:
    """What a model that flies has instead of wheels: its size and the limits its firmware flies
    it within (docs/devices.md's table names each number's source)."""
    motor_diagonal_m: float              # motor to motor, across the frame
    max_speed_mps: float                 # the position controller's velocity limit, per axis
    max_tilt_rad: float                  # the velocity controller's roll and pitch limit
    max_thrust_n: float                  # all motors together
    flight_time_s: float                 # on a full battery, hovering
    battery_full_v: float                # the battery's voltage when full

    def max_horizontal_acceleration_mps2(self) -> float:
        """What the tilt limit allows: g tan(tilt)."""
        return GRAVITY_MPS2 * math.tan(self.max_tilt_rad)

    def max_climb_acceleration_mps2(self, mass_kg: float) -> float:
        """Full thrust against gravity."""
        return self.max_thrust_n / mass_kg - GRAVITY_MPS2


GRAVITY_MPS2 = 9.81


@dataclass(frozen=True)
class RobotModel:
    name: str
    body_radius_m: float           # the footprint is a circle (the dynamics2d robots are)
    body_height_m: float
    mass_kg: float
    wheel_separation_m: float      # distance between the two wheels (ARGoS "interwheel distance")
    wheel_radius_m: float
    max_wheel_speed_mps: float     # used to clamp commands; ARGoS's actuator has none, its examples use 0.10
    max_force_n: float             # pivot joint cap: how hard the drive can push
    max_torque_nm: float           # gear joint cap
    friction: float
    # The devices with a layout that it carries: device name → its layout (the class its module
    # declares), read as ``model.<device>`` (None: not fitted).
    layouts: Mapping[str, Any] = field(default_factory=dict, hash=False)
    # [n_leds, 3] body-frame (x, y, z) positions; ring LEDs first, beacon last.
    led_positions_m: tuple[tuple[float, float, float], ...] = field(default=())
    # Devices a group of this model runs when its world file says nothing about them.
    default_devices: frozenset[str] = frozenset()
    # A second body the 2D engine ties rigidly to the robot's (the foot-bot's gripper body):
    # its mass and moment of inertia add to the robot's when it accelerates.
    carried_mass_kg: float = 0.0
    carried_moment_kg_m2: float = 0.0
    # A model that flies (its firmware moves it, not wheels and the 2D physics; core/flight.py).
    flight: Optional[FlightLimits] = None

    def __post_init__(self):
        for name, layout in self.layouts.items():
            if name not in WITH_LAYOUT or not isinstance(layout, BY_NAME[name].layout):
                raise ValueError(f"{self.name}: {name} is not a device with a layout, or {layout!r} is not its layout")
        missing = sorted(d for d in self.default_devices if d not in self.devices)
        if missing:
            raise ValueError(f"{self.name}: default devices {missing} are not fitted")

    @classmethod
    def of(cls, **fields) -> "RobotModel":
        """A model whose device layouts are given as keywords (``proximity=ProximityRing(…)``)."""
        layouts = {name: fields.pop(name) for name in WITH_LAYOUT if name in fields}
        return cls(**fields, layouts=layouts)

    def __getattr__(self, name: str):
        """``model.lidar``: the layout of a device with one, None when the model does not carry it."""
        if name in WITH_LAYOUT:
            return self.__dict__.get("layouts", {}).get(name)
        raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")

    @property
    def devices(self) -> tuple[str, ...]:
        """Names of the devices this model carries (the always-on ones included)."""
        return tuple(name for name in WITH_LAYOUT if name in self.layouts) + ALWAYS_ON

    @property
    def flies(self) -> bool:
        return self.flight is not None

    @property
    def n_leds(self) -> int:
        return len(self.led_positions_m)

    def led_positions_array(self) -> np.ndarray:
        """[n_leds, 3] body-frame LED positions."""
        return np.asarray(self.led_positions_m, dtype=float).reshape(-1, 3)


def _led_ring(radius_m: float, first_deg: float, count: int, height_m: float):
    return tuple((radius_m * math.cos(a), radius_m * math.sin(a), height_m)
                 for a in _ring_angles(first_deg, 360.0 / count, count))


# --- foot-bot (ARGoS 3, plugins/robots/foot-bot/simulator) ---------------------------
FOOTBOT_BEACON_LED_INDEX = 12

FOOTBOT = RobotModel.of(
    name="foot-bot",
    body_radius_m=0.085036758,          # footbot_entity.cpp BODY_RADIUS
    body_height_m=0.146899733,          # BODY_HEIGHT
    mass_kg=1.6,                        # dynamics2d_footbot_model.cpp
    # dynamics2d_footbot_model.cpp also creates the gripper's body, cpBodyNew(m / 20,
    # cpMomentForCircle(m, 0, R + R)), pinned to the base at its centre and geared to it: the
    # drive accelerates 1.68 kg and twice the base's moment (measured: from rest at 10 cm/s ARGoS's
    # foot-bot covers 8.8928 mm in its first tick, 1.6 kg alone 8.9375 mm).
    carried_mass_kg=1.6 / 20.0,
    carried_moment_kg_m2=1.6 * (2.0 * 0.085036758) ** 2 / 2.0,
    wheel_separation_m=0.14,            # INTERWHEEL_DISTANCE
    wheel_radius_m=0.029112741,         # WHEEL_RADIUS
    max_wheel_speed_mps=0.10,           # argos3-examples flocking: max_speed 10 cm/s
    max_force_n=15.0,                   # dynamics2d differential steering control: max force
    max_torque_nm=150.0,                # ... and max torque
    friction=0.7,
    proximity=ProximityRing(angles_rad=_ring_angles(7.5, 15.0, 24), range_m=0.10,
                            elevation_m=0.06),           # footbot_entity.cpp: proximity sensors at 6 cm
    light=LightRing(angles_rad=_ring_angles(7.5, 15.0, 24), elevation_m=0.06, model="foot-bot"),
    camera=BlobCamera(height_m=0.288699733, aperture_rad=math.radians(70.0)),
    # docs/architecture.md "Motor ground sensor": the foot-bot's four sensors under the body.
    ground=GroundSensors(offsets_m=((0.063, 0.0116), (-0.063, 0.0116), (-0.063, -0.0116),
                                    (0.063, -0.0116))),
    # docs/architecture.md "Range and bearing": 0.1 m above the origin, 3 m default range.
    range_and_bearing=RangeAndBearingDevice(elevation_m=0.1, range_m=3.0),
    # footbot_entity.cpp: 12 ring LEDs at r = R + 5 mm, 15° + 30°·i, z = 0.085; the beacon at
    # z = 0.174249733.
    led_positions_m=_led_ring(0.085036758 + 0.005, 15.0, 12, 0.085) + ((0.0, 0.0, 0.174249733),),
    # The flocking experiments' sensor set; the others cost time and are switched on per world.
    default_devices=frozenset({PROXIMITY, LIGHT, CAMERA}),
)

# --- e-puck (ARGoS 3 core, plugins/robots/e-puck/simulator) --------------------------
# epuck_entity.cpp's sensor_angle[0..7]: π divided by float constants (hence float32), each
# normalised to (-π, π].
EPUCK_PROXIMITY_ANGLES_RAD = tuple(
    math.remainder(math.pi / float(np.float32(divisor)), 2.0 * math.pi)
    for divisor in (10.5884, 3.5999, 2.0, 1.2, 0.8571, 0.6667, 0.5806, 0.5247))
# Not in docs/architecture.md; numbers from ARGoS's own e-puck, as the reference's other robots.
EPUCK = RobotModel.of(
    name="e-puck",
    body_radius_m=0.035,                # epuck_entity.cpp BODY_RADIUS (manufacturer: 70 mm diameter)
    body_height_m=0.086,                # epuck_entity.cpp BODY_HEIGHT
    mass_kg=0.4,                        # dynamics2d_epuck_model.cpp m_fMass
    wheel_separation_m=0.053,           # epuck_entity.cpp INTERWHEEL_DISTANCE
    wheel_radius_m=0.0205,              # epuck_entity.cpp WHEEL_RADIUS
    max_wheel_speed_mps=0.128,          # GCtronic e-puck: 1000 steps/s at 0.13 mm/step ≈ 12.8 cm/s
    max_force_n=1.5,                    # dynamics2d_epuck_model.cpp EPUCK_MAX_FORCE
    max_torque_nm=1.5,                  # EPUCK_MAX_TORQUE
    friction=0.7,                       # dynamics2d_epuck_model.cpp: u = 0.7
    # epuck_entity.cpp: 8 sensors on the rim at 6 cm, 10 cm range, at the angles its active code
    # lists one by one (π/10.5884, π/3.5999, π/2, π/1.2, …: about ±17°, ±50°, ±90°, ±150°, like the
    # real robot's); its evenly spaced ring (22.5° + 45°·i) is commented out there.
    # epuck_proximity_default_sensor.cpp: its own calibration (devices/proximity.py).
    proximity=ProximityRing(angles_rad=EPUCK_PROXIMITY_ANGLES_RAD, range_m=0.10,
                            elevation_m=0.06, calibration="e-puck"),
    # epuck_entity.cpp: the light sensors are the evenly spaced ring, π/8 + 45°·i, on the rim at
    # 6 cm. ARGoS has no e-puck light sensor of its own: the generic ``light`` reads them.
    light=LightRing(angles_rad=_ring_angles(22.5, 45.0, 8), elevation_m=0.06, model="generic"),
    ground=GroundSensors(offsets_m=((0.03, -0.009), (0.03, 0.0), (0.03, 0.009))),   # epuck_entity.cpp
    # epuck_entity.cpp: RAB at the LED ring's elevation, default rab_range 0.8 m.
    range_and_bearing=RangeAndBearingDevice(elevation_m=0.086, range_m=0.8),
    # epuck_entity.cpp: 8 ring LEDs at r = R + 7 mm from π/16 (11.25°), 45° apart, z = 0.086.
    led_positions_m=_led_ring(0.035 + 0.007, 11.25, 8, 0.086),
    default_devices=frozenset({PROXIMITY, GROUND}),
)

# --- TurtleBot 3 burger (docs/architecture.md "TurtleBot 3 burger") ---------------------
TURTLEBOT3_BURGER = RobotModel.of(
    name="turtlebot3-burger",
    body_radius_m=0.08,                 # docs/architecture.md: base radius 0.08 m
    body_height_m=0.192,                # docs/architecture.md: height 0.192 m
    mass_kg=1.0,                        # ROBOTIS e-Manual, TurtleBot3 burger specifications: 1 kg
    wheel_separation_m=0.160,           # docs/architecture.md
    wheel_radius_m=0.033,               # docs/architecture.md
    max_wheel_speed_mps=0.22,           # docs/architecture.md: 0.22 m/s (and 2.84 rad/s) on the real robot
    # No ARGoS model of the burger: the foot-bot's drive caps (a robot of similar mass).
    max_force_n=15.0,
    max_torque_nm=150.0,
    friction=0.7,
    # docs/architecture.md: 360 rays, 0.12-3.5 m, mounted at (-0.064, 0, 0.122). One ray per degree
    # over the full turn (the LDS-01's scan), so the last ray is 1° short of 360°.
    lidar=Lidar(n_rays=360, angle_min_rad=0.0, angle_max_rad=math.radians(359.0),
                min_range_m=0.12, max_range_m=3.5, mount_m=(-0.064, 0.0, 0.122)),
    # The reference gives the burger no IR ring, LEDs or RAB: it senses neighbours by LiDAR.
    default_devices=frozenset({LIDAR}),
)

# --- Thymio II -------------------------------------------------------------------------
# Not in docs/architecture.md and not in ARGoS core. Numbers from the Enki simulator's Thymio2
# model (enki-community/enki, enki/robots/thymio2/Thymio2.cpp, in cm there), which Mobsya's
# own Aseba playground uses, unless noted. Its footprint (front arc of 8 cm radius, flat back
# 3 cm behind the axle) is approximated by a circle: the physics engine's robots are circles.
_THYMIO_IR = (((0.062, 0.0485), 0.69813), ((0.075, 0.0255), 0.34906), ((0.0795, 0.0), 0.0),
              ((0.075, -0.0255), -0.34906), ((0.062, -0.0485), -0.69813),
              ((-0.0295, 0.0295), math.pi), ((-0.0295, -0.0295), math.pi))
THYMIO2 = RobotModel.of(
    name="thymio2",
    body_radius_m=0.056,                # half the manufacturer's 11.2 cm width (Mobsya Thymio II: 11 x 11.2 x 5.3 cm)
    body_height_m=0.053,                # Mobsya: 5.3 cm
    mass_kg=0.2,                        # Enki Thymio2: hull mass 200 g
    wheel_separation_m=0.094,           # Enki Thymio2: DifferentialWheeled(9.4 cm, ...)
    wheel_radius_m=0.022,               # ARGoS Thymio plugin (resilient-swarms/thymio, Thymio_measures.cpp)
    max_wheel_speed_mps=0.166,          # Enki Thymio2: max speed 16.6 cm/s
    max_force_n=1.5,                    # no ARGoS dynamics2d Thymio: the e-puck's caps (a robot of similar size)
    max_torque_nm=1.5,
    friction=0.7,
    # Enki Thymio2: 5 front and 2 back horizontal IR sensors at these body points and
    # directions, about 14 cm range, at the body's mid height. The reading is ARGoS's generic
    # proximity sensor's (exp(-d)). (The community ARGoS Thymio plugin, resilient-swarms/thymio,
    # has other offsets, a 1 m range and a reading that saturates at 1 within it: not this model.)
    proximity=ProximityRing(angles_rad=tuple(a for _, a in _THYMIO_IR), range_m=0.14,
                            elevation_m=0.03, origins_m=tuple(p for p, _ in _THYMIO_IR),
                            calibration="generic"),
    ground=GroundSensors(offsets_m=((0.072, 0.012), (0.072, -0.012))),   # Enki Thymio2 ground sensors
    default_devices=frozenset({PROXIMITY, GROUND}),
)

# --- Khepera IV (docs/architecture.md "Khepera IV") -------------------------------------
KHEPERAIV = RobotModel.of(
    name="kheperaiv",
    body_radius_m=0.0704,
    body_height_m=0.0047 + 0.053,       # the base's elevation plus its height: its top
    mass_kg=0.4,
    wheel_separation_m=0.1054,
    wheel_radius_m=0.021,
    max_wheel_speed_mps=0.813,          # the real robot's top speed; ARGoS's plugin sets no cap
    max_force_n=1.5,
    max_torque_nm=1.5,
    friction=0.7,
    # 8 IR sensors on the rim from the front, 45° apart, 14.5 mm up, 12 cm range, their own curve.
    proximity=ProximityRing(angles_rad=_ring_angles(0.0, 45.0, 8), range_m=0.12,
                            elevation_m=0.0145, calibration="kheperaiv"),
    # The same IR ring; its own sensor, kheperaiv_light (kheperaiv_light_rotzonly_sensor.cpp).
    light=LightRing(angles_rad=_ring_angles(0.0, 45.0, 8), elevation_m=0.0145, model="kheperaiv"),
    ground=GroundSensors(offsets_m=((0.0614, 0.01), (0.0206, 0.059), (0.0206, -0.059),
                                    (0.0614, -0.01))),
    range_and_bearing=RangeAndBearingDevice(elevation_m=0.0577, range_m=3.0),
    # 682 rays over 210° centred on the front, 2 cm to 4 m, 8.4 cm above the top.
    lidar=Lidar(n_rays=682, angle_min_rad=math.radians(-105.0), angle_max_rad=math.radians(105.0),
                min_range_m=0.02, max_range_m=4.0, mount_m=(0.0, 0.0, 0.0577 + 0.084)),
    # 3 LEDs on the top: two at the front, one at the back.
    led_positions_m=((0.04, 0.025, 0.0577), (-0.05, 0.0, 0.0577), (0.04, -0.025, 0.0577)),
    default_devices=frozenset({PROXIMITY, GROUND}),
)

# --- Crazyflie 2.1 (Bitcraze; its firmware, crazyflie-firmware) ---------------------------
# docs/devices.md, "Crazyflie 2.1", names the source of each number. It flies: no wheels, not a
# body of the 2D physics; its firmware's setpoints move it (devices/crazyflie, core/flight.py).
# Its wheel fields are unused and only kept finite (a wheel command to it does nothing).
CRAZYFLIE = RobotModel.of(
    name="crazyflie",
    body_radius_m=0.092 / 2,            # half the 92 mm motor-to-motor diagonal
    body_height_m=0.029,                # 29 mm, motor mount feet included
    mass_kg=0.027,                      # 27 g
    wheel_separation_m=0.092, wheel_radius_m=0.0, max_wheel_speed_mps=0.0, max_force_n=0.0, max_torque_nm=0.0,
    friction=0.0,
    flight=FlightLimits(motor_diagonal_m=0.092, max_speed_mps=1.0, max_tilt_rad=math.radians(20.0),
                        max_thrust_n=4 * 0.12, flight_time_s=7 * 60.0, battery_full_v=4.2),
    # The Crazyswarm2 swarms' range and bearing, at the body's centre; 3 m as the other models'.
    range_and_bearing=RangeAndBearingDevice(elevation_m=0.0, range_m=3.0),
    default_devices=frozenset(),
)

MODELS: dict[str, RobotModel] = {m.name: m for m in (FOOTBOT, EPUCK, TURTLEBOT3_BURGER, THYMIO2,
                                                     KHEPERAIV, CRAZYFLIE)}


def get_model(name: str) -> RobotModel:
    try:
        return MODELS[name]
    except KeyError:
        raise ValueError(f"unknown robot model {name!r}; known: {', '.join(sorted(MODELS))}") from None


def display_colors(led_colors: np.ndarray) -> np.ndarray:
    """The one colour that stands for each robot's LEDs → [n, 3] uint8.

    led_colors: [n, L, 3] (ring LEDs first, beacon last, as in the topic contract) or
    already [n, 3]. The beacon (the last LED) when it is lit, else the first lit ring LED,
    else black (no LED lit).
    """
    c = np.asarray(led_colors)
    c = c if c.dtype == np.uint8 else c.astype(np.uint8)
    if c.ndim == 2 and c.shape[1] == 3:
        return c
    if c.ndim == 3 and c.shape[1] == 0 and c.shape[2] == 3:    # robots without LEDs (TurtleBot 3)
        return np.zeros((len(c), 3), dtype=np.uint8)
    if c.ndim != 3 or c.shape[2] != 3 or c.shape[1] == 0:
        raise ValueError(f"led_colors must be [n, L, 3] or [n, 3], got shape {c.shape}")
    lit = (c[..., 0] | c[..., 1] | c[..., 2]) != 0               # [n, L]; faster than any(axis=2)
    ring_first = np.argmax(lit[:, :-1], axis=1) if c.shape[1] > 1 else np.zeros(len(c), int)
    # With nothing lit argmax gives LED 0, which is then black: the right answer.
    first = np.where(lit[:, -1], c.shape[1] - 1, ring_first)      # [n]
    return c[np.arange(len(c)), first]
