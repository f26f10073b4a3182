"""A world's drones as Crazyswarm2 lists its robots: each one's name, radio address, id, type and
the firmware parameters set at its start (the ``crazyflie:`` section of its robot group), what the
``crazyflie_server`` node offers as its parameters (docs/crazyflie.md)."""
from __future__ import annotations

import re
from dataclasses import dataclass

from composed_sim.world.robot_models import get_model
from composed_sim.world.schema import World

# The drones' messages and services: Crazyswarm2's package, or the one that ships with composed_sim
# (composed_sim/interfaces/activate.py, SHIPPED), built on first use.
MESSAGE_PACKAGE = "crazyflie_interfaces"


def interfaces_needed(world: World) -> tuple[str, ...]:
    """The shipped interface packages ``world``'s robots need: the drones' messages if any flies."""
    return (MESSAGE_PACKAGE,) if any(get_model(g.model).flies for g in world.robots) else ()


# The firmware parameters every drone has here, with the firmware's defaults (its hlCommander
# module's group mask and take-off and landing speeds); a world file may set them and name others.
FIRMWARE_DEFAULTS: dict[str, dict[str, float | int]] = {"hlCommander": {"groupmask": 0, "vtoff": 0.5, "vland": 0.5}}
GROUP_MASK = ("hlCommander", "groupmask")


@dataclass(frozen=True)
class Crazyflie:
    robot: int                  # the robot's index in the run
    name: str                   # its namespace: cf3
    id: int                     # the last byte of its radio address
    uri: str                    # radio://<radio>/80/2M/E7E7E7E7<id>
    type: str                   # its robot type (Crazyswarm2's robot_types)
    firmware_params: dict       # {group: {name: value}}: the defaults, then the world file's


def crazyflies(world: World) -> list[Crazyflie]:
    """The world's drones (robots whose model flies), in robot order. A drone's id is the number in
    its name (the group's ``crazyflie.ids`` name them): cf231 is ``radio://0/80/2M/E7E7E7E7E7``; past
    255, the next radio (cf300: ``radio://1/80/2M/E7E7E7E72C``), as a swarm that big uses several."""
    out = []
    names, groups = world.robot_names(), world.group_of_robot()
    first = 0
    for group in world.robots:
        if get_model(group.model).flies:
            settings = group.crazyflie
            for k in range(group.count):
                name = names[first + k]
                number = int(re.search(r"(\d+)$", name).group(1))      # its id, where its group lists ids
                ident, radio = number % 256, number // 256
                params = {g: dict(v) for g, v in FIRMWARE_DEFAULTS.items()}
                for g, values in (settings.firmware_params if settings is not None else {}).items():
                    params.setdefault(g, {}).update(values)
                out.append(Crazyflie(first + k, name, ident, f"radio://{radio}/80/2M/E7E7E7E7{ident:02X}",
                                     settings.type if settings is not None else "cf21", params))
        first += group.count
    assert first == len(groups)
    return out
