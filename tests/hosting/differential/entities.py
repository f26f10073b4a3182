"""What a generated node makes (in its constructor, in ``on_configure``, or from a callback's
``make`` statement) and the callbacks of those entities: each starts an activation, logs what
triggered it, and runs its body (``statements.py``).

Entity specs (``kind``): ``timer`` (period s, group, async, body), ``scan`` (the robot's
``proximity``), ``service`` (a Plan service; its response echoes the request's value and names
the server), ``client`` (of a Plan service), ``pub``/``sub`` (std_msgs Int64 on a topic of the
robot), ``cmd_vel`` (the robot's answer topic, a Twist publisher), ``action_server`` and
``action_client`` (Drive), ``param_client`` (``raw``: SetParameters/GetParameters clients;
``apc``: rclpy's AsyncParameterClient) and ``lifecycle_client`` (ChangeState). Names of other
places' entities are resolved before the node is built (``spec.py``: ``ros``, ``target``).
"""
from __future__ import annotations

from lifecycle_msgs.srv import ChangeState
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.action import ActionClient, ActionServer, CancelResponse, GoalResponse
from rclpy.lifecycle import LifecycleNode
from rclpy.parameter_client import AsyncParameterClient
from sensor_msgs.msg import LaserScan
from std_msgs.msg import Int64
from geometry_msgs.msg import Twist

from robot_programs_interfaces.action import Drive
from robot_programs_interfaces.srv import Plan

from differential.spec import STEP_TICKS

QUEUE = 10


class Entities:
    """Mixed into ``interpreter.Program``: ``node``, ``groups``, ``entities``, ``who`` are its."""

    def make_all(self, specs) -> None:
        for e in specs:
            self.make(e)

    def make(self, e: dict) -> bool:
        """Make entity ``e`` unless one of its name exists; True if made."""
        if e["name"] in self.entities:
            return False
        self.entities[e["name"]] = getattr(self, f"_make_{e['kind']}")(e)
        return True

    def group_of(self, e: dict):
        return self.groups[e.get("group", "default")]

    def _callback(self, e: dict, start):
        """A callback that opens an activation with ``start(*args)`` (None: nothing to do) and
        runs ``e``'s body, sync or ``async def`` as the spec says."""
        body = e.get("body", ())
        if e.get("async"):
            async def callback(*args):
                act = start(*args)
                if act is not None:
                    await self.arun(act, body)
            return callback

        def callback(*args):
            act = start(*args)
            if act is not None:
                self.run(act, body)
        return callback

    def _make_timer(self, e: dict):
        from differential.interpreter import Activation
        name = e["name"]

        def start():
            # The hosts fire a constructor's timer at tick 0 too (docs/contract.md), rclpy one
            # period after the clock it was made at (0): that firing does nothing here.
            if self.node.get_clock().now().nanoseconds == 0:
                return None
            index = self.next_index(name)
            act = Activation(self, f"{name}#{index}", index)
            act.log("fire", self.tick())
            return act
        return self.node.create_timer(e["period"], self._callback(e, start), callback_group=self.group_of(e))

    def _make_scan(self, e: dict):
        from differential.interpreter import Activation
        name = e["name"]

        def start(msg):
            tick = round((msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec) / self.tick_ns)
            act = Activation(self, f"{name}@{tick}", tick)
            act.log("scan", tick)
            return act
        return self.node.create_subscription(LaserScan, "proximity", self._callback(e, start), QUEUE,
                                             callback_group=self.group_of(e))

    def _make_service(self, e: dict):
        from differential.interpreter import Activation, value_of
        name, code = e["name"], value_of(self.who, e["name"])
        body = e.get("body", ())

        def open_(request):
            act = Activation(self, f"{name}<{int(request.closeness)}")
            act.log("serve", int(request.closeness))
            return act

        def answer(request, response):
            response.linear, response.angular = float(int(request.closeness)), float(code)
            return response
        if e.get("async"):
            async def serve(request, response):
                await self.arun(open_(request), body)
                return answer(request, response)
        else:
            def serve(request, response):
                self.run(open_(request), body)
                return answer(request, response)
        return self.node.create_service(Plan, e["ros"], serve, callback_group=self.group_of(e))

    def _make_client(self, e: dict):
        return self.node.create_client(Plan, e["target"], callback_group=self.group_of(e))

    def _make_pub(self, e: dict):
        if isinstance(self.node, LifecycleNode) and e.get("configured"):
            return self.node.create_lifecycle_publisher(Int64, e["topic"], QUEUE)
        return self.node.create_publisher(Int64, e["topic"], QUEUE)

    def _make_cmd_vel(self, e: dict):
        if isinstance(self.node, LifecycleNode) and e.get("configured"):
            return self.node.create_lifecycle_publisher(Twist, "cmd_vel", QUEUE)
        return self.node.create_publisher(Twist, "cmd_vel", QUEUE)

    def _make_sub(self, e: dict):
        from differential.interpreter import Activation
        name = e["name"]

        def start(msg):
            act = Activation(self, f"{name}<{msg.data}")
            act.log("got", msg.data)
            return act
        return self.node.create_subscription(Int64, e["topic"], self._callback(e, start), QUEUE,
                                             callback_group=self.group_of(e))

    def _make_action_client(self, e: dict):
        return ActionClient(self.node, Drive, e["target"], callback_group=self.group_of(e))

    def _make_param_client(self, e: dict):
        if e.get("how") == "apc":
            return AsyncParameterClient(self.node, e["target"], callback_group=self.group_of(e))
        group = self.group_of(e)
        return (self.node.create_client(SetParameters, f"{e['target']}/set_parameters", callback_group=group),
                self.node.create_client(GetParameters, f"{e['target']}/get_parameters", callback_group=group))

    def _make_lifecycle_client(self, e: dict):
        return self.node.create_client(ChangeState, f"{e['target']}/change_state", callback_group=self.group_of(e))

    def _make_action_server(self, e: dict):
        from differential.interpreter import Activation
        name, style = e["name"], e.get("execute", "immediate")

        def on_goal(goal):
            Activation(self, f"{name}?{int(goal.linear)}").log("goal", goal.ticks)
            return GoalResponse.ACCEPT

        def on_cancel(handle):
            accept = e.get("cancel", "accept") == "accept"
            Activation(self, f"{name}!{int(handle.request.linear)}").log("cancel_request", accept)
            return CancelResponse.ACCEPT if accept else CancelResponse.REJECT

        def execute(handle):
            n, act = handle.request.ticks, Activation(self, f"{name}<{int(handle.request.linear)}")
            act.log("execute", n)
            for k in range(n):
                if handle.is_cancel_requested:
                    handle.canceled()
                    act.log("canceled", k)
                    return Drive.Result(ticks_driven=k)
                handle.publish_feedback(Drive.Feedback(ticks_left=n - k))
                act.log("feedback", n - k)
                if style != "immediate":
                    self.sleep_ticks(style, STEP_TICKS)
                    act.log("woke", self.tick())
            handle.succeed()
            act.log("succeeded", n)
            return Drive.Result(ticks_driven=n)
        return ActionServer(self.node, Drive, e["ros"], execute, goal_callback=on_goal, cancel_callback=on_cancel,
                            callback_group=self.group_of(e))

    def destroy(self, name: str) -> bool:
        """Destroy entity ``name`` (a lifecycle node's ``on_cleanup``, a ``destroy`` statement)."""
        entity = self.entities.pop(name, None)
        if entity is None:
            return False
        if isinstance(entity, (ActionServer, ActionClient)):
            entity.destroy()
            return True
        if isinstance(entity, AsyncParameterClient):
            entity = tuple(getattr(entity, f"_{n}_client") for n in (
                "get_parameter", "list_parameter", "set_parameter", "get_parameter_types", "describe_parameters",
                "set_parameters_atomically"))
        for part in entity if isinstance(entity, tuple) else (entity,):
            kind = type(part).__name__
            method = "destroy_lifecycle_publisher" if kind == "LifecyclePublisher" else DESTROY[kind]
            getattr(self.node, method)(part)
        return True


DESTROY = {"Timer": "destroy_timer", "Publisher": "destroy_publisher", "Subscription": "destroy_subscription",
           "Service": "destroy_service", "Client": "destroy_client"}
