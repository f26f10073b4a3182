"""The run-wide ``crazyflie_server`` node, as Crazyswarm2's server is to its scripts: the robots and
their firmware parameters as its parameters, and the swarm's ``all/*`` services.

Like Crazyswarm2's, it reads its robots from its parameter overrides, which the host gives it from
the world file as Crazyswarm2's launch file gives its crazyflies.yaml (``server_parameters``):
``robots.<cf>.enabled``, ``uri``, ``initial_position``, ``type`` and ``firmware_params.<group>.<name>``.
From them it declares, as Crazyswarm2's server does once connected:

- ``<cf>.params.<group>.<name>``: each drone's firmware parameters (integer or double, as their
  values are), readable with ``get_parameters``, listed with ``list_parameters``, typed with
  ``describe_parameters``, settable with ``set_parameters``; ``hlCommander.groupmask`` sets the
  drone's group mask (the others are kept and read back: their firmware modules are not simulated);
- ``all.params.<group>.<name>``: setting one sets it on every drone that has it.

Its services ``all/takeoff``, ``all/land``, ``all/go_to`` (relative), ``all/start_trajectory``,
``all/notify_setpoints_stop``, ``all/arm`` and ``all/emergency`` and its ``all/cmd_full_state``
subscription post one command for every drone (group masks respected by each drone's firmware) to
the process's outbox (``outbox``, given by the host), which the host applies at the tick's close.
"""
from __future__ import annotations

import functools
from typing import Callable, Optional

from rcl_interfaces.msg import SetParametersResult
from rclpy.node import Node
from rclpy.parameter import Parameter

from composed_sim.core.drone_commands import ALL
from composed_sim.ros.crazyflie import messages
from composed_sim.ros.topic import QOS
from composed_sim.world.crazyflies import GROUP_MASK, Crazyflie

NAME = "crazyflie_server"
GROUP_MASK_PARAM = ".params." + ".".join(GROUP_MASK)


def server_parameters(drones: list[Crazyflie], positions) -> dict:
    """The server's parameter overrides for ``drones`` starting at ``positions`` ([n, 2], every
    robot's), as Crazyswarm2's crazyflies.yaml gives them."""
    params = {}
    for d in drones:
        prefix = f"robots.{d.name}."
        x, y = (float(v) for v in positions[d.robot])
        params.update({prefix + "enabled": True, prefix + "uri": d.uri, prefix + "type": d.type,
                       prefix + "initial_position": [x, y, 0.0]})
        for group, values in d.firmware_params.items():
            params.update({f"{prefix}firmware_params.{group}.{name}": value for name, value in values.items()})
    return params


class CrazyflieServer(Node):
    def __init__(self, **node_kwargs):
        super().__init__(NAME, allow_undeclared_parameters=True,
                         automatically_declare_parameters_from_overrides=True, **node_kwargs)
        self.outbox = None             # the host's (ros/crazyflie/outbox.py): ``attach``
        self._interfaces = messages.load()
        # name → robot index in the run (``attach``); until then, the names its parameters give.
        self.robots = dict.fromkeys(key[len("robots."):-len(".uri")] for key in self._parameters
                                    if key.startswith("robots.") and key.endswith(".uri") and key.count(".") == 2)
        self._fanning_out = False
        self._declare_firmware_params()
        self.add_on_set_parameters_callback(self._check)
        self.add_post_set_parameters_callback(self._apply)
        if self._interfaces is None:
            self.get_logger().warning(messages.MISSING)
            return
        for name, (_, _, convert) in messages.SWARM_SERVICES.items():
            self.create_service(self._interfaces.swarm_services[name], f"all/{name}",
                                functools.partial(self._broadcast, f"all/{name}", convert))
        # Not through the host's run-wide relay: a script in another process streams to it.
        Node.create_subscription(self, self._interfaces.setpoints["cmd_full_state"], "all/cmd_full_state",
                                 functools.partial(self._stream, messages.SETPOINTS["cmd_full_state"][2]), QOS)

    def _declare_firmware_params(self) -> None:
        """``<cf>.params.<group>.<name>`` from ``robots.<cf>.firmware_params.<group>.<name>``, and a
        typed ``all.params.<group>.<name>`` for every one a drone has."""
        mine, swarm = [], {}
        for key, parameter in list(self._parameters.items()):
            parts = key.split(".")
            if len(parts) == 5 and parts[0] == "robots" and parts[2] == "firmware_params":
                name = f"{parts[1]}.params.{parts[3]}.{parts[4]}"
                mine.append((name, parameter.value))
                swarm.setdefault(f"all.params.{parts[3]}.{parts[4]}", parameter.type_)
        self.declare_parameters("", mine)
        self.declare_parameters("", [(name, kind) for name, kind in swarm.items() if not self.has_parameter(name)])

    # --- commands ------------------------------------------------------------------------------

    def _post(self, robot: int, kind: str, args: tuple, stamp_ns: int = 0) -> None:
        if self.outbox is not None:
            self.outbox.post(robot, kind, args, stamp_ns)

    def _broadcast(self, service: str, convert: Callable, request, response):
        kind, args = convert(request)
        mask = getattr(request, "group_mask", 0)
        if mask and not any(self._mask_of(name) & mask for name in self.robots):
            self.get_logger().warning(f"{service}: group mask {mask}: no drone is in it (their "
                                      f"hlCommander.groupmask), so none obeys")
        self._post(ALL, kind, args)
        return response

    def _stream(self, convert: Callable, msg) -> None:
        kind, args = convert(msg)
        self._post(ALL, kind, args)

    def _mask_of(self, name: str) -> int:
        key = name + GROUP_MASK_PARAM
        return int(self.get_parameter(key).value) if self.has_parameter(key) else 0

    # --- firmware parameters -------------------------------------------------------------------

    def _check(self, parameters: list[Parameter]) -> SetParametersResult:
        for p in parameters:
            owner = p.name.split(".params.")[0] if ".params." in p.name else None
            if owner is not None and owner != "all" and owner not in self.robots:
                return SetParametersResult(successful=False, reason=f"{p.name}: the run has no drone {owner}")
        return SetParametersResult(successful=True)

    def _apply(self, parameters: list[Parameter]) -> None:
        """A drone's group mask to its firmware; an ``all.params`` value to every drone's."""
        if self._fanning_out:
            return
        spread = []
        for p in parameters:
            owner, _, rest = p.name.partition(".params.")
            if not rest or p.value is None:
                continue
            if owner == "all":
                spread += [Parameter(f"{name}.params.{rest}", p.type_, p.value) for name in self.robots
                           if self.has_parameter(f"{name}.params.{rest}")]
                if p.name == "all" + GROUP_MASK_PARAM:
                    self._post(ALL, "set_group_mask", (int(p.value),))
            elif p.name == owner + GROUP_MASK_PARAM:
                self._post(self.robots[owner], "set_group_mask", (int(p.value),))
        if spread:
            self._fanning_out = True
            try:
                self.set_parameters(spread)
            finally:
                self._fanning_out = False

    def attach(self, outbox, robots: dict[str, int]) -> None:
        """The host's outbox and each drone's robot index (none where crazyflie_interfaces is not
        built: the drones are not served); the group masks the world file gives go to the firmware
        with the first tick's commands."""
        self.outbox, self.robots = outbox, {name: robots[name] for name in self.robots if name in robots}
        for name, robot in self.robots.items():
            mask = self._mask_of(name)
            if mask:
                self._post(robot, "set_group_mask", (mask,))


def find(nodes) -> Optional[CrazyflieServer]:
    return next((n for n in nodes if isinstance(n, CrazyflieServer)), None)
