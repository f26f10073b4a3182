"""A ROS listener in another process (the simulator's participants ignore the ones of their own
process), for tests that check what goes over the wire."""
import json
import subprocess
import sys
import textwrap
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# Listens on the given topics (``/bot1/light=sensor_msgs/msg/LaserScan``: that type; tf's without
# one) until a line on stdin; says "matched" once each has a publisher
# matched; at the end prints what it got as JSON: per topic the list
# of messages (tf as hex bytes, /clock as stamp nanoseconds), and every topic it saw published.
SCRIPT = textwrap.dedent("""
    import copy, json, select, sys, rclpy
    from rclpy.context import Context
    from rclpy.node import Node
    from rclpy.executors import SingleThreadedExecutor
    from rosgraph_msgs.msg import Clock
    from composed_sim.ros import contract as c
    from composed_sim.ros.topic import message_class
    domain, topics = int(sys.argv[1]), sys.argv[2:]
    # The contract's QoS with a deep reader history: a run publishes a tick every few
    # milliseconds, and a listener slowed down by a loaded machine must not lose the oldest
    # messages of its keep-last history before its callbacks take them (the depth is not matched).
    DEEP = copy.copy(c.QOS); DEEP.depth = 1000
    context = Context(); rclpy.init(context=context, domain_id=domain)
    node = Node("listener", context=context)
    got = {t: [] for t in topics}
    subs = []
    for t in topics:
        if t == "/clock":
            subs.append(node.create_subscription(Clock, t, lambda m: got["/clock"].append(
                m.clock.sec * 1_000_000_000 + m.clock.nanosec), 100))
        else:   # "/bot1/light=sensor_msgs/msg/LaserScan": that type; tf's otherwise
            name, _, type_name = t.partition("=")
            qos = c.STATIC_QOS if t.endswith("tf_static") else DEEP
            subs.append(node.create_subscription(message_class(type_name) if type_name else c.TF_MESSAGE, name,
                                                 lambda data, t=t: got[t].append(data.hex()), qos, raw=True))
    executor = SingleThreadedExecutor(context=context); executor.add_node(node)
    seen, matched = set(), False
    print("listening", flush=True)
    while not select.select([sys.stdin], [], [], 0)[0]:
        executor.spin_once(timeout_sec=0.02)
        if not matched and all(s.get_publisher_count() > 0 for s in subs):
            matched = True
            print("matched", flush=True)
        seen |= {name for name, _ in node.get_topic_names_and_types() if node.count_publishers(name) > 0}
    for _ in range(10):
        executor.spin_once(timeout_sec=0.02)     # what is still on its way
    print(json.dumps({"got": got, "seen": sorted(seen)}))
""")


class Listener:
    def __init__(self, domain: int, topics: list[str]):
        self.process = subprocess.Popen([sys.executable, "-c", SCRIPT, str(domain), *topics], cwd=ROOT,
                                        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self._until("listening")

    def wait_matched(self) -> None:
        """Until each of the topics has a publisher matched with the listener."""
        self._until("matched")

    def _until(self, word: str) -> None:
        """Until the script says ``word``. Fast DDS writes lines of its own on stdout too (a
        shared-memory port another participant of the machine held a moment, in a parallel test
        run): those are passed over."""
        other = []
        for line in self.process.stdout:
            if line.strip() == word:
                return
            other.append(line)
        raise AssertionError(f"the listener ended (exit {self.process.wait()}) before saying {word!r}; "
                             f"it said: {''.join(other)[-2000:]!r}")

    def stop(self) -> dict:
        """{"got": {topic: [message, …]}, "seen": [topic, …]}"""
        return json.loads(self.process.communicate("stop\n", timeout=60)[0].splitlines()[-1])
