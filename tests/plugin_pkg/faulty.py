"""A test controller that misbehaves on purpose: every robot drives a circle, answering each
proximity scan, and the robot named by ``faulty_robot`` commits ``fault`` from its
``from_tick``-th scan on (every ``every`` scans). A plain rclpy Node, like any third party's."""
import ctypes
import math
import os
import threading
import sys
import time

import rclpy
from geometry_msgs.msg import Twist, TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import LaserScan

FAULTS = ("none", "slow", "hang", "busy_hang", "raise", "silent", "nan", "inf", "wrong_stamp",
          "wrong_type", "intrude", "crash", "segfault", "sys_exit", "shutdown_context", "spin")


class Faulty(Node):
    def __init__(self, **node_kwargs):
        super().__init__("faulty", **node_kwargs)
        self.fault = self.declare_parameter("fault", "none").value
        assert self.fault in FAULTS, self.fault
        self.faulty_robot = self.declare_parameter("faulty_robot", "").value
        self.from_tick = self.declare_parameter("from_tick", 5).value
        self.every = self.declare_parameter("every", 1).value
        self.duration_s = self.declare_parameter("duration_s", 0.0).value
        self.victim = self.declare_parameter("victim", "").value
        self.announce = self.declare_parameter("announce", "").value   # a file to create on the fault
        self.me = self.get_namespace().strip("/")
        self.scans = 0
        self.cmd = self.create_publisher(TwistStamped, "cmd_vel", 10)
        self.create_subscription(LaserScan, "proximity", self.on_scan, 10)

    def on_scan(self, scan: LaserScan) -> None:
        tick, self.scans = self.scans, self.scans + 1
        answer = TwistStamped()
        answer.header.stamp = scan.header.stamp
        answer.twist.linear.x, answer.twist.angular.z = 0.05, 0.3
        if (self.me == self.faulty_robot and tick >= self.from_tick
                and (tick - self.from_tick) % self.every == 0):
            if not self.misbehave(answer):
                return
        self.cmd.publish(answer)

    def misbehave(self, answer: TwistStamped) -> bool:
        """Commit the fault; True if the (possibly spoilt) answer is to be published after it."""
        fault = self.fault
        if self.announce:
            with open(self.announce, "w"):
                pass
        if fault == "slow":                         # computes for that long (a time.sleep would be
            until = time.monotonic() + self.duration_s  # set aside on the run's clock: docs/contract.md)
            while time.monotonic() < until:
                pass
        elif fault == "hang":
            threading.Event().wait()                # blocked for good
        elif fault == "busy_hang":
            while True:                             # never returns, but runs Python code
                sum(range(100))
        elif fault == "raise":
            raise RuntimeError("injected fault")
        elif fault == "silent":
            return False
        elif fault == "nan":
            answer.twist.linear.x = math.nan
        elif fault == "inf":
            answer.twist.angular.z = -math.inf
        elif fault == "wrong_stamp":
            answer.header.stamp.sec += 1000
        elif fault == "wrong_type":
            self.create_publisher(Twist, "cmd_vel", 10).publish(Twist())
        elif fault == "intrude":
            hijack = TwistStamped()
            hijack.header.stamp = answer.header.stamp
            hijack.twist.linear.x = 1.0
            self.create_publisher(TwistStamped, f"/{self.victim}/cmd_vel", 10).publish(hijack)
        elif fault == "crash":
            os._exit(7)                             # the process dies, no clean-up
        elif fault == "segfault":
            ctypes.string_at(0)                     # SIGSEGV, as a broken C extension would
        elif fault == "sys_exit":
            sys.exit(3)
        elif fault == "shutdown_context":
            rclpy.shutdown(context=self.context)
        elif fault == "spin":
            rclpy.spin_once(self, timeout_sec=0.01)
        return True
