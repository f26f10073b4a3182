"""A hosted node's parameter services, as its own process would have them, without their cost.

Every rclpy node offers ``~/get_parameters``, ``~/set_parameters``, ``~/list_parameters``,
``~/describe_parameters``, ``~/get_parameter_types`` and ``~/set_parameters_atomically``: what
``ros2 param``, rqt and other nodes use to read and set its parameters at run time. As DDS
services they are twelve endpoints per node, each announced to every participant of the process:
thousands of nodes would multiply the set-up time. So the host builds them in process only
(rclpy's own ``ParameterService``, its handlers and its checks, over the service directory of
hosting/calls/directory.py): another hosted node's client reaches them at once, and a client in another
process finds them once something outside asks (``expose``), when they get their DDS endpoints.
"""
from __future__ import annotations

from rclpy.node import Node
from rclpy.parameter_service import ParameterService

from composed_sim.hosting.calls.directory import ServiceDirectory


class _ServicesInProcess:
    """What ``ParameterService`` sees as its node: the hosted node, whose ``create_service``
    registers the service in the directory instead of creating its DDS endpoint."""

    def __init__(self, node: Node, directory: ServiceDirectory, on_outside):
        self._node, self._directory, self._on_outside = node, directory, on_outside
        self.entries = []

    def __getattr__(self, name):
        return getattr(self._node, name)

    def create_service(self, srv_type, srv_name, callback, *, qos_profile=None, callback_group=None):
        name = self._node.resolve_service_name(srv_name)
        group = callback_group or self._node.default_callback_group
        entry = self._directory.add_in_process(self._node, name, srv_type, callback, group)
        entry.on_outside = self._on_outside
        self.entries.append(entry)


class HostedParameterServices:
    """One node's parameter services, served in process."""

    def __init__(self, node: Node, directory: ServiceDirectory):
        self._node, self._directory = node, directory
        self._proxy = _ServicesInProcess(node, directory, self.expose)   # ParameterService keeps only a weak reference
        ParameterService(self._proxy)     # kept by its services' callbacks, as in rclpy's Node
        self._exposed = False

    def expose(self) -> None:
        """Give the services their DDS endpoints (something in another process looks for them);
        the directory serves requests from either side."""
        if self._exposed:
            return
        self._exposed = True
        for entry in self._proxy.entries:
            self._directory.attach_dds(entry, Node.create_service(self._node, entry.srv_type, entry.name,
                                                                  entry.callback, callback_group=entry.group))
