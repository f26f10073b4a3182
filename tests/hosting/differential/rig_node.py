"""The ground-truth rig's ROS side: a node of its own context that publishes ``/clock`` and each
robot's ``proximity`` scan (only the stamp matters: the programs log the tick it names)."""
from __future__ import annotations

from rclpy.context import Context
from rclpy.node import Node
from rclpy.time import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan


class RigNode:
    def __init__(self, domain: int, robots: list[str]):
        self.domain, self.robots = domain, robots

    def __enter__(self) -> "RigNode":
        import rclpy
        self.context = Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.node = Node("differential_rig", context=self.context)
        from differential.plain_process import RUN_WIDE_CLOCK
        self.clock = self.node.create_publisher(Clock, "/clock", 10)
        self.run_wide_clock = self.node.create_publisher(Clock, RUN_WIDE_CLOCK, 10)
        self.scans = {r: self.node.create_publisher(LaserScan, f"/{r}/proximity", 10) for r in self.robots}
        return self

    def __exit__(self, *exc) -> None:
        import rclpy
        self.node.destroy_node()
        rclpy.shutdown(context=self.context)

    def matched(self, scans: dict[str, int], nodes: tuple[int, int]) -> bool:
        """Every robot's construction-time scan subscriptions and every node's /clock one matched
        (``nodes``: the robots' processes' nodes, the run-wide process's)."""
        return self.clock.get_subscription_count() >= nodes[0] and \
            self.run_wide_clock.get_subscription_count() >= nodes[1] and all(
            self.scans[r].get_subscription_count() >= n for r, n in scans.items())

    def publish_clock(self, ns: int, run_wide: bool) -> None:
        (self.run_wide_clock if run_wide else self.clock).publish(Clock(clock=Time(nanoseconds=ns).to_msg()))

    def publish_scans(self, ns: int) -> None:
        stamp = Time(nanoseconds=ns).to_msg()
        for robot, publisher in self.scans.items():
            scan = LaserScan()
            scan.header.stamp = stamp
            scan.header.frame_id = f"{robot}/base_link"
            publisher.publish(scan)
