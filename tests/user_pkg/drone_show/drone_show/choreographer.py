"""Takes the swarm off, sends each drone to a place on a ring, turns it, lands the swarm: each step a
service call at its time on the node's clock, the responses awaited as a ROS 2 program awaits them."""
from __future__ import annotations

import math

from builtin_interfaces.msg import Duration
from crazyflie_interfaces.srv import GoTo, Land, Takeoff
from geometry_msgs.msg import Point
from rclpy.node import Node


def _seconds(s: float) -> Duration:
    return Duration(sec=int(s), nanosec=int(round((s - int(s)) * 1e9)))


class Choreographer(Node):
    def __init__(self):
        super().__init__("choreographer")
        self.drones = self.declare_parameter("drones", ["cf0"]).value
        self.radius = self.declare_parameter("radius_m", 1.0).value
        self._takeoff = self.create_client(Takeoff, "/all/takeoff")
        self._land = self.create_client(Land, "/all/land")
        self._go_to = {name: self.create_client(GoTo, f"/{name}/go_to") for name in self.drones}
        self._steps = [(0.1, self.take_off), (2.6, self.ring), (6.0, self.turn), (9.0, self.land)]
        self.answered = 0
        self.create_timer(0.05, self._tick)

    def _tick(self) -> None:
        now = self.get_clock().now().nanoseconds * 1e-9
        while self._steps and self._steps[0][0] <= now + 1e-9:
            self._steps.pop(0)[1]()

    def _sent(self, future) -> None:
        future.add_done_callback(lambda _: setattr(self, "answered", self.answered + 1))

    def take_off(self) -> None:
        self._sent(self._takeoff.call_async(Takeoff.Request(height=1.0, duration=_seconds(2.0))))

    def ring(self) -> None:
        for k, name in enumerate(self.drones):
            angle = 2 * math.pi * k / len(self.drones)
            goal = Point(x=self.radius * math.cos(angle), y=self.radius * math.sin(angle), z=1.0 + 0.1 * k)
            self._sent(self._go_to[name].call_async(GoTo.Request(goal=goal, yaw=angle, duration=_seconds(3.0))))

    def turn(self) -> None:
        for name in self.drones:
            goal = Point(x=0.0, y=0.0, z=0.0)
            self._sent(self._go_to[name].call_async(GoTo.Request(goal=goal, relative=True, yaw=math.pi / 2,
                                                                 duration=_seconds(2.0))))

    def land(self) -> None:
        self._sent(self._land.call_async(Land.Request(height=0.0, duration=_seconds(2.0))))
