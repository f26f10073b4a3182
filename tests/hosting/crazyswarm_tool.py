"""A client in a process of its own that talks to a run's drones as Crazyswarm2's crazyflie_py does
(tests/hosting/test_crazyflie.py starts it): it finds the drones by the server's robots
parameters and waits for their services, reads the crazyflie_server's parameters (list, describe, get), calls the drones' and the
swarm's services, streams setpoints, sleeps on the run's clock, and prints what it did as JSON.

    python crazyswarm_tool.py DOMAIN SCENARIO      (crazyflie_interfaces on PYTHONPATH)

Scenarios: ``flight`` (take-off, an uploaded figure eight, a streamed circle, landings), ``masks``
(group masks set as parameters, the swarm's take-off and landing), ``bad`` (what no drone should be
asked, and a drone the run does not have).
"""
from __future__ import annotations

import json
import math
import sys

import rclpy
from builtin_interfaces.msg import Duration
from crazyflie_interfaces.msg import FullState, TrajectoryPolynomialPiece
from geometry_msgs.msg import Point
from crazyflie_interfaces.srv import GoTo, Land, NotifySetpointsStop, StartTrajectory, Takeoff, UploadTrajectory
from rcl_interfaces.msg import Parameter, ParameterType, ParameterValue
from rcl_interfaces.srv import DescribeParameters, GetParameters, ListParameters, SetParameters
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter as RclpyParameter
from std_srvs.srv import Empty

from figure_eight import PERIOD_S, figure_eight      # beside this file (tests/hosting/figure_eight.py)


def seconds(s: float) -> Duration:
    return Duration(sec=int(s), nanosec=int(round((s - int(s)) * 1e9)))


class Script:
    """What a Crazyswarm2 script has: its node on the run's clock, clients found as crazyflie_py finds them."""

    def __init__(self, domain: int):
        self.context = Context()
        rclpy.init(context=self.context, domain_id=domain)
        self.node = Node("crazyswarm_tool", context=self.context,
                         parameter_overrides=[RclpyParameter("use_sim_time", value=True)])
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.names = self._find_drones()
        self.report: dict = {"drones": self.names}

    def _find_drones(self) -> list[str]:
        """As crazyflie_py: the robots named by the crazyflie_server's ``robots.<name>.*`` parameters,
        then each drone's services and the swarm's waited for."""
        listed = self.call(ListParameters, "/crazyflie_server/list_parameters", prefixes=["robots"],
                           depth=ListParameters.Request.DEPTH_RECURSIVE)
        names = sorted({n.split(".")[1] for n in listed.result.names if n.startswith("robots.")})
        if not names:
            raise SystemExit("the crazyflie_server names no robot")
        for name in ("emergency", "takeoff", "land", "go_to", "start_trajectory"):
            self.client(Empty if name == "emergency" else StartTrajectory if name == "start_trajectory"
                        else {"takeoff": Takeoff, "land": Land, "go_to": GoTo}[name], f"/all/{name}")
        for drone in names:
            self.client(StartTrajectory, f"/{drone}/start_trajectory")
        return names

    def client(self, srv_type, name: str, wait: float = 60.0):
        client = self.node.create_client(srv_type, name)
        if wait and not client.wait_for_service(timeout_sec=wait):
            seen = sorted(f"{ns.rstrip('/')}/{n}" for n, ns in self.node.get_node_names_and_namespaces())
            raise SystemExit(f"{name}: not served in {wait:.0f} s; the nodes this tool sees: {seen}")
        return client

    def call(self, srv_type, name: str, **fields):
        future = self.client(srv_type, name).call_async(srv_type.Request(**fields))
        self.executor.spin_until_future_complete(future, timeout_sec=30)
        if not future.done():
            raise SystemExit(f"{name}: no answer")
        return future.result()

    def now(self) -> float:
        return self.node.get_clock().now().nanoseconds / 1e9

    def sleep(self, duration: float) -> None:
        """On the run's clock, as crazyflie_py's TimeHelper sleeps."""
        end = self.now() + duration
        while self.now() < end:
            self.executor.spin_once(timeout_sec=0.01)

    def parameters(self) -> dict:
        server = "/crazyflie_server"
        listed = self.call(ListParameters, f"{server}/list_parameters", depth=ListParameters.Request.DEPTH_RECURSIVE)
        names = sorted(n for n in listed.result.names if ".params." in n)
        described = self.call(DescribeParameters, f"{server}/describe_parameters", names=names)
        got = self.call(GetParameters, f"{server}/get_parameters",
                        names=[f"robots.{d}.{k}" for d in self.names for k in ("initial_position", "uri")])
        values = got.values
        return {"params": {n: d.type for n, d in zip(names, described.descriptors)},
                "initial": {d: list(values[2 * i].double_array_value) for i, d in enumerate(self.names)},
                "uri": {d: values[2 * i + 1].string_value for i, d in enumerate(self.names)}}

    def set_parameter(self, name: str, value: int) -> bool:
        value = ParameterValue(type=ParameterType.PARAMETER_INTEGER, integer_value=value)
        answer = self.call(SetParameters, "/crazyflie_server/set_parameters", parameters=[Parameter(name=name, value=value)])
        return answer.results[0].successful

    def mark(self, what: str) -> None:
        self.report.setdefault("marks", []).append((what, self.now()))


def flight(s: Script) -> None:
    first, second = s.names[0], s.names[1]
    s.report.update(s.parameters())
    coefficients, durations = figure_eight()
    pieces = [TrajectoryPolynomialPiece(poly_x=list(c[0]), poly_y=list(c[1]), poly_z=list(c[2]), poly_yaw=list(c[3]),
                                        duration=seconds(d)) for c, d in zip(coefficients, durations)]
    s.call(UploadTrajectory, f"/{first}/upload_trajectory", trajectory_id=0, piece_offset=0, pieces=pieces)
    s.call(Takeoff, f"/{first}/takeoff", height=1.0, duration=seconds(2.5))
    s.call(Takeoff, f"/{second}/takeoff", height=0.5, duration=seconds(1.5))
    s.sleep(3.0)
    s.call(StartTrajectory, f"/{first}/start_trajectory", trajectory_id=0, timescale=1.0, relative=True)
    publisher = s.node.create_publisher(FullState, f"/{second}/cmd_full_state", 1)
    start, sent = s.report["initial"][second], []
    begin = s.now()
    while (t := s.now() - begin) < 2.0:            # a circle of 0.3 m at 30 Hz, as Crazyswarm2's cmd_full_state script streams
        msg = FullState()
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = \
            start[0] + 0.3 * math.sin(t), start[1] + 0.3 * (1 - math.cos(t)), 0.5
        msg.pose.orientation.w = 1.0
        publisher.publish(msg)
        sent.append([msg.pose.position.x, msg.pose.position.y, 0.5])
        s.sleep(1.0 / 30)
    s.report["streamed"] = sent
    s.call(NotifySetpointsStop, f"/{second}/notify_setpoints_stop", remain_valid_millisecs=100)
    s.call(Land, f"/{second}/land", height=0.03, duration=seconds(1.5))
    s.sleep(PERIOD_S)
    s.call(Land, f"/{first}/land", height=0.03, duration=seconds(2.0))
    s.sleep(2.5)


def masks(s: Script) -> None:
    s.report["set"] = [s.set_parameter(f"{s.names[0]}.params.hlCommander.groupmask", 0b1001),
                       s.set_parameter(f"{s.names[1]}.params.hlCommander.groupmask", 0b0010)]
    s.sleep(0.1)
    s.call(Takeoff, "/all/takeoff", group_mask=4, height=0.5, duration=seconds(1.0))      # no drone's group
    s.sleep(1.5)
    s.mark("first up")
    s.call(Takeoff, "/all/takeoff", group_mask=1, height=0.5, duration=seconds(1.0))      # the first drone's
    s.sleep(1.5)
    s.report["set"].append(s.set_parameter("all.params.hlCommander.groupmask", 1))
    s.sleep(0.1)
    s.mark("all up")
    s.call(Takeoff, "/all/takeoff", group_mask=1, height=0.5, duration=seconds(1.0))      # now both are in it
    s.mark("all up answered")         # the run went on while the call crossed: taken by now
    s.sleep(1.5)
    s.call(Land, "/all/land", group_mask=0, height=0.0, duration=seconds(1.0))
    s.sleep(1.5)


def bad(s: Script) -> None:
    first = s.names[0]
    s.report["cf99"] = s.client(Takeoff, "/cf99/takeoff", wait=0).wait_for_service(timeout_sec=1.0)
    s.report["set cf99"] = s.set_parameter("cf99.params.hlCommander.groupmask", 1)
    s.call(Takeoff, f"/{first}/takeoff", height=1.0, duration=seconds(1.0))
    s.sleep(1.5)
    s.call(Takeoff, f"/{first}/takeoff", height=0.5, duration=seconds(1.0))              # while flying
    s.call(UploadTrajectory, f"/{first}/upload_trajectory", trajectory_id=1, piece_offset=0, pieces=[])
    s.call(UploadTrajectory, f"/{first}/upload_trajectory", trajectory_id=2, piece_offset=0,
           pieces=[TrajectoryPolynomialPiece(poly_x=[0.0] * 8, poly_y=[0.0] * 8, poly_z=[0.0] * 8,
                                             poly_yaw=[0.0] * 8, duration=seconds(0.0))])
    s.call(GoTo, f"/{first}/go_to", goal=Point(x=50.0, y=0.0, z=1.0),
           duration=seconds(2.0))
    s.call(StartTrajectory, f"/{first}/start_trajectory", trajectory_id=1, timescale=1.0, relative=True)
    s.sleep(1.0)
    s.call(Empty, f"/{first}/emergency")
    s.sleep(0.5)
    s.call(Takeoff, f"/{first}/takeoff", height=1.0, duration=seconds(1.0))              # locked
    s.sleep(0.5)


def main() -> None:
    domain, scenario = int(sys.argv[1]), sys.argv[2]
    script = Script(domain)
    {"flight": flight, "masks": masks, "bad": bad}[scenario](script)
    print(json.dumps(script.report), flush=True)
    rclpy.shutdown(context=script.context)


if __name__ == "__main__":
    main()
