"""What a generated callback does: its body, a list of statements run in order (``run`` for a
plain callback, ``arun`` for an ``async def`` one), each logging what it observed.

Statements (``do``), each may carry ``at`` (the callback's indices it runs at):

- ``call`` a Plan client, ``how``: ``block`` (``Client.call``), ``timeout`` (``call`` with
  ``timeout_sec``), ``done`` (``call_async`` + a done callback), ``await`` (in ``async def``);
- ``ready`` / ``wait_service``: ``service_is_ready()``, ``wait_for_service(timeout_sec)``;
- ``publish`` an Int64, ``drive`` (a Twist on cmd_vel);
- ``sleep`` ``ticks`` on the node's clock: ``how`` ``rate`` (``create_rate(...).sleep()``),
  ``rate_destroy`` (the same, then ``destroy_rate``), ``clock`` (``get_clock().sleep_for``);
- ``make`` an entity, ``destroy`` one;
- ``param_set`` / ``param_get`` through a param client (or ``own``), ``how`` as ``call``;
- ``transition`` a lifecycle node (``self``: ``trigger_<t>()``; or through a ChangeState client);
- ``goal`` (``send_goal_async`` with feedback, then the result; ``how`` ``done`` or ``await``)
  and ``cancel`` (the client's last goal);
- ``now``: the node's clock, in ticks.
"""
from __future__ import annotations

import itertools

from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState
from rcl_interfaces.srv import GetParameters, SetParameters
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from geometry_msgs.msg import Twist
from std_msgs.msg import Int64

from robot_programs_interfaces.action import Drive
from robot_programs_interfaces.srv import Plan

WALL_TIMEOUT_S = 30.0        # a blocking call's timeout_sec: never reached by a generated program
WAIT_S = 30.0                # a constructor's wait_for_service
TRANSITIONS = {"configure": Transition.TRANSITION_CONFIGURE, "activate": Transition.TRANSITION_ACTIVATE,
               "deactivate": Transition.TRANSITION_DEACTIVATE, "cleanup": Transition.TRANSITION_CLEANUP}
AWAITING = "await"


def settled(future):
    """A done future's result, or the name of its exception."""
    error = future.exception()
    return f"raised {type(error).__name__}" if error is not None else future.result()


class Statements:
    """Mixed into ``interpreter.Program``."""

    def run(self, act, body) -> None:
        for i, st in enumerate(body):
            if act.due(st):
                self._guarded(act, i, st)

    async def arun(self, act, body) -> None:
        for i, st in enumerate(body):
            if not act.due(st):
                continue
            if st.get("how") == AWAITING:
                request = self._request(act, i, st)
                if request is not None:
                    start, _, report = request
                    try:
                        report(act, await start())
                    except Exception as e:       # what the await raised is what the program saw    # noqa: BLE001 - the program's view, whatever it is
                        act.log("raised", st["do"], type(e).__name__)
            else:
                self._guarded(act, i, st)

    def _guarded(self, act, i, st) -> None:
        try:
            self.step(act, i, st)
        except Exception as e:                   # logged, then the callback raises as the program's would
            act.log("raised", st["do"], type(e).__name__)
            raise

    def step(self, act, i: int, st: dict) -> None:
        do = st["do"]
        simple = getattr(self, f"_do_{do}", None)
        if simple is not None:
            return simple(act, i, st)
        request = self._request(act, i, st)
        if request is None:
            return
        start, blocking, report = request
        how = st.get("how", "done")
        if how in ("block", "timeout") and blocking is not None:
            report(act, blocking(WALL_TIMEOUT_S if how == "timeout" else None))
        else:                                    # done (or await outside async def: a done callback)
            child = act.child(str(i))
            start().add_done_callback(lambda f: report(child, settled(f)))

    # --- statements answered later: (start → future, blocking call or None, report) --------------

    def _request(self, act, i: int, st: dict):
        from differential.interpreter import value_of
        value = value_of(self.who, act.id, i)
        return getattr(self, f"_req_{st['do']}")(act, i, st, value)

    def _req_call(self, act, i, st, value):
        client, name = self.entities[st["client"]], st["client"]
        request = Plan.Request(closeness=float(value))

        def report(a, r):
            if r is None or isinstance(r, str):
                a.log("no_response", name, value, r)
            else:
                a.log("resp", name, value, int(r.linear), int(r.angular))
        return (lambda: client.call_async(request)), (lambda t: client.call(request, timeout_sec=t)), report

    def _req_param_set(self, act, i, st, value):
        value %= 1000
        if st["client"] == "own":
            act.log("set_own", st["name"], value,
                    [r.successful for r in self.node.set_parameters([Parameter(st["name"], value=value)])])
            return None
        client = self.entities[st["client"]]

        def report(a, r):
            a.log("set", st["name"], value, r if r is None or isinstance(r, str) else [x.successful for x in r.results])
        if isinstance(client, AsyncParameterClient):
            return (lambda: client.set_parameters([Parameter(st["name"], value=value)])), None, report
        request = SetParameters.Request(parameters=[Parameter(st["name"], value=value).to_parameter_msg()])
        return (lambda: client[0].call_async(request)), (lambda t: client[0].call(request, timeout_sec=t)), report

    def _req_param_get(self, act, i, st, value):
        if st["client"] == "own":
            act.log("get_own", st["name"], self.node.get_parameter(st["name"]).value)
            return None
        client = self.entities[st["client"]]

        def report(a, r):
            a.log("get", st["name"], r if r is None or isinstance(r, str) else [v.integer_value for v in r.values])
        if isinstance(client, AsyncParameterClient):
            return (lambda: client.get_parameters([st["name"]])), None, report
        request = GetParameters.Request(names=[st["name"]])
        return (lambda: client[1].call_async(request)), (lambda t: client[1].call(request, timeout_sec=t)), report

    def _req_transition(self, act, i, st, value):
        t = st["t"]
        if st["client"] == "self":
            try:
                result = getattr(self.node, f"trigger_{t}")()
                act.log("triggered", t, getattr(result, "name", str(result)))
            except Exception as e:               # a transition the state machine refuses    # noqa: BLE001 - the program's view, whatever it is
                act.log("triggered", t, f"raised {type(e).__name__}")
            return None
        client = self.entities[st["client"]]
        request = ChangeState.Request()
        request.transition.id = TRANSITIONS[t]

        def report(a, r):
            a.log("changed", t, r if r is None or isinstance(r, str) else r.success)
        return (lambda: client.call_async(request)), (lambda t_: client.call(request, timeout_sec=t_)), report

    def _req_goal(self, act, i, st, value):
        client, name = self.entities[st["client"]], st["client"]
        goal = Drive.Goal(linear=float(value), angular=0.0, ticks=st["ticks"])
        feedbacks = itertools.count(1)

        def on_feedback(msg):
            # Whether the goal's acceptance was seen first is not logged: rclpy's action client
            # runs a feedback callback at once and the goal's done callbacks as tasks after it,
            # when both are taken in one wake-up.
            k = next(feedbacks)
            act.child(f"{i}.fb{k}", k).log("feedback", msg.feedback.ticks_left)

        def report(a, handle):
            if handle is None or isinstance(handle, str):
                return a.log("no_goal_response", name, handle)
            a.log("accepted", name, handle.accepted)
            if handle.accepted:
                self.goal_handles[name] = handle
                result_act = act.child(f"{i}.result")
                handle.get_result_async().add_done_callback(
                    lambda f: self._report_result(result_act, settled(f)))
        if st.get("how") == AWAITING:
            async def start():
                handle = await client.send_goal_async(goal, feedback_callback=on_feedback)
                act.log("accepted", name, handle.accepted)
                if handle.accepted:
                    self.goal_handles[name] = handle
                    self._report_result(act, await handle.get_result_async())
                return None
            return start, None, lambda a, r: None
        return (lambda: client.send_goal_async(goal, feedback_callback=on_feedback)), None, report

    @staticmethod
    def _report_result(a, r) -> None:
        if r is None or isinstance(r, str):
            a.log("no_result", r)
        else:
            a.log("result", r.status, r.result.ticks_driven)

    # --- statements done at once ---------------------------------------------------------------

    def _do_ready(self, act, i, st):
        entity = self.entities[st["client"]]
        if isinstance(entity, AsyncParameterClient):
            ready = entity.services_are_ready()
        elif isinstance(entity, tuple):            # a parameter client's own clients
            ready = all(part.service_is_ready() for part in entity)
        else:
            ready = entity.service_is_ready()
        act.log("ready", st["client"], ready)

    def _do_wait_service(self, act, i, st):
        act.log("waited", st["client"], self.entities[st["client"]].wait_for_service(timeout_sec=WAIT_S))

    def _do_publish(self, act, i, st):
        from differential.interpreter import value_of
        value = value_of(self.who, act.id, i)
        self.entities[st["pub"]].publish(Int64(data=value))
        act.log("pub", st["pub"], value)

    def _do_drive(self, act, i, st):
        publisher = self.entities.get("cmd_vel")
        if publisher is not None:
            publisher.publish(Twist())
        act.log("drive", publisher is not None)

    def _do_sleep(self, act, i, st):
        self.sleep_ticks(st.get("how", "clock"), st["ticks"])
        act.log("woke", self.tick())

    def sleep_ticks(self, how: str, ticks: int) -> None:
        if how == "clock":
            self.node.get_clock().sleep_for(Duration(nanoseconds=ticks * self.tick_ns))
            return
        rate = self.node.create_rate(1e9 / (ticks * self.tick_ns))
        rate.sleep()
        if how == "rate_destroy":
            self.node.destroy_rate(rate)

    def _do_make(self, act, i, st):
        act.log("made", st["entity"]["name"], self.make(st["entity"]))

    def _do_destroy(self, act, i, st):
        act.log("destroyed", st["name"], self.destroy(st["name"]))

    def _do_cancel(self, act, i, st):
        handle = self.goal_handles.get(st["client"])
        act.log("cancel", st["client"], handle is not None)
        if handle is not None:
            child = act.child(str(i))
            handle.cancel_goal_async().add_done_callback(
                lambda f: child.log("cancel_response", len(getattr(settled(f), "goals_canceling", ()))))

    def _do_now(self, act, i, st):
        act.log("now", self.tick())
