"""One place of a batch (a robot's nodes, or all run-wide nodes) in a process of its own, as its
own ``main()`` would run it: rclpy's ``MultiThreadedExecutor`` over its nodes, ``use_sim_time``,
lifecycle nodes with ``autostart`` configured and activated before spinning, and a callback's
exception ending the process (``rclpy.spin`` raises it out of ``main``).

``python -m differential.plain_process PLACES.json PLACE DOMAIN``. It tells the rig
(``ground_truth.py``), on stdout: ``@@READY`` once built and every client whose server exists
from the start sees it on the ROS graph; ``@@CLOCK <ns>`` whenever the clocks of all its nodes
have reached a new time; ``@@FAILED <type>`` and its traceback when a callback raised. The nodes'
event lines go to stderr, as rclpy's loggers write them.
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time
import traceback

RUN_WIDE_CLOCK = "/_differential/clock"
THREADS = 16      # more than a generated robot ever blocks at once: no callback waits for a thread


def build(place: str, entries: list) -> list:
    from rclpy.parameter import Parameter
    from differential import interpreter
    nodes = []
    for class_name, spec, autostart in entries:
        cls = getattr(interpreter, class_name)
        node = cls(namespace="/" if place == "run_wide" else f"/{place}",
                   parameter_overrides=[Parameter("spec", value=json.dumps(spec)), Parameter("use_sim_time", value=True)])
        if autostart:
            node.trigger_configure()
            node.trigger_activate()
        nodes.append(node)
    return nodes


def say(text: str) -> None:
    sys.stdout.write(text + "\n")
    sys.stdout.flush()


def watch_clocks(nodes: list) -> list:
    """``@@CLOCK`` each time the slowest node clock moves; the jump handles must be kept."""
    from rclpy.clock import JumpThreshold
    from rclpy.duration import Duration
    times, lock, said = [0] * len(nodes), threading.Lock(), [0]

    def moved(i, node):
        def callback(_jump):
            with lock:
                times[i] = node.get_clock().now().nanoseconds
                if min(times) > said[0]:
                    said[0] = min(times)
                    say(f"@@CLOCK {said[0]}")
        return callback
    threshold = JumpThreshold(min_forward=Duration(nanoseconds=1), min_backward=None, on_clock_change=False)
    return [n.get_clock().create_jump_callback(threshold, post_callback=moved(i, n)) for i, n in enumerate(nodes)]


def endpoints(nodes: list, kind: str) -> dict[str, int]:
    """Per topic (as the nodes name it), the process's construction-time publishers or subscriptions."""
    out: dict[str, int] = {}
    for node in nodes:
        for e in node.program.spec.get("entities", ()):
            if e["kind"] == kind and not e.get("configured"):
                out[e["topic"]] = out.get(e["topic"], 0) + 1
    return out


def matched(node, publishers: dict[str, int], subscriptions: dict[str, int]) -> bool:
    """Both sides of every topic matched (a reliable reader that has not matched its writer yet
    drops what it sends, to get it again a moment later: in another tick): the node's /clock and
    scan subscriptions with the rig's publishers, its topics' publishers and subscriptions with
    one another."""
    if node._time_source._clock_sub.get_publisher_count() < 1:
        return False
    for e in node.program.spec.get("entities", ()):
        entity = node.program.entities.get(e["name"])
        if entity is None or e.get("configured"):
            continue
        if e["kind"] == "pub" and entity.get_subscription_count() < subscriptions.get(e["topic"], 0):
            return False
        if e["kind"] == "sub" and entity.get_publisher_count() < publishers.get(e["topic"], 0):
            return False
        if e["kind"] == "scan" and entity.get_publisher_count() < 1:
            return False
    return True


def ready(node, publishers: dict[str, int], subscriptions: dict[str, int]) -> bool:
    """Every client of ``node`` sees its server, every endpoint its peers (``matched``)."""
    from rclpy.action import ActionClient
    from rclpy.parameter_client import AsyncParameterClient
    from differential.spec import ready_targets
    if not matched(node, publishers, subscriptions):
        return False
    for name in ready_targets(node.program.spec):
        entity = node.program.entities.get(name)
        parts = entity if isinstance(entity, tuple) else (entity,)
        for part in parts:
            if part is None:
                continue
            if isinstance(part, ActionClient):
                if not part.server_is_ready():
                    return False
            elif isinstance(part, AsyncParameterClient):
                if not part.services_are_ready():
                    return False
            elif not part.service_is_ready():
                return False
    return True


def main(argv: list[str]) -> None:
    places_file, place, domain = argv[0], argv[1], int(argv[2])
    from composed_sim.interfaces import activate
    from differential.spec import INTERFACES
    activate([str(INTERFACES)])
    import rclpy
    from rclpy.executors import MultiThreadedExecutor
    # The run-wide process hears the clock on a topic of its own, which the rig publishes once
    # every robot's nodes have the tick's time (ground_truth.py).
    args = ["--ros-args", "-r", f"/clock:={RUN_WIDE_CLOCK}"] if place == "run_wide" else None
    rclpy.init(args=args, domain_id=domain)
    nodes = build(place, json.loads(open(places_file).read())[place])
    handles = watch_clocks(nodes)
    executor = MultiThreadedExecutor(num_threads=THREADS)
    for node in nodes:
        executor.add_node(node)

    def announce_ready():
        publishers, subscriptions = endpoints(nodes, "pub"), endpoints(nodes, "sub")
        while not all(ready(n, publishers, subscriptions) for n in nodes):
            time.sleep(0.02)
        say("@@READY")
    threading.Thread(target=announce_ready, daemon=True).start()
    try:
        executor.spin()
    except Exception as e:                 # a callback raised: the process's main ends with it    # noqa: BLE001 - as rclpy's own process would end
        say(f"@@FAILED {type(e).__name__}")
        say(traceback.format_exc())
        os._exit(1)
    del handles


if __name__ == "__main__":
    main(sys.argv[1:])
